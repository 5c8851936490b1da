// SPDX-License-Identifier: LGPL-2.1-or-later
// A tracked marker measured where its track predicts it (src/detect/tracked.cpp): from
// the grey levels under the predicted outline, on rendered markers with known truth.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "lftag/detector.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::measure_tracked;

namespace {

const Camera kCamera = Camera::pinhole(800, 800, 319.5, 239.5, 640, 480);

// A sharp marker, a little defocused, `pixels` across.
test::RenderedMarker render(int n, double pixels, std::mt19937_64& rng) {
  test::Look look;
  look.defocus = 0.6;
  return test::render_marker(kCamera, n, pixels, look, rng);
}

// The marker's outline moved by `by` pixels: where a track might predict it.
std::array<cv::Point2d, 4> outline(const test::RenderedMarker& r, cv::Point2d by) {
  std::array<cv::Point2d, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = r.truth.corners[std::size_t(k)] + by;
  return out;
}

std::optional<detail::TrackedMeasurement> measure(const test::RenderedMarker& r, TagId id, cv::Point2d by,
                                                  const cv::Mat1b& image) {
  DetectorParams params;
  params.families = {r.marker.family};
  params.camera = kCamera;
  params.tag_size = r.marker.tag_size;
  DetectionStats stats;
  return measure_tracked(ImageView(image), kCamera, params, r.marker.family, id, outline(r, by), stats);
}

// Every square's measured centroid within `pixels` of the truth.
void expect_centroids_within(const detail::TrackedMeasurement& m, const test::RenderedMarker& r, double pixels) {
  const int n = r.marker.family.n();
  for (int g = 0; g < n * n; ++g)
    EXPECT_LT(cv::norm(m.candidate.blobs[g].centroid - r.truth.centroids[g]), pixels) << n << " cell " << g;
}

// A random direction `length` long.
cv::Point2d step(double length, std::mt19937_64& rng) {
  const double a = std::uniform_real_distribution<double>(0, 2 * CV_PI)(rng);
  return {length * std::cos(a), length * std::sin(a)};
}

}  // namespace

TEST(TrackedMeasurement, FindsTheSquaresFromAPredictionAUnitOff) {
  // The windows first reach a unit round each square: a prediction that far off still
  // finds every square, and the outline settles on them within 0.15 px of the truth.
  std::mt19937_64 rng(5);
  for (int n : {3, 4}) {
    int measured = 0;
    const int markers = 12;
    for (int k = 0; k < markers; ++k) {
      const test::RenderedMarker r = render(n, 90, rng);
      const double unit = 90.0 / r.marker.family.side();
      const auto m = measure(r, r.marker.id, step(0.9 * unit, rng), r.image);
      if (!m) continue;
      ++measured;
      EXPECT_EQ(m->decoding.id, r.marker.id);
      expect_centroids_within(*m, r, 0.15);
      EXPECT_EQ(m->edges.sides.size(), 8u);
    }
    EXPECT_EQ(measured, markers) << n;
  }
}

TEST(TrackedMeasurement, NothingIsMeasuredWhereNoMarkerIs) {
  // On bare background every window's centroid is its centre, a perfect grid of the
  // expected id: the decoding refuses it (its error weighs the residuals against the
  // gradient along the border's inner edge, and there is none).
  std::mt19937_64 rng(6);
  for (int k = 0; k < 12; ++k) {
    const test::RenderedMarker r = render(3, 90, rng);
    EXPECT_FALSE(measure(r, r.marker.id, {0, 150}, r.image).has_value()) << k;
  }
}

TEST(TrackedMeasurement, AnotherIdIsNotTaken) {
  // Expected with one data cell's digit changed: that square is found where it is, a
  // unit from where the expected id puts it, and the id read is the marker's own.
  std::mt19937_64 rng(7);
  for (int n : {3, 4})
    for (int k = 0; k < 12; ++k) {
      const test::RenderedMarker r = render(n, 90, rng);
      const int cell = int(rng() % std::uint64_t(r.marker.family.data_cell_count()));
      const TagId other = r.marker.id.with_digit(cell, (r.marker.id.digit(cell) + 1 + int(rng() % 3)) % 4);
      EXPECT_FALSE(measure(r, other, {0, 0}, r.image).has_value()) << n << ", marker " << k;
    }
}

TEST(TrackedMeasurement, ACoveredSquareIsNotMeasured) {
  // A square painted over with the paper's grey (a finger, glare): its window finds no
  // square where the id puts one, and the patch's search is left to say what is there.
  std::mt19937_64 rng(8);
  for (int k = 0; k < 12; ++k) {
    test::RenderedMarker r = render(3, 90, rng);
    ASSERT_TRUE(measure(r, r.marker.id, {0, 0}, r.image).has_value()) << "the set-up: " << k;
    const int g = int(rng() % 9);
    const cv::Point2d c = r.truth.centers[std::size_t(g)];
    const cv::Rect around(cv::Point(int(c.x) - 12, int(c.y) - 12), cv::Size(24, 24));
    double paper = 0;
    cv::minMaxLoc(r.image(around), nullptr, &paper);
    cv::circle(r.image, cv::Point(c), 7, cv::Scalar(paper), cv::FILLED);
    EXPECT_FALSE(measure(r, r.marker.id, {0, 0}, r.image).has_value()) << k << ", square " << g;
  }
}

TEST(TrackedMeasurement, AShadowAcrossTheMarkerIsLeftToTheSearch) {
  // A shadow's edge across the marker, light enough (0.8) that the squares on both sides
  // still decode: the paper round them differs by more than even light allows, and only
  // the search's paper level under each pixel keeps the shadowed squares' centroids
  // where they are.
  std::mt19937_64 rng(9);
  for (int k = 0; k < 12; ++k) {
    test::RenderedMarker r = render(3, 90, rng);
    ASSERT_TRUE(measure(r, r.marker.id, {0, 0}, r.image).has_value()) << "the set-up: " << k;
    const int edge = int(r.truth.center.x);
    cv::Mat1b shaded = r.image.colRange(edge, r.image.cols);
    shaded.convertTo(shaded, -1, 0.8);
    EXPECT_FALSE(measure(r, r.marker.id, {0, 0}, r.image).has_value()) << k;
  }
}

TEST(TrackedMeasurement, AMotionBlurredMarkerSettles) {
  // Smeared along its motion by 2 to 3 units, more than the windows' margin round each
  // square, and predicted 0.9 unit off: a window clips its square's smear, so each refit
  // moves the squares only part of the way, and they settle in four to six refits. A
  // smear is even about its square's centre, so the centroids settled on stay true.
  std::mt19937_64 rng(10);
  for (int n : {3, 4}) {
    int measured = 0;
    const int markers = 12;
    for (int k = 0; k < markers; ++k) {
      test::RenderedMarker r = render(n, 90, rng);
      const double unit = 90.0 / r.marker.family.side();
      const double length = std::uniform_real_distribution<double>(2.0, 3.0)(rng) * unit;
      const double angle = std::uniform_real_distribution<double>(0, 180)(rng);
      cv::filter2D(r.image, r.image, -1, motion_blur_kernel(length, angle), cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
      const auto m = measure(r, r.marker.id, step(0.9 * unit, rng), r.image);
      if (!m) continue;
      ++measured;
      expect_centroids_within(*m, r, 0.3);
    }
    EXPECT_EQ(measured, markers) << n;
  }
}
