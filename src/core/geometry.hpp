// SPDX-License-Identifier: LGPL-2.1-or-later
// Small plane-geometry helpers shared inside the library (not part of its API).
#pragma once

#include <array>
#include <cmath>
#include <optional>
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
  if (a == 0) {  // degenerate (collinear or empty): the vertices' mean
    cv::Point2d mean;
    for (const cv::Point2d& p : poly) mean += p;
    return poly.empty() ? mean : mean / double(poly.size());
  }
  return {cx / (3 * a), cy / (3 * a)};
}

// The image of point p under the homography h.
inline cv::Point2d apply(const cv::Matx33d& h, cv::Point2d p) {
  const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1);
  return {q[0] / q[2], q[1] / q[2]};
}

// Where the diagonals of a quadrilateral cross: the image of a planar square's centre.
// The vertices' mean when they are parallel (a degenerate quadrilateral).
inline cv::Point2d diagonals_crossing(const std::array<cv::Point2d, 4>& q) {
  const cv::Point2d a = q[2] - q[0], b = q[3] - q[1];
  const double d = a.cross(b);
  if (d == 0) return (q[0] + q[1] + q[2] + q[3]) / 4;
  return q[0] + a * ((q[1] - q[0]).cross(b) / d);
}

// Signed area of a quadrilateral (shoelace): positive when its vertices run clockwise on
// screen (y down).
inline double quad_area(const std::array<cv::Point2d, 4>& q) {
  double a = 0;
  for (int i = 0; i < 4; ++i) a += q[i].cross(q[(i + 1) % 4]);
  return a / 2;
}

// Indices of the four vertices of a convex polygon (vertices in order) that span the
// largest quadrilateral, in the polygon's order; none when it has fewer than four or no
// area. For each diagonal, the farthest vertex on either side: O(n^3).
inline std::optional<std::array<int, 4>> largest_quad(const std::vector<cv::Point2d>& convex) {
  const int h = int(convex.size());
  if (h < 4) return std::nullopt;
  const auto at = [&](int i) { return convex[std::size_t(i % h)]; };
  std::array<int, 4> best{};
  double best_area = 0;
  for (int a = 0; a < h; ++a)
    for (int d = a + 2; d < h; ++d) {
      const cv::Point2d base = at(d) - at(a);
      // The vertices between a and d lie on one side of the diagonal, those after d on
      // the other.
      int b = -1, e = -1;
      double left = 0, right = 0;
      for (int i = a + 1; i < d; ++i)
        if (const double t = std::abs(base.cross(at(i) - at(a))); t > left) left = t, b = i;
      for (int i = d + 1; i < a + h; ++i)
        if (const double t = std::abs(base.cross(at(i) - at(a))); t > right) right = t, e = i % h;
      if (b < 0 || e < 0) continue;
      if (const double area = (left + right) / 2; area > best_area) best_area = area, best = {a, b, d, e};
    }
  if (!(best_area > 0)) return std::nullopt;
  return best;
}

}  // namespace lftag::detail
