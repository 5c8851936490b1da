// SPDX-License-Identifier: LGPL-2.1-or-later
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/render.hpp"
#include "scenes.hpp"

using namespace lftag;
using lftag::test::rotation;

namespace {

// Darkness-weighted centroid of square g, over its projected footprint grown by 1 u.
cv::Point2d measured_centre(const cv::Mat1f& image, float white, const Camera& cam, const SceneMarker& m, int g) {
  const UnitRect s = m.family.black_squares(m.id)[g];
  std::vector<cv::Point3d> corners;
  for (const cv::Point2d& u :
       {cv::Point2d(s.x - 1, s.y - 1), cv::Point2d(s.x + s.width + 1, s.y - 1),
        cv::Point2d(s.x + s.width + 1, s.y + s.height + 1), cv::Point2d(s.x - 1, s.y + s.height + 1)})
    corners.push_back(m.family.to_marker_frame(u, m.tag_size));
  std::vector<cv::Point> poly;
  for (const cv::Point2d& p : cam.project(corners, m.rvec, m.tvec))
    poly.emplace_back(cvRound(p.x * 16), cvRound(p.y * 16));
  cv::Mat1b mask(image.size(), uchar(0));
  cv::fillConvexPoly(mask, poly, 255, cv::LINE_8, 4);
  double w = 0, wx = 0, wy = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x)
      if (mask(y, x)) {
        const double d = std::max(0.0f, white - image(y, x));
        w += d, wx += d * x, wy += d * y;
      }
  return {wx / w, wy / w};
}

}  // namespace

TEST(Scene, TruthSitsOnTheRenderedCentroids) {
  // A 100 px marker, fronto-parallel and tilted, with and without lens distortion.
  struct Case {
    double roll, tilt, pan;
    bool distortion;
  };
  for (const Case& c :
       {Case{0, 0, 0, false}, Case{30, 40, 20, false}, Case{-70, 20, -35, false}, Case{10, 30, 0, true}}) {
    SceneParams p;
    p.camera = Camera::pinhole(500, 500, 319.5, 239.5, 640, 480);
    if (c.distortion) p.camera.distortion = {-0.2, 0.05, 0, 0, 0};
    p.supersample = 16;
    SceneMarker m;
    m.family = Family(3);
    m.id = 6789;
    m.tag_size = 0.2;
    m.tvec = {0.05, -0.03, 1.0};  // 100 px across
    m.rvec = rotation(c.roll, c.tilt, c.pan);
    const SceneRenderer renderer(p);
    const cv::Mat1f image = renderer.render_linear({to_target(m)});
    const MarkerTruth truth = make_truth(p.camera, m);
    EXPECT_TRUE(truth.fully_visible);
    EXPECT_LT(cv::norm(truth.center - p.camera.project({cv::Point3d(0, 0, 0)}, m.rvec, m.tvec)[0]), 1e-9);
    EXPECT_NEAR(truth.edge_px, 100.0, 15.0);
    const float white = 255.0f * m.white;
    for (int g = 0; g < m.family.cell_count(); ++g) {
      const cv::Point2d got = measured_centre(image, white, p.camera, m, g);
      EXPECT_NEAR(got.x, truth.centroids[g].x, 0.05) << "cell " << g << " roll " << c.roll << " tilt " << c.tilt;
      EXPECT_NEAR(got.y, truth.centroids[g].y, 0.05) << "cell " << g << " roll " << c.roll << " tilt " << c.tilt;
      // Centres and centroids differ only by the small perspective bias.
      EXPECT_LT(cv::norm(truth.centers[g] - truth.centroids[g]), c.tilt == 0 && c.pan == 0 ? 0.01 : 0.2);
    }
    for (int k = 0; k < 4; ++k) EXPECT_EQ(truth.keypoints[k], truth.centers[m.family.keypoint_cells()[k]]);
  }
}

TEST(Scene, CoverageOfAFrontoParallelMarkerIsItsArea) {
  SceneParams p;
  p.camera = Camera::pinhole(400, 400, 199.5, 149.5, 400, 300);
  p.background = 0.9;
  SceneMarker m;
  m.family = Family(4);
  m.id = 98765;
  m.tag_size = 0.5;
  m.tvec = {0.0123, 0.0456, 1.3};
  const cv::Mat1f image = SceneRenderer(p).render_linear({to_target(m)});
  const double px_per_unit = 400.0 * 0.5 / 1.3 / m.family.side();
  double black = 0;  // darkness / (white - black) = covered area in pixels
  for (float v : cv::Mat_<float>(image)) black += (255.0 * 0.9 - v) / (255.0 * (0.9 - 0.05));
  double area = 30.0 * 30 - 26.0 * 26;
  for (const UnitRect& r : m.family.black_squares(m.id)) area += r.width * r.height;
  EXPECT_NEAR(black / (px_per_unit * px_per_unit), area, 0.002 * area);
}

TEST(Scene, FarMarkersKeepTheirArea) {
  // The paper's set-up: 640x480, f = 320, a 1 m marker at 28 m is about 11 px wide.
  SceneParams p;
  p.camera = Camera::pinhole(320, 320, 319.5, 239.5, 640, 480);
  p.background = 0.9;
  p.supersample = 16;
  SceneMarker m;
  m.family = Family(3);
  m.id = 4321;
  m.tvec = {0.011, -0.007, 28};
  const cv::Mat1f image = SceneRenderer(p).render_linear({to_target(m)});
  const double px_per_unit = 320.0 / 28 / 24;
  double black = 0;
  for (float v : cv::Mat_<float>(image)) black += (255.0 * 0.9 - v) / (255.0 * (0.9 - 0.05));
  double area = 24.0 * 24 - 20.0 * 20;
  for (const UnitRect& r : m.family.black_squares(m.id)) area += r.width * r.height;
  EXPECT_NEAR(black / (px_per_unit * px_per_unit), area, 0.01 * area);
}

