// SPDX-License-Identifier: LGPL-2.1-or-later
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "lftag/render.hpp"

using namespace lftag;

namespace {

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

int count(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

}  // namespace

TEST(Print, PngMarkerIsTheExactRasterAtTheRequestedResolution) {
  PrintOptions o;
  o.size_m = 0.0508;  // 2 inches at 150 dpi: 300 px for the 24 u border, 12.5 px per unit
  o.dpi = 150;
  o.caption = false;
  const std::string path = testing::TempDir() + "/m.png";
  write_marker(path, Family(3), 6789, o);
  const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
  ASSERT_EQ(image.cols, 350);  // (24 + 2 * 2) u * 12.5 px
  ASSERT_EQ(image.rows, 350);
  const cv::Mat1b expected = rasterize_marker(Family(3), 6789, 12.5, 2);
  EXPECT_EQ(cv::norm(image, expected, cv::NORM_INF), 0.0);
  // With a caption the image grows below and the marker is unchanged.
  o.caption = true;
  write_marker(path, Family(3), 6789, o);
  const cv::Mat captioned = cv::imread(path, cv::IMREAD_GRAYSCALE);
  EXPECT_GT(captioned.rows, 350);
  EXPECT_EQ(cv::norm(captioned(cv::Rect(0, 0, 350, 350)), expected, cv::NORM_INF), 0.0);
  EXPECT_LT(cv::mean(captioned(cv::Rect(0, 350, 350, captioned.rows - 350)))[0], 254.0);  // some text
}

TEST(Print, SvgAndPdfCarryTheVectorGeometry) {
  PrintOptions o;
  o.size_m = 0.1;
  const std::string svg = testing::TempDir() + "/m.svg", pdf = testing::TempDir() + "/m.pdf";
  write_marker(svg, Family(4), 12345, o);
  write_marker(pdf, Family(4), 12345, o);
  const std::string s = slurp(svg), p = slurp(pdf);
  EXPECT_NE(s.find("<svg"), std::string::npos);
  // 100 mm + 2 * (2/30) * 100 mm margin = 113.33 mm = 321.26 pt wide.
  EXPECT_NE(s.find("width=\"321.259843pt"), std::string::npos) << s.substr(0, 300);
  EXPECT_EQ(p.rfind("%PDF", 0), 0u);
  EXPECT_EQ(count(p, "/Type /Page\n") + count(p, "/Type /Page "), 1);
}

TEST(Print, SheetsFillPages) {
  PrintOptions o;
  o.size_m = 0.05;
  std::vector<TagId> ids;
  for (int i = 0; i < 40; ++i) ids.emplace_back(std::uint64_t(i));
  const std::string pdf = testing::TempDir() + "/sheet.pdf";
  const int pages = write_sheet(pdf, Family(3), ids, o, Paper::a4);
  EXPECT_GE(pages, 2);
  const std::string p = slurp(pdf);
  EXPECT_EQ(count(p, "/Type /Page\n") + count(p, "/Type /Page "), pages);
  // One page holds fewer than 40 markers of 5 cm: SVG and PNG refuse.
  EXPECT_THROW(write_sheet(testing::TempDir() + "/sheet.svg", Family(3), ids, o, Paper::letter), std::invalid_argument);
  ids.resize(6);
  o.dpi = 100;
  const std::string png = testing::TempDir() + "/sheet.png";
  EXPECT_EQ(write_sheet(png, Family(3), ids, o, Paper::letter), 1);
  const cv::Mat page = cv::imread(png, cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(page.cols, 850);   // 8.5 in at 100 dpi
  EXPECT_EQ(page.rows, 1100);  // 11 in
}

TEST(Print, ErrorsAreClear) {
  PrintOptions o;
  EXPECT_THROW(write_marker(testing::TempDir() + "/m.bmp", Family(3), 1, o), std::invalid_argument);
  EXPECT_THROW(write_marker("/nonexistent-dir/m.svg", Family(3), 1, o), std::runtime_error);
  EXPECT_THROW(write_marker(testing::TempDir() + "/m.svg", Family(3), 16384, o), std::out_of_range);
  o.size_m = 1.0;
  EXPECT_THROW(write_sheet(testing::TempDir() + "/s.pdf", Family(3), {1}, o, Paper::a4), std::invalid_argument);
  EXPECT_THROW(parse_paper("a5"), std::invalid_argument);
}

TEST(Print, NumbersOutsideWhatAFileCanHoldAreRefused) {
  // Each of these once reached a float-to-int conversion (undefined) or a huge allocation.
  const std::string svg = testing::TempDir() + "/n.svg", png = testing::TempDir() + "/n.png";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (auto set : std::vector<void (*)(PrintOptions&, double)>{[](PrintOptions&o, double v) { o.size_m = v; },
                                                               [](PrintOptions&o, double v) { o.dpi = v; },
                                                               [](PrintOptions&o, double v) { o.margin_units = v; }})
    for (double v : {nan, 1e300, -1.0}) {
      PrintOptions o;
      set(o, v);
      EXPECT_THROW(write_marker(png, Family(3), 1, o), std::invalid_argument) << v;
      EXPECT_THROW(write_sheet(svg, Family(3), {1}, o, Paper::a4), std::invalid_argument) << v;
    }
  PrintOptions o;
  o.dpi = 10000;  // an A4 page at 10000 dpi is 116,929 pixels high
  EXPECT_THROW(write_sheet(png, Family(3), {1}, o, Paper::a4), std::invalid_argument);
  o.size_m = 2;  // a 2 m marker at 10000 dpi
  EXPECT_THROW(write_marker(png, Family(3), 1, o), std::invalid_argument);
  EXPECT_THROW(rasterize_marker(Family(3), 0, 1e6), std::invalid_argument);
}

TEST(Print, AFailedWriteLeavesAnExistingFileAlone) {
  // A4 at 20,000 dpi is wider than cairo's largest image: refused before the file is touched.
  const std::string path = testing::TempDir() + "/keep.png";
  std::ofstream(path) << "keep me";
  PrintOptions o;
  o.dpi = 20000;
  EXPECT_THROW(write_sheet(path, Family(3), {1}, o, Paper::a4), std::invalid_argument);
  EXPECT_EQ(slurp(path), "keep me");
  EXPECT_FALSE(std::ifstream(path + ".part").good());
  // A write that succeeds replaces it whole.
  o.dpi = 50;
  EXPECT_EQ(write_sheet(path, Family(3), {1}, o, Paper::a4), 1);
  EXPECT_EQ(cv::imread(path).cols, int(std::ceil(0.210 / 0.0254 * 50 - 1e-6)));
  EXPECT_FALSE(std::ifstream(path + ".part").good());
  std::remove(path.c_str());
  // A write that fails after drawing (a folder is in the way of the final rename) leaves
  // no partial file behind.
  const std::string folder = testing::TempDir() + "/in-the-way.png";
  ASSERT_EQ(system(("mkdir -p '" + folder + "'").c_str()), 0);
  EXPECT_THROW(write_marker(folder, Family(3), 1, o), std::runtime_error);
  EXPECT_FALSE(std::ifstream(folder + ".part").good());
  ASSERT_EQ(system(("rmdir '" + folder + "'").c_str()), 0);
}
