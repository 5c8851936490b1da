// SPDX-License-Identifier: LGPL-2.1-or-later
// Key points and the geometry, angle and collinearity constraints (src/detect/keypoints.cpp),
// on crafted candidates: blobs with chosen points, no image.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>

#include "../../src/core/geometry.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::apply;
using lftag::detail::Blob;
using lftag::detail::Candidate;
using lftag::detail::KeyPoints;

namespace {

using Quad = std::array<int, 4>;

// Units -> pixels for a marker of `family` seen by a pinhole camera (f = 800, principal
// point (320, 240)) at `distance` marker sides, turned `roll` in its plane, then tilted
// about the camera's x axis and panned about its y axis (degrees).
cv::Matx33d view(const Family& f, double roll, double tilt, double pan, double distance = 4) {
  const double d = CV_PI / 180, s = f.side();
  cv::Matx33d rz, rx, ry;
  cv::Rodrigues(cv::Vec3d(0, 0, roll * d), rz);
  cv::Rodrigues(cv::Vec3d(tilt * d, 0, 0), rx);
  cv::Rodrigues(cv::Vec3d(0, pan * d, 0), ry);
  const cv::Matx33d r = ry * rx * rz;
  // Marker frame: (u - S/2) / S per axis, so the marker is one unit of length wide.
  const cv::Matx33d to_frame(1 / s, 0, -0.5, 0, 1 / s, -0.5, 0, 0, 1);
  const cv::Matx33d extrinsic(r(0, 0), r(0, 1), 0, r(1, 0), r(1, 1), 0, r(2, 0), r(2, 1), distance);
  const cv::Matx33d k(800, 0, 320, 0, 800, 240, 0, 0, 1);
  return k * extrinsic * to_frame;
}

// A candidate whose blobs are the marker's n^2 centres under `h`, in a shuffled order;
// `truth` receives the blob indices of K0..K3.
Candidate make(const Family& f, TagId id, const cv::Matx33d& h, Quad& truth, unsigned seed = 1) {
  Candidate c;
  c.family = f;
  const std::vector<cv::Point2d> centres = f.centers(id);
  std::vector<int> order(centres.size());
  std::iota(order.begin(), order.end(), 0);
  std::mt19937 rng(seed);
  std::shuffle(order.begin(), order.end(), rng);
  c.blobs.resize(centres.size());
  for (int g = 0; g < int(centres.size()); ++g) {
    Blob& b = c.blobs[order[g]];
    b.region = g;
    b.area = f.is_baseline(g) ? 16 : 9;
    b.mass = 255.0 * b.area;
    b.point = b.centroid = apply(h, centres[g]);
  }
  const std::array<int, 4> cells = f.keypoint_cells();
  for (int i = 0; i < 4; ++i) truth[i] = order[cells[i]];
  return c;
}

Candidate from_points(const Family& f, const std::vector<cv::Point2d>& points) {
  Candidate c;
  c.family = f;
  for (const cv::Point2d& p : points) {
    Blob b;
    b.point = b.centroid = p;
    b.area = 9;
    b.mass = 1;
    c.blobs.push_back(b);
  }
  return c;
}

std::set<Quad> as_set(const std::vector<KeyPoints>& k) {
  std::set<Quad> s;
  for (const KeyPoints& q : k) s.insert(q.blob);
  return s;
}

// The key points of the four sides of the hull when K0..K3 = t: the hull runs K0, K1, K3,
// K2 clockwise, and each side taken as the baseline turns the marker by 90 degrees.
std::set<Quad> turns(const Quad& t) {
  return {Quad{t[0], t[1], t[2], t[3]}, Quad{t[1], t[3], t[0], t[2]}, Quad{t[3], t[2], t[1], t[0]},
          Quad{t[2], t[0], t[3], t[1]}};
}

// sqrt(smaller / larger eigenvalue) of the points' scatter, from OpenCV's eigen solver.
double spread(const Candidate& c) {
  cv::Mat1d pts(int(c.blobs.size()), 2);
  for (int i = 0; i < pts.rows; ++i) pts(i, 0) = c.blobs[i].point.x, pts(i, 1) = c.blobs[i].point.y;
  cv::Mat cov, mean;
  cv::calcCovarMatrix(pts, cov, mean, cv::COVAR_NORMAL | cv::COVAR_ROWS);
  cv::Mat values;
  cv::eigen(cov, values);
  return std::sqrt(values.at<double>(1) / values.at<double>(0));
}

double degrees(double radians) { return radians * 180 / CV_PI; }

}  // namespace