TEST(Scene, MotionBlurKernel) {
  const cv::Mat1f k = motion_blur_kernel(9.0, 90.0);  // horizontal
  EXPECT_NEAR(cv::sum(k)[0], 1.0, 1e-6);
  double mx = 0, my = 0, vx = 0, vy = 0;
  const int c = k.rows / 2;
  for (int y = 0; y < k.rows; ++y)
    for (int x = 0; x < k.cols; ++x) {
      mx += k(y, x) * (x - c), my += k(y, x) * (y - c);
      vx += k(y, x) * (x - c) * (x - c), vy += k(y, x) * (y - c) * (y - c);
    }
  EXPECT_NEAR(mx, 0, 1e-4);
  EXPECT_NEAR(my, 0, 1e-4);
  EXPECT_NEAR(vx, 81.0 / 12 + 1.0 / 6, 0.1);  // uniform segment plus the bilinear splat
  EXPECT_LT(vy, 0.2);
  EXPECT_EQ(motion_blur_kernel(0, 0).at<float>(1, 1), 1.0f);
}

TEST(Scene, NoiseBackgroundAndLight) {
  SceneParams p;
  p.camera = Camera::pinhole(300, 300, 99.5, 99.5, 200, 200);
  p.background = 0.5;
  p.noise_sigma = 5;
  p.seed = 3;
  const cv::Mat1b a = SceneRenderer(p).render({});
  cv::Scalar mean, sd;
  cv::meanStdDev(a, mean, sd);
  EXPECT_NEAR(mean[0], 127.5, 1.0);
  EXPECT_NEAR(sd[0], 5.0, 0.3);
  EXPECT_EQ(cv::norm(a, SceneRenderer(p).render({}), cv::NORM_INF), 0.0);  // seeded
  const SceneRenderer r(p);
  EXPECT_EQ(cv::norm(a, r.quantize(r.render_linear({})), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, SceneRenderer(p).render({}, 99), cv::NORM_INF), 0.0);

  p.noise_sigma = 0;
  p.light_gradient = 0.5;  // +-25 % left to right
  const cv::Mat1b lit = SceneRenderer(p).render({});
  EXPECT_NEAR(lit(100, 0), 127.5 * 0.75, 2);
  EXPECT_NEAR(lit(100, 199), 127.5 * 1.25, 2);

  p.light_gradient = 0;
  p.photo = cv::Mat1b(50, 100, uchar(200));
  p.photo(cv::Rect(0, 0, 50, 50)).setTo(0);
  const cv::Mat1b photo = SceneRenderer(p).render({});
  EXPECT_LT(photo(100, 20), 5);
  EXPECT_GT(photo(100, 180), 195);
}

TEST(Scene, TruthKnowsWhenAMarkerLeavesTheFrame) {
  const Camera cam = Camera::pinhole(320, 320, 319.5, 239.5, 640, 480);
  SceneMarker m;
  m.tvec = {0, 0, 3};
  EXPECT_TRUE(make_truth(cam, m).fully_visible);
  m.tvec = {3.2, 0, 3};
  EXPECT_FALSE(make_truth(cam, m).fully_visible);
  m.tvec = {0, 0, -3};
  EXPECT_FALSE(make_truth(cam, m).fully_visible);
}

TEST(Scene, RejectsBadParameters) {
  SceneParams p;
  p.camera = Camera::pinhole(300, 300, 100, 100);  // no frame size
  EXPECT_THROW(SceneRenderer{p}, std::invalid_argument);
  p.camera = Camera::pinhole(300, 300, 100, 100, 200, 200);
  p.supersample = 0;
  EXPECT_THROW(SceneRenderer{p}, std::invalid_argument);
  SceneMarker m;
  m.margin_units = 1.5;
  EXPECT_THROW(to_target(m), std::invalid_argument);
}

TEST(Scene, DegenerateCamerasNeverDrawOutsideTheMarker) {
  // Focal lengths so small that the rays overflow to infinity and grid coordinates become
  // NaN (this crashed with fx = 1e-100) are refused; at the smallest focal length accepted
  // the renderer draws, never reading outside the albedo (an out-of-bounds read fails
  // here under the sanitizer build).
  SceneMarker m;
  m.tvec = {0, 0, 1};
  for (double fx : {1e-100, 1e-300, 1e-30}) {
    SceneParams p;
    p.camera = Camera::pinhole(fx, fx, 31.5, 23.5, 64, 48);
    EXPECT_THROW(SceneRenderer{p}, std::invalid_argument) << fx;
  }
  SceneParams p;
  p.camera = Camera::pinhole(Camera::kMinFocal, Camera::kMinFocal, 31.5, 23.5, 64, 48);
  const SceneRenderer renderer(p);
  const cv::Mat1b image = renderer.render({to_target(m)});
  ASSERT_EQ(image.size(), cv::Size(64, 48));
  // The marker projects to far less than a pixel (about 1e-4 px across): it covers no
  // pixel by more than a grey level, so the image is the empty scene's. A sample counted
  // although its grid point lies outside the albedo would count as covered and draw its
  // pixel in the marker's grey instead.
  const cv::Mat1b empty = renderer.render({});
  EXPECT_LE(cv::norm(image, empty, cv::NORM_INF), 1.0);
}
