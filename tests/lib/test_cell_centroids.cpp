// SPDX-License-Identifier: LGPL-2.1-or-later
// Cell centroids for the final pose (src/detect/cell_centroids.cpp): each square's ink
// over its window under the decoded homography, on rendered markers with known truth.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "lftag/detector.hpp"
#include "lftag/render.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::cell_centroids;
using lftag::test::random_id;
using lftag::test::rotation;

namespace {

const Camera kCamera = Camera::pinhole(800, 800, 319.5, 239.5, 640, 480);

using Rendered = lftag::test::RenderedMarker;

// A marker `pixels` across at a random turn, tilt (up to 30 degrees) and sub-pixel place,
// defocused by `defocus` px and lit by a gradient of `gradient` across the frame.
Rendered render(int n, double pixels, double defocus, double gradient, std::mt19937_64& rng, cv::Point2d at = {0, 0}) {
  test::Look look;
  look.defocus = defocus, look.gradient = gradient, look.at = at;
  return test::render_marker(kCamera, n, pixels, look, rng);
}

// Mean over the outer cells of each centroid's error along the direction from the
// marker's centre: negative when the centroids are pulled inwards.
double mean_radial_error(const MarkerTruth& truth, const std::vector<cv::Point2d>& found) {
  const int n = truth.family.n();
  double sum = 0;
  int count = 0;
  for (int g = 0; g < n * n; ++g) {
    const int r = g / n, c = g % n;
    if (r != 0 && c != 0 && r != n - 1 && c != n - 1) continue;
    const cv::Point2d out = truth.centroids[g] - truth.center;
    sum += (found[g] - truth.centroids[g]).dot(out) / cv::norm(out);
    ++count;
  }
  return sum / count;
}

}  // namespace

TEST(CellCentroids, DefocusDoesNotPullTheSquaresInwards) {
  // 60 px markers under a defocus of 1.2 px: the blob centroids that decoding uses come
  // out about 0.05 px inwards (the marker looks 0.3 % smaller and the pose puts it that
  // much too far); the cells' windows put each square within 0.15 px of the truth and no
  // nearer the centre on average, under the true homography and the decoded one, and
  // the detector's distance is right within 0.05 % on average.
  std::mt19937_64 rng(3);
  for (int n : {3, 4}) {
    double cells = 0, detected = 0, blobs = 0, depth = 0;
    const int markers = 12;
    for (int k = 0; k < markers; ++k) {
      const Rendered r = render(n, 60, 1.2, 0, rng);
      const std::vector<cv::Point2d> found =
          cell_centroids(ImageView(r.image), kCamera, r.marker.family, r.marker.id, r.homography);
      ASSERT_EQ(found.size(), std::size_t(n * n));
      for (int g = 0; g < n * n; ++g) EXPECT_LT(cv::norm(found[g] - r.truth.centroids[g]), 0.15) << n << " cell " << g;
      cells += mean_radial_error(r.truth, found) / markers;

      // The detector's own blob centroids, from its trace, for the comparison.
      DetectorParams params;
      params.families = {r.marker.family};
      params.camera = kCamera;
      Detector detector(params);
      DetectionTrace trace;
      const std::vector<Detection> detections = detector.detect(ImageView(r.image), nullptr, &trace);
      ASSERT_EQ(detections.size(), 1u);
      EXPECT_EQ(detections[0].id, r.marker.id);
      // Its centroids are the cells', under the homography it decoded.
      for (int g = 0; g < n * n; ++g) EXPECT_LT(cv::norm(detections[0].centroids[g] - r.truth.centroids[g]), 0.15);
      detected += mean_radial_error(r.truth, detections[0].centroids) / markers;
      depth += (cv::norm(detections[0].tvec) / cv::norm(r.marker.tvec) - 1) / markers;
      std::vector<cv::Point2d> nearest;  // the trace's blobs in grid order
      for (int g = 0; g < n * n; ++g) {
        cv::Point2d best = trace.candidates.at(0).at(0);
        for (const cv::Point2d& b : trace.candidates[0])
          if (cv::norm(b - r.truth.centroids[g]) < cv::norm(best - r.truth.centroids[g])) best = b;
        nearest.push_back(best);
      }
      blobs += mean_radial_error(r.truth, nearest) / markers;
    }
    EXPECT_LT(std::abs(cells), 0.01) << n << "x" << n;
    EXPECT_LT(std::abs(detected), 0.01) << n << "x" << n;
    EXPECT_LT(std::abs(depth), 5e-4) << n << "x" << n << ": the pose's distance, relative";
    EXPECT_LT(blobs, -0.025) << n << "x" << n << ": the set-up no longer shows the blobs' bias";
  }
}