TEST(SignedAngle, PositiveClockwiseOnScreen) {
  EXPECT_DOUBLE_EQ(detail::signed_angle({1, 0}, {0, 1}), CV_PI / 2);  // y down: below is clockwise
  EXPECT_DOUBLE_EQ(detail::signed_angle({1, 0}, {0, -1}), -CV_PI / 2);
  EXPECT_DOUBLE_EQ(detail::signed_angle({0, 2}, {-3, 0}), CV_PI / 2);
  EXPECT_DOUBLE_EQ(detail::signed_angle({1, 1}, {2, 2}), 0.0);
  EXPECT_NEAR(detail::signed_angle({1, 0}, {1, std::sqrt(3.0)}), CV_PI / 3, 1e-15);
  EXPECT_NEAR(std::abs(detail::signed_angle({1, 0}, {-1, 0})), CV_PI, 1e-15);
  EXPECT_NEAR(detail::signed_angle({3, 4}, {-4, 3}), CV_PI / 2, 1e-15);  // scale-free
}

TEST(FindKeypoints, CanonicalGridsGiveEverySideAndTheTruth) {
  const std::tuple<int, TagId> markers[] = {{2, TagId(9)},  {3, TagId(0)},         {3, TagId(6789)},
                                            {4, TagId(77)}, {5, TagId(123456789)}, {5, TagId::parse("0x3ffffffffff")}};
  const double rolls[] = {0, 37, 90, 180, 251, -12};
  for (const auto& [n, id] : markers)
    for (double roll : rolls)
      for (const auto& [tilt, pan] : {std::pair{0.0, 0.0}, std::pair{35.0, 0.0}, std::pair{-30.0, 25.0}}) {
        const Family f(n);
        Quad truth;
        const Candidate c = make(f, id, view(f, roll, tilt, pan), truth, unsigned(n * 1000 + roll));
        DetectionStats stats;
        const std::vector<KeyPoints> out = detail::find_keypoints(c, DetectorParams{}, stats);
        SCOPED_TRACE(f.name() + " id " + id.to_decimal() + " roll " + std::to_string(roll) + " tilt " +
                     std::to_string(tilt) + " pan " + std::to_string(pan));
        EXPECT_EQ(out.size(), 4u);
        EXPECT_EQ(as_set(out), turns(truth));
        EXPECT_EQ(as_set(out).count(truth), 1u);
        EXPECT_EQ(stats.geometry, 1);
        EXPECT_EQ(stats.angle, 1);
        EXPECT_EQ(stats.collinearity, 1);
      }
}

TEST(FindKeypoints, StatsCountCandidatesNotSides) {
  const Family f(3);
  Quad truth;
  const Candidate c = make(f, 4321, view(f, 10, 20, 0), truth);
  DetectionStats stats;
  stats.geometry = 5, stats.angle = 4, stats.collinearity = 3, stats.decoded = 2;
  detail::find_keypoints(c, DetectorParams{}, stats);
  detail::find_keypoints(c, DetectorParams{}, stats);
  EXPECT_EQ(stats.geometry, 7);
  EXPECT_EQ(stats.angle, 6);
  EXPECT_EQ(stats.collinearity, 5);
  EXPECT_EQ(stats.decoded, 2);
  EXPECT_EQ(stats.topology, 0);
}

