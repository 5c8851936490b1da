// SPDX-License-Identifier: LGPL-2.1-or-later
// Drawing detections and the debug images of the stages (src/draw/draw.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/draw.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"

using namespace lftag;

namespace {

const Camera kCamera = Camera::pinhole(500, 500, 319.5, 239.5, 640, 480);

// A detection as the detector reports it, made from a known pose: a 0.2 m marker 1 m away
// (100 px), its centre at pixel (x, y).
Detection detection_at(double x, double y, const cv::Vec3d& rvec = {0.3, -0.2, 0.1}) {
  Detection d;
  d.family = Family(3);
  d.id = 6789;
  d.tag_size = 0.2;
  d.rvec = rvec;
  d.tvec = {(x - kCamera.cx) / kCamera.fx, (y - kCamera.cy) / kCamera.fy, 1.0};
  const std::vector<cv::Point2d> p =
      kCamera.project({{-0.1, -0.1, 0}, {0.1, -0.1, 0}, {0.1, 0.1, 0}, {-0.1, 0.1, 0}, {0, 0, 0}}, d.rvec, d.tvec);
  for (int i = 0; i < 4; ++i) d.corners[i] = p[i];
  d.center = p[4];
  return d;
}

// Pixels that differ between two images of the same type, as a mask.
cv::Mat1b changed(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  if (diff.channels() > 1) {
    std::vector<cv::Mat> planes;
    cv::split(diff, planes);
    cv::Mat m = planes[0].clone();
    for (std::size_t i = 1; i < planes.size(); ++i) m = cv::max(m, planes[i]);
    diff = m;
  }
  return diff > 0;
}

// The region a drawing of `d` may touch: its outline, its axes (one tag size long) and its
// label, grown by a margin.
cv::Rect reach(const Detection& d, int margin) {
  std::vector<cv::Point2d> p(d.corners.begin(), d.corners.end());
  const std::vector<cv::Point2d> axes =
      kCamera.project({{0, 0, 0}, {0.2, 0, 0}, {0, 0.2, 0}, {0, 0, 0.2}}, d.rvec, d.tvec);
  p.insert(p.end(), axes.begin(), axes.end());
  double x0 = p[0].x, y0 = p[0].y, x1 = p[0].x, y1 = p[0].y;
  for (const cv::Point2d& q : p)
    x0 = std::min(x0, q.x), y0 = std::min(y0, q.y), x1 = std::max(x1, q.x), y1 = std::max(y1, q.y);
  return cv::Rect(cv::Point(int(x0) - margin, int(y0) - margin), cv::Point(int(x1) + margin + 1, int(y1) + margin + 1));
}

// Where the label may be: a band of text height 13.3 px (480 / 36) under the marker's
// lowest corner, as wide as the frame, grown by a margin.
cv::Rect label_box(const Detection& d, int cols, int rows) {
  double bottom = -1e9;
  for (const cv::Point2d& c : d.corners) bottom = std::max(bottom, c.y);
  return cv::Rect(0, int(bottom), cols, 40) & cv::Rect(0, 0, cols, rows);
}

}  // namespace

TEST(DrawDetections, TheLabelSitsBesideTheMarkerInsideTheFrame) {
  // A small marker (40 px): the label leaves its inside untouched, under it, or over it at
  // the foot of the frame; at the frame's edges it stays whole inside the frame.
  DrawOptions id_only;
  id_only.outline = false, id_only.axes = false;
  auto small_at = [](double x, double y) {
    Detection d = detection_at(x, y, {0, 0, 0});
    for (cv::Point2d& c : d.corners) c = d.center + (c - d.center) * 0.4;
    return d;
  };
  auto corner_box = [](const Detection& d) {
    std::vector<cv::Point2f> p(d.corners.begin(), d.corners.end());
    return cv::boundingRect(p);
  };
  for (const cv::Point2d& at :
       {cv::Point2d(320, 200), cv::Point2d(320, 470), cv::Point2d(5, 240), cv::Point2d(635, 10)}) {
    const Detection d = small_at(at.x, at.y);
    cv::Mat1b image(480, 640, uchar(100));
    draw_detections(image, {d}, kCamera, id_only);
    const cv::Mat1b mask = image != 100;
    SCOPED_TRACE("marker at " + std::to_string(at.x) + ", " + std::to_string(at.y));
    const cv::Rect inside = corner_box(d) & cv::Rect(0, 0, 640, 480);
    EXPECT_EQ(cv::countNonZero(mask(inside)), 0) << "the label covers the marker";
    const cv::Rect drawn = cv::boundingRect(mask);
    ASSERT_GT(drawn.area(), 0);
    EXPECT_GT(drawn.width, 50) << "the label was cut by the frame's edge";  // "3x3:6789" is ~90 px wide
    if (at.y < 400)
      EXPECT_GE(drawn.y, inside.br().y) << "under the marker";
    else
      EXPECT_LE(drawn.br().y, inside.y) << "over the marker, at the frame's foot";
  }
}

