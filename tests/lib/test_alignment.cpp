// SPDX-License-Identifier: LGPL-2.1-or-later
// The outline reading's alignment (src/detect/alignment.cpp): it must take the steps that
// cv::findTransformECC takes, ending where it ends and failing where it fails.
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "stages.hpp"

using namespace lftag::detail;

namespace {

// A template of blobs and bars on white, like a marker's structure: `side` pixels square.
cv::Mat1f blob_template(int side, std::mt19937_64& rng) {
  cv::Mat1f t(side, side, 1.0f);
  std::uniform_int_distribution<int> at(side / 8, side - side / 8), size(side / 16, side / 6);
  cv::rectangle(t, cv::Rect(side / 10, side / 10, side - side / 5, side - side / 5), 0.0f, std::max(2, side / 16));
  for (int i = 0; i < 9; ++i) {
    const int s = size(rng);
    cv::rectangle(t, cv::Rect(at(rng) - s / 2, at(rng) - s / 2, s, s), 0.0f, cv::FILLED);
  }
  cv::GaussianBlur(t, t, cv::Size(0, 0), 1.2);
  return t;
}

// A homography (template -> image) that puts the template at `scale` pixels per template
// pixel near the image's centre, tilted and turned at random.
cv::Matx33f random_warp(int side, cv::Size image, double scale, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<cv::Point2f> from = {{0, 0}, {float(side), 0}, {float(side), float(side)}, {0, float(side)}}, to;
  const double half = scale * side / 2, turn = u(rng) * CV_PI;
  for (int i = 0; i < 4; ++i) {
    const double a = turn + i * CV_PI / 2;
    const double r = half * std::sqrt(2.0) * (1 + 0.2 * u(rng));
    to.emplace_back(float(image.width / 2.0 + r * std::cos(a)), float(image.height / 2.0 + r * std::sin(a)));
  }
  return cv::Matx33f(cv::Mat_<float>(cv::getPerspectiveTransform(from, to)));
}

cv::Point2d apply(const cv::Matx33f& h, cv::Point2d p) {
  const cv::Vec3d q = cv::Matx33d(h) * cv::Vec3d(p.x, p.y, 1);
  return {q[0] / q[2], q[1] / q[2]};
}

// The start of a trial: the true warp's corners moved by up to `jitter` pixels.
cv::Matx33f jittered(const cv::Matx33f& truth, int side, double jitter, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-jitter, jitter);
  std::vector<cv::Point2f> from = {{0, 0}, {float(side), 0}, {float(side), float(side)}, {0, float(side)}}, to;
  for (const cv::Point2f& f : from) {
    const cv::Point2d p = apply(truth, f);
    to.emplace_back(float(p.x + u(rng)), float(p.y + u(rng)));
  }
  return cv::Matx33f(cv::Mat_<float>(cv::getPerspectiveTransform(from, to)));
}

const cv::TermCriteria kCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 25, 1e-4);

std::optional<double> opencv_ecc(const cv::Mat1f& templ, const cv::Mat1f& image, cv::Matx33f& warp) {
  cv::Mat w(warp);
  try {
    const double c = cv::findTransformECC(templ, image, w, cv::MOTION_HOMOGRAPHY, kCriteria, cv::noArray(), 3);
    warp = cv::Matx33f(w);
    return c;
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
}

}  // namespace

// Templates warped into noisy images, some of them reaching beyond the image's edges, each
// alignment started up to 3 pixels off: both alignments end on the same warp (to 0.01 px
// at the template's corners) with the same correlation (to 1e-4, the change at which both stop).
TEST(Alignment, TakesTheStepsOfOpenCvsEcc) {
  std::mt19937_64 rng(7);
  std::normal_distribution<float> noise(0, 0.03f);
  for (int trial = 0; trial < 40; ++trial) {
    const int side = 40 + 10 * (trial % 4);
    const cv::Mat1f templ = blob_template(side, rng);
    const cv::Size size(int(side * 1.8), int(side * 1.6));
    const cv::Matx33f truth = random_warp(side, size, 1.0 + 0.5 * (trial % 3), rng);
    cv::Mat1f image;
    cv::warpPerspective(templ, image, cv::Mat(truth), size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 1.0);
    cv::Mat1f n(image.size());
    for (float& v : n) v = noise(rng);
    image += n;
    const cv::Matx33f start = jittered(truth, side, 3, rng);
    cv::Matx33f want = start, warp = start;
    const std::optional<double> expected = opencv_ecc(templ, image, want);
    const std::optional<double> got = EccAlignment(image).align(templ, warp, 25, 1e-4);
    ASSERT_TRUE(expected && got) << "trial " << trial;
    EXPECT_GT(*got, 0.9) << "trial " << trial;
    EXPECT_GT(*got, 0.95) << "trial " << trial;
    EXPECT_NEAR(*got, *expected, 1e-4) << "trial " << trial;
    for (const cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(side, 0), cv::Point2d(side, side), cv::Point2d(0, side)})
      EXPECT_LT(cv::norm(apply(warp, p) - apply(want, p)), 0.01) << "trial " << trial;
  }
}