TEST(FindKeypoints, GeometryConstraintRejectsASide) {
  // The canonical 3x3 with the centre blob moved above the baseline (to (12, 3) units):
  // two blobs above the top side, where the design allows n - 2 = 1. The hull keeps its four
  // corners, so the other three sides pass and only the true one is rejected.
  const Family f(3);
  Quad truth;
  Candidate c = make(f, 0, cv::Matx33d(10, 0, 50, 0, 10, 40, 0, 0, 1), truth);
  for (Blob& b : c.blobs)
    if (b.region == 4) b.point = b.centroid = cv::Point2d(10 * 12 + 50, 10 * 3 + 40);
  DetectionStats stats;
  const std::vector<KeyPoints> out = detail::find_keypoints(c, DetectorParams{}, stats);
  std::set<Quad> expected = turns(truth);
  expected.erase(truth);
  EXPECT_EQ(as_set(out), expected);
  EXPECT_EQ(stats.geometry, 1);
}

TEST(FindKeypoints, GeometryConstraintRejectsEverySide) {
  // 16 blobs on a circle: the largest quadrilateral takes every fourth, and each side has
  // three blobs beyond it where a 4x4 marker allows two.
  std::vector<cv::Point2d> points;
  for (int i = 0; i < 16; ++i)
    points.emplace_back(100 + 50 * std::cos(i * CV_PI / 8), 100 + 50 * std::sin(i * CV_PI / 8));
  const Candidate c = from_points(Family(4), points);
  DetectionStats stats;
  EXPECT_TRUE(detail::find_keypoints(c, DetectorParams{}, stats).empty());
  EXPECT_EQ(stats.geometry, 0);
  EXPECT_EQ(stats.angle, 0);
  EXPECT_EQ(stats.collinearity, 0);
  // As a 5x5 set (25 points, three allowed beyond a side), the circle of 25 fails alike.
  points.clear();
  for (int i = 0; i < 25; ++i)
    points.emplace_back(50 * std::cos(i * 2 * CV_PI / 25), 50 * std::sin(i * 2 * CV_PI / 25));
  DetectionStats s5;
  EXPECT_TRUE(detail::find_keypoints(from_points(Family(5), points), DetectorParams{}, s5).empty());
  EXPECT_EQ(s5.geometry, 0);
}

TEST(FindKeypoints, AngleConstraint) {
  // A convex quadrilateral K0 (0,0), K1 (10,0), K3 (12,3), K2 (13,7.5), four blobs just
  // below the side K0 K1, and one blob q just above it near K0, at angle -beta from the
  // baseline seen from K0. The side K0 K1 passes the geometry constraint (one blob above,
  // n - 2 = 1 allowed); seen from K0 the other blobs turn by +phi in all, so the angle sum
  // is phi - beta: the side passes for beta < phi and is rejected for beta > phi.
  const std::vector<cv::Point2d> base = {{0, 0},    {10, 0},   {13, 7.5}, {12, 3},
                                         {5, 0.05}, {6, 0.05}, {7, 0.05}, {8, 0.05}};
  double phi = 0;
  for (std::size_t i = 2; i < base.size(); ++i) phi += std::atan2(base[i].y, base[i].x);
  ASSERT_NEAR(degrees(phi), 45.84, 0.01);
  const Quad side{0, 1, 2, 3};  // K0, K1, K2, K3
  for (double beta_deg : {degrees(phi) - 3, degrees(phi) + 3, 100.0}) {
    std::vector<cv::Point2d> points = base;
    const double beta = beta_deg * CV_PI / 180;
    points.emplace_back(0.5 * std::cos(beta), -0.5 * std::sin(beta));
    const Candidate c = from_points(Family(3), points);
    int below = 0;  // the geometry constraint's count for the side K0 K1, by hand
    for (std::size_t i = 2; i < points.size(); ++i) below += points[i].y > 0;
    ASSERT_EQ(below, 6);
    DetectionStats stats;
    const std::set<Quad> out = as_set(detail::find_keypoints(c, DetectorParams{}, stats));
    SCOPED_TRACE("beta " + std::to_string(beta_deg));
    // The other three sides pass regardless.
    std::set<Quad> others = turns(side);
    others.erase(side);
    for (const Quad& q : others) EXPECT_EQ(out.count(q), 1u);
    EXPECT_EQ(out.count(side), beta_deg < degrees(phi) ? 1u : 0u);
    EXPECT_EQ(stats.geometry, 1);
    EXPECT_EQ(stats.angle, 1);
  }
}

