// SPDX-License-Identifier: LGPL-2.1-or-later
// The border's stroke for the final pose (src/detect/border_edges.cpp), on rendered
// markers with known truth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "lftag/render.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::border_edges;
using lftag::detail::BorderEdges;
using lftag::test::Look;
using lftag::test::render_marker;
using lftag::test::RenderedMarker;

namespace {

const Camera kCamera = Camera::pinhole(800, 800, 319.5, 239.5, 640, 480);

// Signed distances (px) of the points from the true stroke centre line of their side,
// positive inwards.
std::vector<double> offsets(const RenderedMarker& r, const BorderEdges& edges) {
  const Family& f = r.marker.family;
  const double s = f.side();
  const cv::Point2d centre = r.truth.center;
  std::vector<double> out;
  for (const detail::EdgePoint& e : edges.points) {
    // The side this point is on: its marker-frame coordinate nearest +-half the line.
    const double half = r.marker.tag_size * (s / 2 - 1) / s;
    const bool vertical = std::abs(std::abs(e.object.x) - half) < 1e-9;
    const double sign = vertical ? (e.object.x > 0 ? 1 : -1) : (e.object.y > 0 ? 1 : -1);
    const cv::Point3d a = vertical ? cv::Point3d(sign * half, -half, 0) : cv::Point3d(-half, sign * half, 0);
    const cv::Point3d b = vertical ? cv::Point3d(sign * half, half, 0) : cv::Point3d(half, sign * half, 0);
    const std::vector<cv::Point2d> ends = kCamera.project({a, b}, r.marker.rvec, r.marker.tvec);
    const cv::Point2d d = (ends[1] - ends[0]) / cv::norm(ends[1] - ends[0]);
    cv::Point2d normal(-d.y, d.x);
    if ((centre - ends[0]).dot(normal) < 0) normal = -normal;
    out.push_back((e.observed - ends[0]).dot(normal));
  }
  return out;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

TEST(BorderEdges, PointsLieOnTheStrokesCentreLine) {
  // 3x3, 4x4 and 6x6 markers of 2 to 8 px a unit, sharp and defocused by 1.2 and 2.4 px:
  // nearly every sampled point is kept, each within 0.15 px of its side's true centre
  // line (pixel quantisation at 2 px a unit), their median within 0.02 px, and their
  // scatter is measured. Defocused by 1.15 units (2.4 px at 2 px a unit), the stroke is
  // not used: the squares' blurred ink reaches into it. The bound lies between a blur of
  // 0.6 and 0.85 units (the pixel's own size adds to the blur the stroke shows).
  std::mt19937_64 rng(11);
  for (const int n : {3, 4, 6})
    for (const double pixels : {50.0, 90.0, 200.0})
      for (const double defocus : {0.0, 1.2, 2.4}) {
        Look look;
        look.defocus = defocus;
        const RenderedMarker r = render_marker(kCamera, n, pixels * (n + 1) / 4, look, rng);
        const BorderEdges edges =
            border_edges(ImageView(r.image), kCamera, r.marker.family, r.homography, r.marker.tag_size);
        const double blur = defocus / (pixels / 24);  // units
        if (blur > 0.85) {
          EXPECT_TRUE(edges.points.empty() && edges.sides.empty()) << n << "x" << n << " " << pixels << " px";
          continue;
        }
        if (blur > 0.6) continue;
        const std::vector<double> d = offsets(r, edges);
        const int sampled = 4 * std::min(16, r.marker.family.side() - 7);
        EXPECT_GE(int(d.size()), sampled * 9 / 10) << n << "x" << n << " " << pixels << " px";
        for (const double v : d) EXPECT_LT(std::abs(v), 0.15) << n << "x" << n << " " << pixels << " px";
        EXPECT_LT(std::abs(median(d)), 0.02) << n << "x" << n << " " << pixels << " px";
        EXPECT_GT(edges.noise, 0);
        EXPECT_LT(edges.noise, 0.05);
        for (const detail::EdgePoint& e : edges.points) EXPECT_NEAR(cv::norm(e.normal), 1, 1e-9);
        // Two points stand for each side's, on the true centre line too.
        EXPECT_EQ(edges.sides.size(), 8u);
        double stood_for = 0;
        for (const detail::EdgePoint& e : edges.sides) stood_for += e.weight;
        EXPECT_EQ(stood_for, double(d.size()));
        for (const double v : offsets(r, BorderEdges{edges.sides, {}, 0})) EXPECT_LT(std::abs(v), 0.08);
      }
}

TEST(BorderEdges, AToneCurveUnderDefocusDoesNotMoveThem) {
  // A gamma of 0.5, 1 and 2 on 150 px markers defocused by 1 px: the stroke stays
  // centred where the edges on either side of it move apart or together (a tone curve
  // makes a blurred edge's rise asymmetric), so the pose's scale does not change with
  // the exposure.
  std::mt19937_64 rng(13);
  for (const double gamma : {0.5, 1.0, 2.0})
    for (int k = 0; k < 6; ++k) {
      Look look;
      look.defocus = 1, look.gamma = gamma;
      const RenderedMarker r = render_marker(kCamera, 3 + k % 2, 150, look, rng);
      const BorderEdges edges =
          border_edges(ImageView(r.image), kCamera, r.marker.family, r.homography, r.marker.tag_size);
      const std::vector<double> d = offsets(r, edges);
      ASSERT_GT(d.size(), 40u) << gamma;
      EXPECT_LT(std::abs(median(d)), 0.03) << "gamma " << gamma;
    }
}

TEST(BorderEdges, TheSquaresBlurredInDoNotPullTheStrokeInwards) {
  // 3x3 markers of 4 px a unit on a six-unit margin, defocused by half a unit: the
  // squares two units inside the stroke darken the paper beside it, a margin this wide
  // does not. The centroid of the whole profile (a unit of paper either side) put these
  // markers' points 0.0045 to 0.009 units inwards on average; the window centred on the
  // stroke keeps each marker's mean within 0.002 units.
  std::mt19937_64 rng(23);
  constexpr double kPixelsPerUnit = 4;
  for (int k = 0; k < 12; ++k) {
    Look look;
    look.defocus = 0.5 * kPixelsPerUnit, look.margin_units = 6;
    const RenderedMarker r = render_marker(kCamera, 3, 24 * kPixelsPerUnit, look, rng);
    const BorderEdges edges =
        border_edges(ImageView(r.image), kCamera, r.marker.family, r.homography, r.marker.tag_size);
    const std::vector<double> d = offsets(r, edges);
    ASSERT_GT(d.size(), 40u) << k;
    double mean = 0;  // units
    for (const double v : d) mean += v / kPixelsPerUnit / double(d.size());
    EXPECT_LT(std::abs(mean), 0.002) << k;
  }
}

TEST(BorderEdges, NoneWithoutAWhiteMarginOrForASmallMarker) {
  std::mt19937_64 rng(17);
  // Printed without a margin on a dark table: one side of the stroke is not paper.
  Look dark;
  dark.margin_units = 0, dark.background = 0.06;
  const RenderedMarker bare = render_marker(kCamera, 3, 100, dark, rng);
  EXPECT_TRUE(border_edges(ImageView(bare.image), kCamera, bare.marker.family, bare.homography, 0.1).points.empty());
  // The same marker with its margin.
  Look margin = dark;
  margin.margin_units = 2;
  const RenderedMarker printed = render_marker(kCamera, 3, 100, margin, rng);
  EXPECT_GT(
      border_edges(ImageView(printed.image), kCamera, printed.marker.family, printed.homography, 0.1).points.size(),
      50u);
  // 3x3 at 26 px across: about 1.1 px per unit, under the cell centroids' 1.25.
  const RenderedMarker small = render_marker(kCamera, 3, 26, Look{}, rng);
  EXPECT_TRUE(border_edges(ImageView(small.image), kCamera, small.marker.family, small.homography, 0.1).points.empty());
  // A homography that is not finite.
  const double nan = std::nan("");
  EXPECT_TRUE(border_edges(ImageView(printed.image), kCamera, printed.marker.family,
                           cv::Matx33d(nan, 0, 0, 0, 1, 0, 0, 0, 1), 0.1)
                  .points.empty());
}

TEST(BorderEdges, AnOccluderOverOneSideLosesOnlyItsPoints) {
  // A dark bar across half of one side's stroke and its margin: the points under it are
  // dropped (no paper beside the stroke there), the rest stay on the line.
  std::mt19937_64 rng(19);
  RenderedMarker r = render_marker(kCamera, 4, 150, Look{}, rng);
  const BorderEdges whole = border_edges(ImageView(r.image), kCamera, r.marker.family, r.homography, 0.1);
  const double s = r.marker.family.side();
  std::vector<cv::Point> bar;
  for (const cv::Point2d u :
       {cv::Point2d(-3, -3), cv::Point2d(s / 2, -3), cv::Point2d(s / 2, 2.5), cv::Point2d(-3, 2.5)}) {
    const cv::Vec3d p = r.homography * cv::Vec3d(u.x, u.y, 1);
    bar.emplace_back(int(std::lround(p[0] / p[2])), int(std::lround(p[1] / p[2])));
  }
  cv::fillConvexPoly(r.image, bar, cv::Scalar(20));
  const BorderEdges cut = border_edges(ImageView(r.image), kCamera, r.marker.family, r.homography, 0.1);
  EXPECT_LT(cut.points.size(), whole.points.size() - 6);
  EXPECT_GT(cut.points.size(), whole.points.size() - 12);
  for (const double v : offsets(r, cut)) EXPECT_LT(std::abs(v), 0.1);
}
