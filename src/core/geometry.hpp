// SPDX-License-Identifier: LGPL-2.1-or-later
// Small plane-geometry helpers shared inside the library (not part of its API).
#pragma once

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

}  // namespace lftag::detail