TEST(FindKeypoints, AngleConstraintRejectsEverySideThatPassesTheGeometry) {
  // A 5x5 set built so that only the side K0 K1 passes the geometry constraint, and fails
  // the angle constraint: a thin quadrilateral K0 (0,0), K1 (10,0), K3 (22,1.2),
  // K2 (11.95,1.05); four blobs just beyond the middle of each other side (three allowed);
  // three blobs just above K0 at -60 degrees from the baseline, whose angles outweigh the
  // small positive ones of the 20 blobs below; six blobs inside. The funnel counts the
  // candidate at the geometry stage and not at the angle stage.
  const cv::Point2d k0(0, 0), k1(10, 0), k3(22, 1.2), k2(11.95, 1.05);
  std::vector<cv::Point2d> points = {k0, k1, k2, k3};
  auto beyond = [&](cv::Point2d a, cv::Point2d b) {
    const cv::Point2d d = b - a, out = cv::Point2d(d.y, -d.x) * (0.01 / cv::norm(d));
    for (int i = 0; i < 4; ++i) points.push_back(a + d * (0.35 + 0.1 * i) + out);
  };
  beyond(k1, k3), beyond(k3, k2), beyond(k2, k0);
  for (double a : {-60.0, -58.0, -62.0})
    points.emplace_back(0.1 * std::cos(a * CV_PI / 180), 0.1 * std::sin(a * CV_PI / 180));
  for (int i = 0; i < 6; ++i) points.push_back((k0 + k1 + k2 + k3) * 0.25 + cv::Point2d(0.3 * i - 0.8, 0.05 * (i % 2)));
  ASSERT_EQ(points.size(), 25u);
  // By hand, for the four sides of K0 K1 K3 K2: blobs on the inner side, and for K0 K1 the
  // angle sum seen from K0.
  const cv::Point2d hull[4] = {k0, k1, k3, k2};
  for (int side = 0; side < 4; ++side) {
    const cv::Point2d a = hull[side], b = hull[(side + 1) % 4];
    int inside = 0;
    for (const cv::Point2d& p : points)
      if (p != a && p != b) inside += (b - a).cross(p - a) > 0;
    if (side == 0) {
      EXPECT_EQ(inside, 25 - 2 - 3);  // passes: 3 = n - 2 beyond
    } else {
      EXPECT_LT(inside, 25 - 2 - 3) << "side " << side;
    }
  }
  double sum = 0;
  for (std::size_t i = 2; i < points.size(); ++i) sum += detail::signed_angle(k1 - k0, points[i] - k0);
  ASSERT_LT(sum, 0);
  DetectionStats stats;
  EXPECT_TRUE(detail::find_keypoints(from_points(Family(5), points), DetectorParams{}, stats).empty());
  EXPECT_EQ(stats.geometry, 1);
  EXPECT_EQ(stats.angle, 0);
  EXPECT_EQ(stats.collinearity, 0);
}

TEST(FindKeypoints, CollinearityConstraint) {
  // A 3x3 grid squashed to a thin band: its spread ratio is the squash factor times that of
  // the square grid; tau2 just above rejects every side, just below accepts them all.
  const Family f(3);
  const TagId id = 6789;
  for (double squash : {0.03, 0.08, 0.2}) {
    Quad truth;
    const Candidate c = make(f, id, cv::Matx33d(10, 0, 50, 0, 10 * squash, 40, 0, 0, 1), truth);
    const double s = spread(c);
    ASSERT_LT(s, 0.25);
    SCOPED_TRACE("squash " + std::to_string(squash) + " spread " + std::to_string(s));
    DetectorParams tight;
    tight.min_spread_ratio = s * 1.001;
    DetectionStats rejected;
    EXPECT_TRUE(detail::find_keypoints(c, tight, rejected).empty());
    EXPECT_EQ(rejected.geometry, 1);
    EXPECT_EQ(rejected.angle, 1);
    EXPECT_EQ(rejected.collinearity, 0);
    DetectorParams loose;
    loose.min_spread_ratio = s * 0.999;
    DetectionStats passed;
    EXPECT_EQ(as_set(detail::find_keypoints(c, loose, passed)), turns(truth));
    EXPECT_EQ(passed.collinearity, 1);
    // The default tau2 = 0.1 rejects the thinnest two.
    DetectionStats by_default;
    EXPECT_EQ(detail::find_keypoints(c, DetectorParams{}, by_default).empty(), s < 0.1);
  }
  // The unsquashed grid spreads evenly.
  Quad truth;
  EXPECT_GT(spread(make(f, id, cv::Matx33d(10, 0, 50, 0, 10, 40, 0, 0, 1), truth)), 0.9);
}

