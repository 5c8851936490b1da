// SPDX-License-Identifier: LGPL-2.1-or-later
#include <gtest/gtest.h>

#include "lftag/render.hpp"

using namespace lftag;

namespace {

double analytic_black_area(const Family& f, TagId id) {
  const double s = f.side();
  double area = s * s - (s - 4) * (s - 4);
  for (const UnitRect& r : f.black_squares(id)) area += r.width * r.height;
  return area;
}

cv::Mat1f marker_cells(const Family& f, TagId id) {
  cv::Mat1f cells;
  f.unit_bitmap(id).convertTo(cells, CV_32F, 1.0 / 255);
  return cells;
}

}  // namespace

TEST(Raster, CoverageAddsUpToTheAnalyticBlackArea) {
  for (const auto& [n, id, scale] : {std::tuple{2, 5ull, 3.3}, std::tuple{3, 6789ull, 7.3},
                                     std::tuple{4, 123456ull, 0.77}, std::tuple{8, 987654321ull, 2.05}}) {
    const Family f(n);
    const cv::Mat1f cells = marker_cells(f, id);
    const int size = int(std::ceil((f.side() + 4) * scale)) + 1;
    // Arbitrary sub-pixel placement.
    const cv::Mat1f image =
        resample_cells(cells, cv::Size(size, size), scale, cv::Point2d(2 * scale - 0.2, 2 * scale + 0.13));
    const double black = cv::sum(1.0 - image)[0] / (scale * scale);
    EXPECT_NEAR(black, analytic_black_area(f, id), 1e-3 * analytic_black_area(f, id)) << f.name();
  }
}

TEST(Raster, PixelsAreAreaWeightedMeans) {
  // One black cell of 1.5 px at offset 0.25: pixel 0 ([-0.5, 0.5]) is covered 0.25,
  // pixel 1 fully, pixel 2 covered 0.25.
  const cv::Mat1f one(1, 1, 0.0f);
  const cv::Mat1f img = resample_cells(one, cv::Size(3, 1), 1.5, cv::Point2d(0.25, -0.5), 1.0f);
  EXPECT_NEAR(img(0, 0), 0.75f, 1e-6);
  EXPECT_NEAR(img(0, 1), 0.0f, 1e-6);
  EXPECT_NEAR(img(0, 2), 0.75f, 1e-6);
}

TEST(Raster, HighResolutionCentroidsSitAtTheSpecCentres) {
  const double scale = 23.7, margin = 2;  // pixels per unit, deliberately not whole
  for (const auto& [n, id] : {std::pair{3, TagId(6789)}, std::pair{4, TagId(268435455)}, std::pair{5, TagId(0)},
                              std::pair{7, TagId::parse("0x2468ace13579bdf02468ace")}}) {
    const Family f(n);
    const cv::Mat1b image = rasterize_marker(f, id, scale, margin);
    const auto centres = f.centers(id);
    const auto squares = f.black_squares(id);
    for (int g = 0; g < f.cell_count(); ++g) {
      // Darkness-weighted centroid over the square grown by 1 u (neighbours are 2 u away).
      const UnitRect& s = squares[g];
      const cv::Rect roi(int((s.x - 1 + margin) * scale), int((s.y - 1 + margin) * scale), int((s.width + 2) * scale),
                         int((s.height + 2) * scale));
      double m = 0, mx = 0, my = 0;
      for (int y = roi.y; y < roi.y + roi.height; ++y)
        for (int x = roi.x; x < roi.x + roi.width; ++x) {
          const double w = 255.0 - image(y, x);
          m += w, mx += w * x, my += w * y;
        }
      const double ux = (mx / m + 0.5) / scale - margin, uy = (my / m + 0.5) / scale - margin;
      EXPECT_NEAR(ux, centres[g].x, 0.01) << f.name() << " cell " << g;
      EXPECT_NEAR(uy, centres[g].y, 0.01) << f.name() << " cell " << g;
    }
  }
}

TEST(Raster, RejectsBadArguments) {
  EXPECT_THROW(rasterize_marker(Family(3), 0, 0.0), std::invalid_argument);
  EXPECT_THROW(rasterize_marker(Family(3), 0, 1.0, -1), std::invalid_argument);
  EXPECT_THROW(rasterize_marker(Family(3), 16384, 1.0), std::out_of_range);
  EXPECT_THROW(resample_cells(cv::Mat1f(), cv::Size(3, 3), 1, {}), std::invalid_argument);
}