TEST(CellCentroids, UnevenLightDoesNotMoveThem) {
  // Light varying by 80 % across the frame (at any angle): each window's paper level is
  // its own, so the darker side of a square's ring weighs nothing.
  std::mt19937_64 rng(5);
  for (int n : {3, 4})
    for (int k = 0; k < 8; ++k) {
      const Rendered r = render(n, 80, 0.6, 0.8, rng);
      const std::vector<cv::Point2d> found =
          cell_centroids(ImageView(r.image), kCamera, r.marker.family, r.marker.id, r.homography);
      ASSERT_EQ(found.size(), std::size_t(n * n));
      for (int g = 0; g < n * n; ++g) EXPECT_LT(cv::norm(found[g] - r.truth.centroids[g]), 0.08) << n << " cell " << g;
      EXPECT_LT(std::abs(mean_radial_error(r.truth, found)), 0.03);
    }
}

TEST(CellCentroids, EveryOtherRowAndColumnFindsTheSquaresNearlyWhereAllDo) {
  // A coarse look (stride 2) weighs a quarter of the pixels: its centroids lie within
  // 0.1 units of the full look's on 2 to 4 px-a-unit markers, close enough to centre the
  // narrower windows that measure them, and its paper level is the same.
  std::mt19937_64 rng(9);
  for (int n : {3, 4, 6})
    for (const double pixels : {2.0 * (6 * n + 6), 4.0 * (6 * n + 6)}) {
      const Rendered r = render(n, pixels, 0.6, 0.3, rng);
      std::vector<detail::CellInk> all_inks, coarse_inks;
      const auto all = cell_centroids(ImageView(r.image), kCamera, r.marker.family, r.marker.id, r.homography, {},
                                      &all_inks, 1, 0.5, 1);
      const auto coarse = cell_centroids(ImageView(r.image), kCamera, r.marker.family, r.marker.id, r.homography, {},
                                         &coarse_inks, 1, 0.5, 2);
      ASSERT_EQ(all.size(), std::size_t(n * n));
      ASSERT_EQ(coarse.size(), all.size());
      const double unit = pixels / (6 * n + 6);
      for (int g = 0; g < n * n; ++g) {
        EXPECT_LT(cv::norm(coarse[g] - all[g]), 0.1 * unit) << n << " " << pixels << " cell " << g;
        EXPECT_NEAR(coarse_inks[g].mass / all_inks[g].mass, 0.25, 0.05) << n << " " << pixels << " cell " << g;
        EXPECT_NEAR(coarse_inks[g].paper, all_inks[g].paper, 3) << n << " " << pixels << " cell " << g;
      }
    }
}

TEST(CellCentroids, TheWindowsFollowTheLensDistortion) {
  // Strong barrel distortion, 70 px markers towards the frame's corners, where it bends
  // their squares' places by pixels: the windows, placed under the homography of the
  // undistorted corners and distorted as the lens does, still put each square within
  // 0.15 px of the truth.
  Camera camera = kCamera;
  camera.distortion = {-0.25, 0.08, 0.001, -0.001, 0};
  std::mt19937_64 rng(11);
  for (int n : {3, 4})
    for (const cv::Point2d at : {cv::Point2d(-190, -130), cv::Point2d(190, 130), cv::Point2d(-190, 130)}) {
      const Rendered r = test::render_marker(camera, n, 70, test::Look{0.6, 0, 1, 0.45, 2, at}, rng);
      const std::vector<cv::Point2d> corners = camera.undistort({r.truth.corners.begin(), r.truth.corners.end()});
      const double s = r.marker.family.side();
      const std::vector<cv::Point2f> units{{0, 0}, {float(s), 0}, {float(s), float(s)}, {0, float(s)}};
      const cv::Matx33d homography(
          cv::getPerspectiveTransform(units, std::vector<cv::Point2f>(corners.begin(), corners.end())));
      const std::vector<cv::Point2d> found =
          cell_centroids(ImageView(r.image), camera, r.marker.family, r.marker.id, homography);
      ASSERT_EQ(found.size(), std::size_t(n * n)) << n << "x" << n << " at " << at;
      for (int g = 0; g < n * n; ++g)
        EXPECT_LT(cv::norm(found[g] - r.truth.centroids[g]), 0.15) << n << "x" << n << " at " << at << ", cell " << g;
    }
}

