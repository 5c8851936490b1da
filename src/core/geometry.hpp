// SPDX-License-Identifier: LGPL-2.1-or-later
// Small plane-geometry helpers shared inside the library (not part of its API).
#pragma once

#include <array>
#include <vector>

#include <opencv2/core.hpp>

namespace lftag::detail {

// Area centroid of a simple polygon (vertices in order, either orientation).
inline cv::Point2d polygon_centroid(const std::vector<cv::Point2d>& poly) {
  double a = 0, cx = 0, cy = 0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const cv::Point2d& p = poly[i];
    const cv::Point2d& q = poly[(i + 1) % poly.size()];
    const double cross = p.x * q.y - q.x * p.y;
    a += cross, cx += (p.x + q.x) * cross, cy += (p.y + q.y) * cross;
  }
  return {cx / (3 * a), cy / (3 * a)};
}

// Signed area of a quadrilateral (shoelace): positive when its vertices run clockwise on
// screen (y down).
inline double quad_area(const std::array<cv::Point2d, 4>& q) {
  double a = 0;
  for (int i = 0; i < 4; ++i) a += q[i].cross(q[(i + 1) % 4]);
  return a / 2;
}

}  // namespace lftag::detail