TEST(DrawDetections, ChangesPixelsAtTheMarkerAndNowhereElse) {
  const Detection d = detection_at(200, 180);
  for (int type : {CV_8UC1, CV_8UC3, CV_8UC4}) {
    const cv::Mat before(480, 640, type, cv::Scalar(90, 100, 110, 0));
    cv::Mat image = before.clone();
    draw_detections(image, {d}, kCamera);
    const cv::Mat1b mask = changed(before, image);
    SCOPED_TRACE("type " + std::to_string(type));
    // On the outline: every side's midpoint has changed pixels within 2 px.
    for (int i = 0; i < 4; ++i) {
      const cv::Point2d mid = (d.corners[i] + d.corners[(i + 1) % 4]) * 0.5;
      EXPECT_GT(cv::countNonZero(mask(cv::Rect(int(mid.x) - 2, int(mid.y) - 2, 5, 5))), 0) << "side " << i;
    }
    // Nothing far away: outside the marker, its axes and its label (under it), grown by 15 px.
    cv::Mat1b outside = mask.clone();
    outside(reach(d, 15) & cv::Rect(0, 0, 640, 480)).setTo(0);
    outside(label_box(d, 640, 480)).setTo(0);
    EXPECT_EQ(cv::countNonZero(outside), 0);
    EXPECT_GT(cv::countNonZero(mask), 200);
  }
}

