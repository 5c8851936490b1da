// SPDX-License-Identifier: LGPL-2.1-or-later
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/image_file.hpp"

using namespace lftag;

namespace {

const std::string kTmp = testing::TempDir();

std::vector<unsigned char> slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

void write(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

void put_be16(std::vector<unsigned char>& b, std::size_t at, unsigned v) { b[at] = v >> 8, b[at + 1] = v & 0xFF; }
void put_be32(std::vector<unsigned char>& b, std::size_t at, unsigned v) { put_be16(b, at, v >> 16), put_be16(b, at + 2, v & 0xFFFF); }
void put_le16(std::vector<unsigned char>& b, std::size_t at, unsigned v) { b[at] = v & 0xFF, b[at + 1] = v >> 8; }
void put_le32(std::vector<unsigned char>& b, std::size_t at, unsigned v) { put_le16(b, at, v & 0xFFFF), put_le16(b, at + 2, v >> 16); }

// A 20,000 x 20,000 image (400 MP) of each format, as a header and a few bytes of data.
std::vector<unsigned char> huge_png() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.png");
  put_be32(b, 16, 20000), put_be32(b, 20, 20000);
  return b;
}

std::vector<unsigned char> huge_jpeg() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.jpg");
  for (std::size_t i = 2; i + 9 < b.size(); ++i)
    if (b[i] == 0xFF && b[i + 1] == 0xC0) {  // baseline start of frame: length, precision, height, width
      put_be16(b, i + 5, 20000), put_be16(b, i + 7, 20000);
      break;
    }
  return b;
}

std::vector<unsigned char> huge_bmp() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.bmp");
  put_le32(b, 18, 20000), put_le32(b, 22, 20000);
  return b;
}

std::vector<unsigned char> huge_pgm() {
  const std::string s = "P5\n# a comment\n20000 20000\n255\n\x80\x80";
  return {s.begin(), s.end()};
}

std::vector<unsigned char> huge_tiff() {
  std::vector<unsigned char> b(8 + 2 + 2 * 12 + 4, 0);
  b[0] = b[1] = 'I', b[2] = '*';
  put_le32(b, 4, 8);
  put_le16(b, 8, 2);
  for (int e = 0; e < 2; ++e) {
    const std::size_t at = 10 + e * 12;
    put_le16(b, at, 256 + e), put_le16(b, at + 2, 4), put_le32(b, at + 4, 1), put_le32(b, at + 8, 20000);
  }
  return b;
}

std::vector<unsigned char> huge_webp() {
  std::vector<unsigned char> b(32, 0);
  std::copy_n("RIFF", 4, b.begin()), std::copy_n("WEBPVP8X", 8, b.begin() + 8);
  put_le32(b, 4, 22), put_le32(b, 16, 10);
  put_le32(b, 24, 19999), put_le32(b, 27, 19999);  // 24-bit sizes minus one (the second overwrites a zero byte)
  return b;
}

}  // namespace

TEST(ImageFile, HeadersGiveTheSizesOpenCVWrites) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  for (const char* ext : {"png", "jpg", "bmp", "pgm", "ppm", "tiff", "webp"}) {
    const std::string path = kTmp + "/img." + ext;
    cv::Mat written = image;
    if (std::string(ext) == "ppm") cv::cvtColor(image, written, cv::COLOR_GRAY2BGR);
    if (!cv::imwrite(path, written)) {
      ADD_FAILURE() << "OpenCV cannot write ." << ext;
      continue;
    }
    const std::optional<cv::Size> size = image_file_size(path);
    ASSERT_TRUE(size) << ext;
    EXPECT_EQ(*size, cv::Size(53, 37)) << ext;
    EXPECT_EQ(read_grey_image(path).size(), cv::Size(53, 37)) << ext;
  }
}

TEST(ImageFile, ImagesPastTheLimitAreRefusedBeforeDecoding) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  for (const char* ext : {"png", "jpg", "bmp"}) ASSERT_TRUE(cv::imwrite(kTmp + "/img." + ext, image));
  const std::pair<const char*, std::vector<unsigned char>> cases[] = {
      {"png", huge_png()}, {"jpg", huge_jpeg()}, {"bmp", huge_bmp()},
      {"pgm", huge_pgm()}, {"tiff", huge_tiff()}, {"webp", huge_webp()}};
  for (const auto& [ext, bytes] : cases) {
    const std::string path = kTmp + "/huge." + ext;
    write(path, bytes);
    const std::optional<cv::Size> size = image_file_size(path);
    ASSERT_TRUE(size) << ext;
    EXPECT_EQ(*size, cv::Size(20000, 20000)) << ext;
    try {
      read_grey_image(path);
      ADD_FAILURE() << ext << " was not refused";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("20000x20000 pixels, more than the limit of 100000000"), std::string::npos)
          << e.what();
    }
  }
  // A smaller limit applies to ordinary images too.
  EXPECT_THROW(read_grey_image(kTmp + "/img.png", 1000), std::runtime_error);
  EXPECT_NO_THROW(read_grey_image(kTmp + "/img.png", 53 * 37));
}

TEST(ImageFile, CutAndUnknownHeadersAreLeftToOpenCV) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  ASSERT_TRUE(cv::imwrite(kTmp + "/img.png", image));
  ASSERT_TRUE(cv::imwrite(kTmp + "/img.jpg", image));
  for (const char* ext : {"png", "jpg"}) {
    std::vector<unsigned char> b = slurp(kTmp + "/img." + ext);
    b.resize(ext == std::string("png") ? 20 : 4);
    const std::string path = kTmp + "/cut." + ext;
    write(path, b);
    EXPECT_FALSE(image_file_size(path)) << ext;
    EXPECT_THROW(read_grey_image(path), std::runtime_error) << ext;
  }
  const std::string text = kTmp + "/text.png";
  write(text, {'h', 'e', 'l', 'l', 'o'});
  EXPECT_FALSE(image_file_size(text));
  EXPECT_THROW(read_grey_image(text), std::runtime_error);
  // A JPEG whose segments loop on themselves (length 2 forever) ends.
  std::vector<unsigned char> loop = {0xFF, 0xD8};
  for (int i = 0; i < 10000; ++i) loop.insert(loop.end(), {0xFF, 0xE0, 0x00, 0x02});
  write(kTmp + "/loop.jpg", loop);
  EXPECT_FALSE(image_file_size(kTmp + "/loop.jpg"));
  EXPECT_THROW(image_file_size(kTmp + "/does-not-exist.png"), std::runtime_error);
  EXPECT_THROW(read_grey_image(kTmp + "/does-not-exist.png"), std::runtime_error);
}