TEST(CellCentroids, NoneForASmallMarkerOrAWindowOutsideTheFrame) {
  std::mt19937_64 rng(7);
  // 3x3 at 26 px across: about 1.1 px per unit, where the window's pixels are too few.
  const Rendered small = render(3, 26, 0, 0, rng);
  EXPECT_TRUE(
      cell_centroids(ImageView(small.image), kCamera, small.marker.family, small.marker.id, small.homography).empty());
  // 44 px: read.
  const Rendered fair = render(3, 44, 0, 0, rng);
  EXPECT_EQ(cell_centroids(ImageView(fair.image), kCamera, fair.marker.family, fair.marker.id, fair.homography).size(),
            9u);
  // A marker whose squares' windows reach past the frame's edge.
  const Rendered edge = render(3, 80, 0, 0, rng, {-300, 0});
  EXPECT_TRUE(
      cell_centroids(ImageView(edge.image), kCamera, edge.marker.family, edge.marker.id, edge.homography).empty());
  // A homography that is not finite.
  const double nan = std::nan("");
  EXPECT_TRUE(cell_centroids(ImageView(fair.image), kCamera, fair.marker.family, fair.marker.id,
                             cv::Matx33d(nan, 0, 0, 0, 1, 0, 0, 0, 1))
                  .empty());
}

TEST(CellCentroids, AShadowAcrossTheMarkerDoesNotMoveThemWithThePaperUnderIt) {
  // A hard shadow (0.45 of the light, a 2 px penumbra) across the middle of a 100 px
  // marker at any angle: the squares and paper it darkens are weighed against the paper
  // under them (the closed level that paper_under gives a candidate whose light varies).
  // Against the ring's one median, the shadowed paper round a square near the shadow's
  // edge counts as ink and pulls its centroid (0.49 px on average here, against 0.11).
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1, 1);
  double near_local = 0, near_ring = 0, far_worst = 0;
  int near = 0;
  for (int n : {3, 4})
    for (int k = 0; k < 6; ++k) {
      Rendered r = render(n, 100, 0.6, 0, rng);
      // The same marker rendered again in shadow: the linear image times the light.
      SceneParams p;
      p.camera = kCamera;
      p.background = 0.45;
      p.noise_sigma = 1;
      const SceneRenderer renderer(p);
      cv::Mat1f linear = renderer.render_linear({to_target(r.marker)});
      cv::GaussianBlur(linear, linear, cv::Size(), 0.6);
      const double angle = CV_PI * u(rng);
      const cv::Point2d normal(std::cos(angle), std::sin(angle));
      const double offset = 6 * u(rng);  // px from the marker's centre
      const auto from_edge = [&](cv::Point2d q) { return (q - r.truth.center).dot(normal) - offset; };
      for (int y = 0; y < linear.rows; ++y)
        for (int x = 0; x < linear.cols; ++x)
          linear(y, x) *= float(0.45 + 0.55 * std::clamp(0.5 + from_edge(cv::Point2d(x, y)) / 2, 0.0, 1.0));
      r.image = renderer.quantize(linear, rng());
      const double per_unit = 100.0 / r.marker.family.side();
      detail::PaperLevel paper(255);
      paper.local = detail::paper_level(r.image, int(std::ceil(3 * per_unit * 1.3)) + 2);  // wider than a square
      const ImageView view(r.image);
      const std::vector<cv::Point2d> local =
          cell_centroids(view, kCamera, r.marker.family, r.marker.id, r.homography, paper);
      const std::vector<cv::Point2d> ring = cell_centroids(view, kCamera, r.marker.family, r.marker.id, r.homography);
      ASSERT_EQ(local.size(), std::size_t(n * n));
      ASSERT_EQ(ring.size(), std::size_t(n * n));
      for (int g = 0; g < n * n; ++g) {
        const double local_error = cv::norm(local[g] - r.truth.centroids[g]);
        if (std::abs(from_edge(r.truth.centroids[g])) < 2.5 * per_unit) {  // its window meets the edge
          near_local += local_error, near_ring += cv::norm(ring[g] - r.truth.centroids[g]), ++near;
        } else {
          far_worst = std::max(far_worst, local_error);
        }
      }
    }
  ASSERT_GT(near, 20);
  EXPECT_LT(near_local / near, 0.15);
  EXPECT_LT(near_local, 0.4 * near_ring);
  EXPECT_GT(near_ring / near, 0.3) << "the set-up no longer shows the ring's bias";
  EXPECT_LT(far_worst, 0.15);  // the ring's own there: 0.16
}
