// SPDX-License-Identifier: LGPL-2.1-or-later
#include <gtest/gtest.h>

#include "lftag/camera.hpp"

using lftag::Camera;

namespace {
const std::string kData = LFTAG_TEST_DATA;

std::string error_of(const std::string& path) {
  try {
    Camera::load(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Camera, LoadsOpenCvSampleCalibration) {
  const Camera c = Camera::load(kData + "/opencv_sample.yml");
  EXPECT_TRUE(c.calibrated);
  EXPECT_DOUBLE_EQ(c.fx, 628.158);
  EXPECT_DOUBLE_EQ(c.cy, 260.908);
  EXPECT_EQ(c.width, 640);
  ASSERT_EQ(c.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(c.distortion[1], -0.206384);
}

TEST(Camera, LoadsGStreamerCameraCalibrateKeys) {
  const Camera c = Camera::load(kData + "/gst_cameracalibrate.xml");
  EXPECT_DOUBLE_EQ(c.fx, 800);
  EXPECT_DOUBLE_EQ(c.cx, 319.5);
  EXPECT_DOUBLE_EQ(c.distortion[0], -0.1);
  EXPECT_EQ(c.width, 0);  // unknown
}

TEST(Camera, ErrorsNameTheFileAndTheProblem) {
  const std::string missing = error_of(kData + "/does-not-exist.yml");
  EXPECT_NE(missing.find("does-not-exist.yml"), std::string::npos);
  EXPECT_NE(missing.find("cannot be opened"), std::string::npos);
  const std::string malformed = error_of(kData + "/malformed.yml");
  EXPECT_NE(malformed.find("malformed.yml"), std::string::npos);
  const std::string shape = error_of(kData + "/wrong_shape.yml");
  EXPECT_NE(shape.find("expected 3x3"), std::string::npos) << shape;
  const std::string none = error_of(kData + "/no_matrix.yml");
  EXPECT_NE(none.find("camera_matrix"), std::string::npos) << none;
}

TEST(Camera, ParsesAndSavesRoundTrip) {
  Camera c = Camera::pinhole(500, 510, 320, 240, 640, 480);
  c.distortion = {0.1, -0.05, 0.001, 0.002, 0.01};
  const std::string path = testing::TempDir() + "/cam.yml";
  c.save(path);
  const Camera d = Camera::load(path);
  EXPECT_DOUBLE_EQ(d.fy, 510);
  EXPECT_EQ(d.height, 480);
  EXPECT_EQ(d.distortion, c.distortion);
  EXPECT_THROW(Camera::parse("camera_matrix: 5", "inline"), std::runtime_error);
}

TEST(Camera, UndistortInvertsProjection) {
  Camera c = Camera::load(kData + "/opencv_sample.yml");
  std::vector<cv::Point3d> pts;
  for (double x = -0.4; x <= 0.4; x += 0.1)
    for (double y = -0.3; y <= 0.3; y += 0.1) pts.emplace_back(x, y, 1.0);
  const auto distorted = c.project(pts);
  const auto ideal = c.undistort(distorted);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    EXPECT_NEAR(ideal[i].x, c.fx * pts[i].x + c.cx, 1e-6);
    EXPECT_NEAR(ideal[i].y, c.fy * pts[i].y + c.cy, 1e-6);
  }
}

TEST(Camera, DefaultAndScaledCameras) {
  const Camera d = Camera::default_for(1280, 720);
  EXPECT_FALSE(d.calibrated);
  EXPECT_DOUBLE_EQ(d.fx, 1280);
  EXPECT_DOUBLE_EQ(d.cx, 639.5);
  EXPECT_DOUBLE_EQ(d.cy, 359.5);
  const Camera c = Camera::pinhole(600, 600, 319.5, 239.5, 640, 480).for_frame(1280, 960);
  EXPECT_DOUBLE_EQ(c.fx, 1200);
  EXPECT_DOUBLE_EQ(c.cx, 639.5);
  EXPECT_THROW(Camera::pinhole(600, 600, 319.5, 239.5, 640, 480).for_frame(1280, 720), std::invalid_argument);
  EXPECT_THROW(Camera::pinhole(0, 600, 1, 1).validate(), std::invalid_argument);
}