TEST(FindKeypoints, PointsOnALineAreNoQuadrilateral) {
  std::vector<cv::Point2d> points;
  for (int i = 0; i < 9; ++i) points.emplace_back(10 + 3.0 * i, 20 + 1.5 * i);
  DetectionStats stats;
  EXPECT_TRUE(detail::find_keypoints(from_points(Family(3), points), DetectorParams{}, stats).empty());
  EXPECT_EQ(stats.geometry, 0);
  EXPECT_EQ(stats.angle, 0);
  EXPECT_EQ(stats.collinearity, 0);
  // Three distinct points (the rest repeated): a triangle, still no quadrilateral.
  points = {{0, 0}, {10, 0}, {5, 8}, {0, 0}, {10, 0}, {5, 8}, {0, 0}, {10, 0}, {5, 8}};
  EXPECT_TRUE(detail::find_keypoints(from_points(Family(3), points), DetectorParams{}, stats).empty());
}

TEST(FindKeypoints, AMirroredMarkerDoesNotGiveTheTruth) {
  // Seen from behind (mirrored), the hull's clockwise order runs K0, K2, K3, K1: no side
  // yields K0..K3 in the marker's order.
  const Family f(3);
  Quad truth;
  const Candidate c = make(f, 1234, cv::Matx33d(-10, 0, 300, 0, 10, 40, 0, 0, 1), truth);
  DetectionStats stats;
  const std::set<Quad> out = as_set(detail::find_keypoints(c, DetectorParams{}, stats));
  EXPECT_EQ(out.count(truth), 0u);
  EXPECT_EQ(out.size(), 4u);
}

TEST(FindKeypoints, TheLargestHullQuadrilateralOfARingOfDots) {
  // 67 blobs on a slightly irregular ring: an 8x8 candidate with three extra children,
  // the case where trying every 4-subset of the hull took 635,000 quadrilaterals. The
  // corners found must span the largest quadrilateral, as a brute force finds it.
  std::vector<cv::Point2d> points;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> wobble(-0.3, 0.3);
  for (int i = 0; i < 67; ++i) {
    const double t = 2 * CV_PI * i / 67;
    points.emplace_back(200 + (100 + wobble(rng)) * std::cos(t), 150 + (60 + wobble(rng)) * std::sin(t));
  }
  const Candidate c = from_points(Family(8), points);
  auto area = [&](const Quad& q) {
    double a = 0;
    for (int i = 0; i < 4; ++i) a += points[q[i]].cross(points[q[(i + 1) % 4]]);
    return std::abs(a) / 2;
  };
  double best = 0;
  for (int a = 0; a < 67; ++a)
    for (int b = a + 1; b < 67; ++b)
      for (int d = b + 1; d < 67; ++d)
        for (int e = d + 1; e < 67; ++e) best = std::max(best, area({a, b, d, e}));
  const std::vector<int> corners = detail::hull_corners(c);
  ASSERT_EQ(corners.size(), 4u);
  EXPECT_NEAR(area({corners[0], corners[1], corners[2], corners[3]}), best, 1e-9 * best);
  // Clockwise on screen (y down): a positive shoelace sum.
  double signed_area = 0;
  for (int i = 0; i < 4; ++i) signed_area += points[corners[i]].cross(points[corners[(i + 1) % 4]]);
  EXPECT_GT(signed_area, 0);
}