TEST(DrawDetections, ColoursAndAlpha) {
  // Outline only: yellow (BGR 0, 255, 255) on BGR, its luminance on grey, opaque on BGRA.
  const Detection d = detection_at(320, 240, {0, 0, 0});
  DrawOptions outline;
  outline.id = false, outline.axes = false, outline.line_width = 3;
  const cv::Point top(320, int(std::round(d.corners[0].y)));  // the middle of the top side

  cv::Mat bgr(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_detections(bgr, {d}, kCamera, outline);
  EXPECT_EQ(bgr.at<cv::Vec3b>(top), cv::Vec3b(0, 255, 255));

  cv::Mat grey(480, 640, CV_8UC1, cv::Scalar(0));
  draw_detections(grey, {d}, kCamera, outline);
  EXPECT_NEAR(grey.at<uchar>(top), 0.587 * 255 + 0.299 * 255, 1.0);

  cv::Mat bgra(480, 640, CV_8UC4, cv::Scalar(0, 0, 0, 0));
  draw_detections(bgra, {d}, kCamera, outline);
  EXPECT_EQ(bgra.at<cv::Vec4b>(top), cv::Vec4b(0, 255, 255, 255));
  EXPECT_EQ(bgra.at<cv::Vec4b>(10, 10), cv::Vec4b(0, 0, 0, 0));  // a transparent overlay stays so

  // Axes only: x red from the centre along +x (the marker faces the camera unrotated).
  DrawOptions axes;
  axes.id = false, axes.outline = false, axes.line_width = 2;
  cv::Mat a(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_detections(a, {d}, kCamera, axes);
  const cv::Point x_axis(320 + 60, 240);  // the x axis ends 100 px to the right
  const cv::Vec3b px = a.at<cv::Vec3b>(x_axis);
  EXPECT_EQ(px, cv::Vec3b(0, 0, 255));
  const cv::Point y_axis(320, 240 + 60);
  EXPECT_EQ(a.at<cv::Vec3b>(y_axis), cv::Vec3b(0, 255, 0));
  // z points into the marker, away from the camera: its image is the centre itself.
  EXPECT_EQ(a.at<cv::Vec3b>(240 - 30, 320 - 30), cv::Vec3b(0, 0, 0));
}

TEST(DrawDetections, OtherImageTypesAreRejected) {
  const std::vector<Detection> ds = {detection_at(320, 240)};
  for (int type : {CV_8UC2, CV_16UC1, CV_16UC3, CV_32FC1, CV_32FC3, CV_8SC1, CV_8SC3, CV_64FC4}) {
    cv::Mat image(48, 64, type, cv::Scalar::all(0));
    EXPECT_THROW(draw_detections(image, ds, kCamera), std::invalid_argument) << "type " << type;
  }
  // Without detections the type is still checked; with none, a valid image is untouched.
  cv::Mat f(48, 64, CV_32FC1, cv::Scalar(0));
  EXPECT_THROW(draw_detections(f, {}, kCamera), std::invalid_argument);
  cv::Mat ok(48, 64, CV_8UC3, cv::Scalar(1, 2, 3));
  draw_detections(ok, {}, kCamera);
  EXPECT_EQ(cv::countNonZero(changed(ok, cv::Mat(48, 64, CV_8UC3, cv::Scalar(1, 2, 3)))), 0);
}

TEST(DrawDetections, AxesOnlyInFrontOfTheCamera) {
  DrawOptions axes;
  axes.outline = false, axes.id = false;
  // Facing the camera, 1 m away: axes drawn.
  const Detection front = detection_at(320, 240, {0.2, 0.1, 0});
  cv::Mat a(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_detections(a, {front}, kCamera, axes);
  EXPECT_GT(cv::countNonZero(changed(a, cv::Mat(480, 640, CV_8UC3, cv::Scalar(0, 0, 0)))), 50);

  // Turned over (z towards the camera) and 5 cm away: the z axis (20 cm) ends behind the
  // camera, so no axis is drawn at all.
  Detection behind = detection_at(320, 240, {CV_PI, 0, 0});
  behind.tvec = {0, 0, 0.05};
  cv::Mat b(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_detections(b, {behind}, kCamera, axes);
  EXPECT_EQ(cv::countNonZero(changed(b, cv::Mat(480, 640, CV_8UC3, cv::Scalar(0, 0, 0)))), 0);
  // Just far enough (25 cm), the same marker gets its axes.
  behind.tvec = {0, 0, 0.25};
  draw_detections(b, {behind}, kCamera, axes);
  EXPECT_GT(cv::countNonZero(changed(b, cv::Mat(480, 640, CV_8UC3, cv::Scalar(0, 0, 0)))), 50);

  // A marker wholly behind the camera.
  Detection back = detection_at(320, 240);
  back.tvec = {0, 0, -1};
  cv::Mat c(480, 640, CV_8UC3, cv::Scalar(0, 0, 0));
  draw_detections(c, {back}, kCamera, axes);
  EXPECT_EQ(cv::countNonZero(changed(c, cv::Mat(480, 640, CV_8UC3, cv::Scalar(0, 0, 0)))), 0);
}

TEST(DrawDetections, EveryDetectionIsDrawn) {
  const Detection a = detection_at(150, 150), b = detection_at(480, 330);
  cv::Mat one(480, 640, CV_8UC3, cv::Scalar(50, 50, 50)), two = one.clone();
  const cv::Mat blank = one.clone();
  draw_detections(one, {a}, kCamera);
  draw_detections(two, {a, b}, kCamera);
  const cv::Rect around_b = reach(b, 5) & cv::Rect(0, 0, 640, 480);
  EXPECT_EQ(cv::countNonZero(changed(one, blank)(around_b)), 0);
  EXPECT_GT(cv::countNonZero(changed(two, blank)(around_b)), 200);
}

TEST(DrawTrace, FiveBgrImagesOfTheFrameSize) {
  SceneParams p;
  p.camera = kCamera;
  p.background = 0.7;
  SceneMarker m;
  m.family = Family(3);
  m.id = 6789;
  m.tag_size = 0.2;
  m.tvec = {0.05, 0.02, 1.0};
  m.rvec = {0.3, 0.2, 0.1};
  const RenderedScene scene = render_scene(p, {m});
  DetectorParams params;
  params.camera = kCamera;
  params.tag_size = 0.2;
  Detector detector(params);
  DetectionTrace trace;
  const std::vector<Detection> found = detector.detect(ImageView(scene.image), nullptr, &trace);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].id, m.id);

  const std::map<std::string, cv::Mat> images = draw_trace(scene.image, trace, kCamera);
  std::vector<std::string> names;
  for (const auto& [name, image] : images) {
    names.push_back(name);
    EXPECT_EQ(image.size(), scene.image.size()) << name;
    EXPECT_EQ(image.type(), CV_8UC3) << name;
  }
  EXPECT_EQ(names, (std::vector<std::string>{"candidates", "final", "hypotheses", "keypoints", "threshold"}));

  // The threshold image shows black as black; the others draw over the grey frame.
  cv::Mat grey_bgr;
  cv::cvtColor(scene.image, grey_bgr, cv::COLOR_GRAY2BGR);
  cv::Mat thr;
  cv::cvtColor(images.at("threshold"), thr, cv::COLOR_BGR2GRAY);
  EXPECT_EQ(cv::norm(thr, 255 - trace.binary, cv::NORM_INF), 0.0);
  for (const char* name : {"candidates", "keypoints", "hypotheses", "final"}) {
    const cv::Mat1b mask = changed(images.at(name), grey_bgr);
    EXPECT_GT(cv::countNonZero(mask), 20) << name;
    // Only around the marker.
    cv::Mat1b outside = mask.clone();
    outside(reach(found[0], 15) & cv::Rect(0, 0, 640, 480)).setTo(0);
    EXPECT_EQ(cv::countNonZero(outside), 0) << name;
  }
  // "final" is draw_detections over the frame.
  cv::Mat expected = grey_bgr.clone();
  draw_detections(expected, found, kCamera);
  EXPECT_EQ(cv::norm(expected, images.at("final"), cv::NORM_INF), 0.0);

  // An empty frame gives nothing; an empty trace the plain frame four times.
  EXPECT_TRUE(draw_trace(cv::Mat(), trace, kCamera).empty());
  const std::map<std::string, cv::Mat> bare = draw_trace(scene.image, DetectionTrace{}, kCamera);
  EXPECT_EQ(bare.count("threshold"), 0u);
  EXPECT_EQ(bare.size(), 4u);
  for (const auto& [name, image] : bare) EXPECT_EQ(cv::norm(image, grey_bgr, cv::NORM_INF), 0.0) << name;
}