// Images that do not hold the template (noise, or another template): where OpenCV's
// alignment gives up, this one gives up too. Their paths may part after a few steps (with
// nothing to converge to, float rounding decides them), so the first step must agree
// always and the whole alignment's outcome nearly always.
TEST(Alignment, FailsWhereOpenCvsEccFails) {
  std::mt19937_64 rng(13);
  std::normal_distribution<float> noise(0, 0.2f);
  int both_failed = 0, agreed = 0;
  const int trials = 40;
  for (int trial = 0; trial < trials; ++trial) {
    const int side = 40 + 10 * (trial % 4);
    const cv::Mat1f templ = blob_template(side, rng);
    const cv::Size size(int(side * 1.8), int(side * 1.6));
    cv::Mat1f image(size, 0.5f);
    if (trial % 2 == 0) {
      cv::warpPerspective(blob_template(side, rng), image, cv::Mat(random_warp(side, size, 1.0, rng)), size,
                          cv::INTER_LINEAR, cv::BORDER_CONSTANT, 1.0);
    } else {
      for (float& v : image) v += noise(rng);
    }
    const cv::Matx33f start = random_warp(side, size, 1.0, rng);
    cv::Matx33f want = start, warp = start;
    const std::optional<double> expected = opencv_ecc(templ, image, want);
    const std::optional<double> got = EccAlignment(image).align(templ, warp, 25, 1e-4);
    both_failed += !expected && !got;
    agreed += bool(expected) == bool(got);

    cv::Mat first_warp(start);
    bool first = true;
    try {
      cv::findTransformECC(templ, image, first_warp, cv::MOTION_HOMOGRAPHY,
                           cv::TermCriteria(cv::TermCriteria::COUNT, 1, 0), cv::noArray(), 3);
    } catch (const cv::Exception&) {
      first = false;
    }
    cv::Matx33f our_first = start;
    EXPECT_EQ(first, bool(EccAlignment(image).align(templ, our_first, 1, 0))) << "trial " << trial;
  }
  EXPECT_GT(both_failed, trials / 4);
  EXPECT_GE(agreed, trials * 9 / 10);
}

// The image's edges: a template that the warp puts partly outside the image is aligned on
// the part inside, as OpenCV's masked alignment does.
TEST(Alignment, AlignsATemplatePartlyOutsideTheImage) {
  std::mt19937_64 rng(11);
  const int side = 48;
  const cv::Mat1f templ = blob_template(side, rng);
  const cv::Size size(60, 60);
  cv::Matx33f truth = cv::Matx33f::eye();
  truth(0, 2) = 20, truth(1, 2) = 4;  // the template's right third lies beyond the image
  cv::Mat1f image;
  cv::warpPerspective(templ, image, cv::Mat(truth), size, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 1.0);
  cv::Matx33f start = truth;
  start(0, 2) += 1.5f, start(1, 2) -= 1.0f;
  cv::Mat expected_warp(start);
  const double expected =
      cv::findTransformECC(templ, image, expected_warp, cv::MOTION_HOMOGRAPHY, kCriteria, cv::noArray(), 3);
  cv::Matx33f warp = start;
  const std::optional<double> got = EccAlignment(image).align(templ, warp, 25, 1e-4);
  ASSERT_TRUE(got);
  EXPECT_NEAR(*got, expected, 1e-4);
  const cv::Matx33f want(expected_warp);
  for (const cv::Point2d p : {cv::Point2d(0, 0), cv::Point2d(side, side)})
    EXPECT_LT(cv::norm(apply(warp, p) - apply(want, p)), 0.02);
  EXPECT_LT(cv::norm(apply(warp, {0, 0}) - apply(truth, {0, 0})), 0.2);
}
