// SPDX-License-Identifier: LGPL-2.1-or-later
// Key point identification (paper IV-D) and geometry filtering (IV-E).
//
// The centroids lie on a projected n x n grid, so the four extreme corners of their convex
// hull are K0, K1, K3 and K2 in clockwise order for one of the four sides as the baseline
// (a front view keeps the orientation). The paper takes the two heaviest blobs as the
// baseline, but perspective alone can change a blob's area by the baseline's 16/9, so all
// four sides go to the decoder, which weighs the squares' ink once the homography is exact.
// The paper's geometry, angle and collinearity constraints filter the sides.
#include <algorithm>
#include <cmath>
#include <numeric>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {

double signed_angle(cv::Point2d a, cv::Point2d b) { return std::atan2(a.cross(b), a.dot(b)); }

namespace {

// Sum of the angles from the baseline (from -> to) to every other blob, seen from `from`.
double angle_sum(const Candidate& c, int from, int to) {
  const cv::Point2d o = c.blobs[from].point, base = c.blobs[to].point - o;
  double sum = 0;
  for (int i = 0; i < int(c.blobs.size()); ++i)
    if (i != from && i != to) sum += signed_angle(base, c.blobs[i].point - o);
  return sum;
}

// sqrt(smaller / larger eigenvalue) of the centroids' scatter: 0 for a line, 1 for a disc.
double spread_ratio(const Candidate& c) {
  cv::Point2d mean;
  for (const Blob& b : c.blobs) mean += b.point;
  mean *= 1.0 / c.blobs.size();
  double sxx = 0, sxy = 0, syy = 0;
  for (const Blob& b : c.blobs) {
    const cv::Point2d d = b.point - mean;
    sxx += d.x * d.x, sxy += d.x * d.y, syy += d.y * d.y;
  }
  const double mid = (sxx + syy) / 2, dev = std::hypot((sxx - syy) / 2, sxy);
  const double big = mid + dev, small = std::max(0.0, mid - dev);
  return big > 0 ? std::sqrt(small / big) : 0.0;
}

}  // namespace

// The hull's largest quadrilateral (largest_quad): cubic in the hull's size, where trying
// every 4-subset was quartic (635,000 quadrilaterals for the 67 blobs of an 8x8 candidate
// on a ring of dots).
std::vector<int> hull_corners(const Candidate& c) {
  std::vector<cv::Point2f> points;
  for (const Blob& b : c.blobs) points.emplace_back(cv::Point2f(b.point));
  std::vector<int> hull;
  cv::convexHull(points, hull, false, false);
  std::vector<cv::Point2d> polygon;
  for (const int i : hull) polygon.push_back(c.blobs[i].point);
  const std::optional<std::array<int, 4>> quad = largest_quad(polygon);
  if (!quad) return {};
  std::vector<int> out;
  for (const int i : *quad) out.push_back(hull[i]);
  const std::array<cv::Point2d, 4> q = {c.blobs[out[0]].point, c.blobs[out[1]].point, c.blobs[out[2]].point,
                                        c.blobs[out[3]].point};
  if (quad_area(q) < 0) std::reverse(out.begin(), out.end());  // clockwise with y down
  return out;
}

std::vector<KeyPoints> find_keypoints(const Candidate& c, const DetectorParams& params, DetectionStats& stats) {
  const int n = c.family.n(), count = int(c.blobs.size());
  const std::vector<int> corners = hull_corners(c);
  if (corners.empty()) return {};
  std::vector<KeyPoints> out;
  std::array<bool, 3> passed{};
  // Each side of the hull may be the baseline; the decoder tells them apart by the ink of
  // the squares (see decode.cpp). The constraints are the paper's, side by side.
  for (int side = 0; side < 4; ++side) {
    const int k0 = corners[side], k1 = corners[(side + 1) % 4];
    const cv::Point2d p0 = c.blobs[k0].point, base = c.blobs[k1].point - p0;

    // Geometry: all but the n-2 top-row data blobs lie on one side of the baseline.
    int below = 0;
    for (int i = 0; i < count; ++i)
      if (i != k0 && i != k1) below += base.cross(c.blobs[i].point - p0) > 0;
    if (below < count - 2 - (n - 2)) continue;
    passed[0] = true;

    // Angle: seen from K0 the blobs turn one way from the baseline, from K1 the other way.
    if (!(angle_sum(c, k0, k1) > 0) || !(angle_sum(c, k1, k0) < 0)) continue;
    passed[1] = true;

    // Collinearity, scale-free: the centroids must spread in two directions.
    if (spread_ratio(c) < params.min_spread_ratio) continue;
    passed[2] = true;

    KeyPoints k;
    k.blob = {k0, k1, corners[(side + 3) % 4], corners[(side + 2) % 4]};
    out.push_back(k);
  }
  stats.geometry += passed[0], stats.angle += passed[1], stats.collinearity += passed[2];
  return out;
}

}  // namespace lftag::detail
