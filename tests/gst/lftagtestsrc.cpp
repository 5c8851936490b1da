// SPDX-License-Identifier: LGPL-2.1-or-later
// lftagtestsrc: caps and formats, the ground truth over long runs (and whether the
// pixels agree with it), determinism, seeking, live mode, property changes while
// playing, and bad settings.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <glib/gstdio.h>
#include <gst/base/gstbasesrc.h>
#include <gst/video/video.h>
#include <sys/stat.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "metaconversion.h"
// Last: check's macros (fail...) clash with names in the C++ library.
#include "check-main.h"
#include "frames.hpp"

namespace {

using lftag::gst::FrameTruth;

FrameTruth truth_of(GstBuffer* buffer) {
  const auto truth = lftag::gst::read_truth_meta(buffer);
  fail_unless(truth.has_value(), "a frame without LFTagTruthMeta");
  return *truth;
}

const GstStructure* truth_structure(GstBuffer* buffer) {
  const GstStructure* s = lftag_meta_get_structure(buffer, LFTAG_TRUTH_META_NAME);
  fail_unless(s != nullptr, "a frame without LFTagTruthMeta");
  return s;
}

std::vector<std::string> ids_of(const FrameTruth& truth) {
  std::vector<std::string> ids;
  for (const lftag::MarkerTruth& m : truth.markers) ids.push_back(m.id.to_decimal());
  return ids;
}

bool inside(const cv::Point2d& p, const lftag::Camera& c) {
  return p.x >= 0 && p.y >= 0 && p.x <= c.width - 1 && p.y <= c.height - 1;
}

// The grey plane of a GRAY8 frame as a matrix (copied, so the buffer may go).
cv::Mat1b grey_of(GstBuffer* buffer, GstVideoInfo* info) {
  GstVideoFrame frame;
  fail_unless(gst_video_frame_map(&frame, info, buffer, GST_MAP_READ));
  fail_unless_equals_int(GST_VIDEO_FRAME_FORMAT(&frame), GST_VIDEO_FORMAT_GRAY8);
  const cv::Mat1b grey =
      cv::Mat(GST_VIDEO_FRAME_HEIGHT(&frame), GST_VIDEO_FRAME_WIDTH(&frame), CV_8UC1,
              GST_VIDEO_FRAME_PLANE_DATA(&frame, 0), std::size_t(GST_VIDEO_FRAME_PLANE_STRIDE(&frame, 0)))
          .clone();
  gst_video_frame_unmap(&frame);
  return grey;
}

// `buffer` holds what videoconvert makes of the GRAY8 frame `converted` came from:
// the same bytes in every component, neutral chroma, and R = G = B.
void expect_videoconvert(GstBuffer* buffer, GstVideoInfo* info, GstBuffer* converted, GstVideoInfo* converted_info) {
  GstVideoFrame frame, reference;
  fail_unless(gst_video_frame_map(&frame, info, buffer, GST_MAP_READ));
  fail_unless(gst_video_frame_map(&reference, converted_info, converted, GST_MAP_READ));
  const GstVideoFormatInfo* f = frame.info.finfo;
  fail_unless_equals_int(GST_VIDEO_FRAME_FORMAT(&frame), GST_VIDEO_FRAME_FORMAT(&reference));
  auto at = [](const GstVideoFrame& fr, guint c, int x, int y) {
    return int(static_cast<const guint8*>(GST_VIDEO_FRAME_COMP_DATA(
        &fr, c))[y * GST_VIDEO_FRAME_COMP_STRIDE(&fr, c) + x * GST_VIDEO_FRAME_COMP_PSTRIDE(&fr, c)]);
  };
  // Checked pixel by pixel, reported once: check's assertions are slow.
  std::string problem;
  for (guint c = 0; c < GST_VIDEO_FORMAT_INFO_N_COMPONENTS(f) && problem.empty(); ++c)
    for (int y = 0; y < GST_VIDEO_FRAME_COMP_HEIGHT(&frame, c) && problem.empty(); ++y)
      for (int x = 0; x < GST_VIDEO_FRAME_COMP_WIDTH(&frame, c) && problem.empty(); ++x) {
        const int value = at(frame, c, x, y);
        if (value != at(reference, c, x, y))
          problem = "differs from videoconvert";
        else if (GST_VIDEO_FORMAT_INFO_IS_YUV(f) && c > 0 && std::abs(value - 128) > 1)
          problem = "chroma is not neutral";
        else if (GST_VIDEO_FORMAT_INFO_IS_RGB(f) && c > 0 && c < 3 && value != at(frame, 0, x, y))
          problem = "R, G and B differ";
        else if (GST_VIDEO_FORMAT_INFO_HAS_ALPHA(f) && c == 3 && value != 255)
          problem = "alpha is not opaque";
        if (!problem.empty())
          problem += " in component " + std::to_string(c) + " at (" + std::to_string(x) + ", " + std::to_string(y) +
                     "): " + std::to_string(value);
      }
  fail_unless(problem.empty(), "%s: %s", GST_VIDEO_FORMAT_INFO_NAME(f), problem.c_str());
  gst_video_frame_unmap(&reference);
  gst_video_frame_unmap(&frame);
}

const char* const kFormats[] = {"GRAY8", "I420", "YV12", "NV12", "NV21", "Y42B", "Y444", "RGB", "BGR",
                                "RGBx",  "BGRx", "xRGB", "xBGR", "RGBA", "BGRA", "ARGB", "ABGR"};

void check_formats(int width, int height, const std::vector<const char*>& formats) {
  const std::string launch = "lftagtestsrc num-buffers=1 count=2 seed=11 noise=2";
  const std::string size = ",width=" + std::to_string(width) + ",height=" + std::to_string(height);
  Frames grey;
  pull_frames(grey, launch, ("video/x-raw,format=GRAY8" + size).c_str(), 1);
  fail_unless_equals_int(GST_VIDEO_INFO_WIDTH(&grey.info), width);
  fail_unless_equals_int(GST_VIDEO_INFO_HEIGHT(&grey.info), height);
  const FrameTruth truth = truth_of(grey.buffers[0]);
  fail_unless_equals_int(truth.camera.width, width);
  fail_unless_equals_int(truth.camera.height, height);

  for (const char* format : formats) {
    const std::string caps = std::string("video/x-raw,format=") + format + size;
    Frames frames, converted;
    pull_frames(frames, launch, caps.c_str(), 1);
    pull_frames(converted, launch + " ! video/x-raw,format=GRAY8 ! videoconvert dither=none", caps.c_str(), 1);
    fail_unless_equals_string(gst_video_format_to_string(GST_VIDEO_INFO_FORMAT(&frames.info)), format);
    fail_unless(gst_buffer_get_size(frames.buffers[0]) >= GST_VIDEO_INFO_SIZE(&frames.info));
    expect_videoconvert(frames.buffers[0], &frames.info, converted.buffers[0], &converted.info);
    fail_unless(gst_structure_is_equal(truth_structure(frames.buffers[0]), truth_structure(grey.buffers[0])),
                "the truth depends on the format");
  }
}

}  // namespace

GST_START_TEST(test_default_caps) {
  Frames frames;
  pull_frames(frames, "lftagtestsrc num-buffers=2", nullptr, 2);
  fail_unless_equals_int(GST_VIDEO_INFO_FORMAT(&frames.info), GST_VIDEO_FORMAT_GRAY8);
  fail_unless_equals_int(GST_VIDEO_INFO_WIDTH(&frames.info), 640);
  fail_unless_equals_int(GST_VIDEO_INFO_HEIGHT(&frames.info), 480);
  fail_unless_equals_int(GST_VIDEO_INFO_FPS_N(&frames.info), 30);
  fail_unless_equals_int(GST_VIDEO_INFO_FPS_D(&frames.info), 1);

  const FrameTruth truth = truth_of(frames.buffers[0]);
  fail_unless_equals_int(truth.markers.size(), 1);
  fail_unless(truth.markers[0].family == lftag::Family(3));
  // The documented default camera: fx = fy = width, centred.
  fail_unless(truth.camera.fx == 640 && truth.camera.fy == 640);
  fail_unless(truth.camera.cx == 319.5 && truth.camera.cy == 239.5);
  fail_unless(truth.camera.distortion.empty());
}
GST_END_TEST;

GST_START_TEST(test_every_format) { check_formats(160, 120, {std::begin(kFormats), std::end(kFormats)}); }
GST_END_TEST;

GST_START_TEST(test_odd_sizes) {
  for (const cv::Size size : {cv::Size(1, 1), cv::Size(17, 13), cv::Size(1921, 1081)})
    check_formats(size.width, size.height, {"I420", "NV12", "Y42B", "RGB", "xBGR"});
}
GST_END_TEST;

// 300 frames: timestamps, the configured markers in every frame, a truth that agrees
// with itself and with the pixels, and motion that a demo needs: markers in view,
// moving smoothly, coming closer and receding, spinning and tilting moderately.
static void check_long_run(const std::string& family, const std::string& ids_property,
                           const std::vector<std::string>& ids, guint count) {
  const int n_frames = 300;
  const std::string launch = "lftagtestsrc num-buffers=300 seed=4 family=" + family +
                             " count=" + std::to_string(count) + (ids_property.empty() ? "" : " ids=" + ids_property);
  GstHarness* h = gst_harness_new_parse(launch.c_str());
  gst_harness_play(h);

  struct Motion {
    int visible = 0;
    double min_edge = 1e9, max_edge = 0, max_tilt = 0, max_jump = 0, roll = 0, min_roll = 0, max_roll = 0;
    cv::Point2d last_center{-1, -1};
    double last_angle = 0;
  };
  std::vector<Motion> motion(count);
  int image_checks = 0;
  const lftag::Family fam = lftag::Family::parse(family);
  const int side = fam.side();

  for (int i = 0; i < n_frames; ++i) {
    GstBuffer* buffer = gst_harness_pull(h);
    fail_unless(buffer != nullptr, "frame %d did not come", i);
    fail_unless_equals_uint64(GST_BUFFER_PTS(buffer), gst_util_uint64_scale(i, GST_SECOND, 30));
    fail_unless_equals_uint64(GST_BUFFER_DURATION(buffer),
                              gst_util_uint64_scale(i + 1, GST_SECOND, 30) - GST_BUFFER_PTS(buffer));
    fail_unless_equals_uint64(GST_BUFFER_OFFSET(buffer), i);

    const FrameTruth truth = truth_of(buffer);
    const lftag::Camera& cam = truth.camera;
    fail_unless(cam.width == 640 && cam.height == 480);
    fail_unless_equals_int(truth.markers.size(), count);
    if (!ids.empty()) {
      const std::vector<std::string> seen = ids_of(truth);
      for (guint k = 0; k < count; ++k) fail_unless_equals_string(seen[k].c_str(), ids[k % ids.size()].c_str());
    }

    GstVideoInfo info;
    gst_video_info_set_format(&info, GST_VIDEO_FORMAT_GRAY8, 640, 480);
    const cv::Mat1b grey = grey_of(buffer, &info);

    for (guint k = 0; k < count; ++k) {
      const lftag::MarkerTruth& m = truth.markers[k];
      fail_unless(m.family == fam);
      fail_unless(m.tag_size == 0.1);
      fail_unless(m.tvec[2] > 0, "a marker behind the camera");

      // The pose reproduces the key points and corners.
      std::vector<cv::Point3d> points;
      for (const cv::Point2d& u : fam.keypoints(m.id)) points.push_back(fam.to_marker_frame(u, m.tag_size));
      for (const cv::Point2d& u : fam.outer_corners()) points.push_back(fam.to_marker_frame(u, m.tag_size));
      const std::vector<cv::Point2d> projected = cam.project(points, m.rvec, m.tvec);
      for (int j = 0; j < 4; ++j) {
        fail_unless(cv::norm(projected[j] - m.keypoints[j]) < 1e-6, "key point %d disagrees with the pose", j);
        fail_unless(cv::norm(projected[4 + j] - m.corners[j]) < 1e-6, "corner %d disagrees with the pose", j);
      }
      fail_unless_equals_int(m.centers.size(), fam.cell_count());
      fail_unless_equals_int(m.centroids.size(), fam.cell_count());

      // Fully visible exactly when every corner is in the frame, and then every point is.
      const bool corners_in =
          std::all_of(m.corners.begin(), m.corners.end(), [&](const cv::Point2d& p) { return inside(p, cam); });
      fail_unless(m.fully_visible == corners_in, "frame %d marker %u: fully-visible is wrong", i, k);
      if (m.fully_visible) {
        for (const auto* list : {&m.keypoints, &m.centers, &m.centroids})
          for (const cv::Point2d& p : *list) fail_unless(inside(p, cam), "frame %d: a point outside the frame", i);
        motion[k].visible++;
      }

      // The pixels agree: black at K0 and on the border, white just inside the border.
      if (m.fully_visible && m.edge_px >= 3 * side) {
        std::vector<cv::Point2f> units, image;
        for (const cv::Point2d& u : fam.outer_corners()) units.emplace_back(u);
        for (const cv::Point2d& p : m.corners) image.emplace_back(p);
        const cv::Matx33d to_image = cv::getPerspectiveTransform(units, image);
        auto grey_at = [&](double ux, double uy) {
          const cv::Vec3d p = to_image * cv::Vec3d(ux, uy, 1);
          return int(grey(int(std::lround(p[1] / p[2])), int(std::lround(p[0] / p[2]))));
        };
        fail_unless(grey_at(6, 6) < 80, "frame %d: K0 is not black (%d)", i, grey_at(6, 6));
        fail_unless(grey_at(1, side / 2.0) < 80, "frame %d: the border is not black", i);
        fail_unless(grey_at(3, 3) > 160, "frame %d: the white margin is not white (%d)", i, grey_at(3, 3));
        fail_unless(grey_at(side - 3, side / 2.0) > 160, "frame %d: the right margin is not white", i);
        ++image_checks;
      }

      Motion& mo = motion[k];
      mo.min_edge = std::min(mo.min_edge, m.edge_px);
      mo.max_edge = std::max(mo.max_edge, m.edge_px);
      cv::Matx33d r;
      cv::Rodrigues(m.rvec, r);
      mo.max_tilt = std::max(mo.max_tilt, std::acos(std::clamp(r(2, 2), -1.0, 1.0)) * 180 / CV_PI);
      const cv::Point2d center = cam.project({cv::Point3d(0, 0, 0)}, m.rvec, m.tvec)[0];
      const cv::Point2d baseline = m.keypoints[1] - m.keypoints[0];
      const double angle = std::atan2(baseline.y, baseline.x) * 180 / CV_PI;
      if (i > 0) {
        mo.max_jump = std::max(mo.max_jump, cv::norm(center - mo.last_center));
        mo.roll += std::remainder(angle - mo.last_angle, 360.0);
        mo.min_roll = std::min(mo.min_roll, mo.roll);
        mo.max_roll = std::max(mo.max_roll, mo.roll);
      }
      mo.last_center = center;
      mo.last_angle = angle;
    }
    gst_buffer_unref(buffer);
  }
  gst_harness_teardown(h);

  fail_unless(image_checks > 20, "too few large markers to compare with the pixels (%d)", image_checks);
  for (guint k = 0; k < count; ++k) {
    const Motion& mo = motion[k];
    fail_unless(mo.visible >= n_frames * 9 / 10, "marker %u fully visible in only %d frames", k, mo.visible);
    fail_unless(mo.max_edge >= 2 * mo.min_edge, "marker %u: distance hardly varies (%.0f..%.0f px)", k, mo.min_edge,
                mo.max_edge);
    fail_unless(mo.max_tilt <= 60 && mo.max_tilt >= 15, "marker %u: tilt up to %.0f degrees", k, mo.max_tilt);
    fail_unless(mo.max_roll - mo.min_roll >= 45, "marker %u hardly spins", k);
    fail_unless(mo.max_jump <= 0.03 * std::hypot(640, 480), "marker %u jumps %.1f px", k, mo.max_jump);
  }
}

GST_START_TEST(test_truth_3x3) { check_long_run("3x3", "6789,0,16383", {"6789", "0", "16383"}, 3); }
GST_END_TEST;

GST_START_TEST(test_truth_4x4_repeating_ids) { check_long_run("4x4", "268435455,0x1f2e", {"268435455", "7982"}, 5); }
GST_END_TEST;

GST_START_TEST(test_truth_8x8_random_ids) { check_long_run("8x8", "", {}, 1); }
GST_END_TEST;

GST_START_TEST(test_large_ids_exact) {
  Frames frames;
  // 2^100 + 1 and 2^124 - 1 need more than 64 bits.
  pull_frames(frames,
              "lftagtestsrc num-buffers=1 family=8x8 ids=1267650600228229401496703205377,"
              "0xfffffffffffffffffffffffffffffff",
              nullptr, 1);
  const GstStructure* s = truth_structure(frames.buffers[0]);
  const GValue* markers = gst_structure_get_value(s, LFTAG_META_FIELD_MARKERS);
  fail_unless_equals_int(gst_value_array_get_size(markers), 2);
  const GstStructure* m0 = gst_value_get_structure(gst_value_array_get_value(markers, 0));
  const GstStructure* m1 = gst_value_get_structure(gst_value_array_get_value(markers, 1));
  fail_unless_equals_string(gst_structure_get_string(m0, LFTAG_FIELD_ID_STRING), "1267650600228229401496703205377");
  fail_unless_equals_string(gst_structure_get_string(m1, LFTAG_FIELD_ID_STRING),
                            "21267647932558653966460912964485513215");
  fail_if(gst_structure_has_field(m0, LFTAG_FIELD_ID), "no 64-bit id field for a 101-bit id");
}
GST_END_TEST;

GST_START_TEST(test_random_ids_distinct) {
  Frames frames;
  pull_frames(frames, "lftagtestsrc num-buffers=1 family=2x2 count=16 seed=9", nullptr, 1);
  std::vector<std::string> ids = ids_of(truth_of(frames.buffers[0]));
  std::sort(ids.begin(), ids.end());
  fail_unless(std::unique(ids.begin(), ids.end()) == ids.end(), "2x2 has 16 ids, and 16 markers get all");
}
GST_END_TEST;

GST_START_TEST(test_truth_survives_convert_and_scale) {
  const std::string source = "lftagtestsrc num-buffers=3 count=2 seed=21";
  Frames direct, scaled;
  pull_frames(direct, source, nullptr, 3);
  pull_frames(scaled, source + " ! video/x-raw,width=640,height=480 ! videoconvert ! videoscale",
              "video/x-raw,format=I420,width=320,height=240", 3);
  fail_unless_equals_int(GST_VIDEO_INFO_WIDTH(&scaled.info), 320);
  for (int i = 0; i < 3; ++i) {
    // The meta passes unchanged: coordinates stay those of the rendered 640x480 frame.
    const FrameTruth truth = truth_of(scaled.buffers[i]);
    fail_unless(truth.camera.width == 640 && truth.camera.height == 480);
    fail_unless(gst_structure_is_equal(truth_structure(scaled.buffers[i]), truth_structure(direct.buffers[i])));
  }
}
GST_END_TEST;

GST_START_TEST(test_deterministic) {
  const std::string launch = "lftagtestsrc num-buffers=6 count=3 noise=5 motion-blur=0.6 background=gradient";
  Frames a, b, c;
  pull_frames(a, launch + " seed=7", nullptr, 6);
  pull_frames(b, launch + " seed=7", nullptr, 6);
  pull_frames(c, launch + " seed=8", nullptr, 6);
  int differing = 0;
  for (int i = 0; i < 6; ++i) {
    const cv::Mat1b pa = grey_of(a.buffers[i], &a.info), pb = grey_of(b.buffers[i], &b.info);
    fail_unless(cv::countNonZero(pa != pb) == 0, "frame %d differs between runs with one seed", i);
    fail_unless(gst_structure_is_equal(truth_structure(a.buffers[i]), truth_structure(b.buffers[i])));
    differing += cv::countNonZero(pa != grey_of(c.buffers[i], &c.info)) > 0;
  }
  fail_unless_equals_int(differing, 6);
  fail_if(ids_of(truth_of(a.buffers[0])) == ids_of(truth_of(c.buffers[0])), "another seed, the same ids");
}
GST_END_TEST;

GST_START_TEST(test_blur_and_noise) {
  const std::string launch = "lftagtestsrc num-buffers=10 count=4 seed=5 speed=4";
  Frames sharp, blurred, noisy;
  pull_frames(sharp, launch, nullptr, 10);
  pull_frames(blurred, launch + " motion-blur=1", nullptr, 10);
  pull_frames(noisy, launch + " noise=8", nullptr, 10);
  double sharp_edges = 0, blurred_edges = 0;
  for (int i = 0; i < 10; ++i) {
    // Neither changes where the markers are.
    fail_unless(gst_structure_is_equal(truth_structure(sharp.buffers[i]), truth_structure(blurred.buffers[i])));
    fail_unless(gst_structure_is_equal(truth_structure(sharp.buffers[i]), truth_structure(noisy.buffers[i])));
    const cv::Mat1b s = grey_of(sharp.buffers[i], &sharp.info);
    cv::Mat1f gx, gy;
    cv::Sobel(s, gx, CV_32F, 1, 0);
    cv::Sobel(s, gy, CV_32F, 0, 1);
    // Blur spreads an edge: its gradient energy (not its summed gradient) falls.
    sharp_edges += cv::sum(gx.mul(gx) + gy.mul(gy))[0];
    cv::Sobel(grey_of(blurred.buffers[i], &blurred.info), gx, CV_32F, 1, 0);
    cv::Sobel(grey_of(blurred.buffers[i], &blurred.info), gy, CV_32F, 0, 1);
    blurred_edges += cv::sum(gx.mul(gx) + gy.mul(gy))[0];

    cv::Mat1f difference;
    cv::subtract(grey_of(noisy.buffers[i], &noisy.info), s, difference, cv::noArray(), CV_32F);
    cv::Scalar mean, sigma;
    cv::meanStdDev(difference, mean, sigma);
    // (The flat background lies at 127.5 grey levels, which rounding turns into 128.)
    fail_unless(std::abs(sigma[0] - 8) < 0.5 && std::abs(mean[0]) < 0.75, "noise sigma %.2f mean %.2f", sigma[0],
                mean[0]);
  }
  fail_unless(blurred_edges < 0.8 * sharp_edges, "motion blur did not soften the edges (%.3g vs %.3g)", blurred_edges,
              sharp_edges);
}
GST_END_TEST;

GST_START_TEST(test_speed) {
  Frames still, normal, fast;
  pull_frames(still, "lftagtestsrc num-buffers=5 count=2 speed=0", nullptr, 5);
  pull_frames(normal, "lftagtestsrc num-buffers=9 count=2", nullptr, 9);
  pull_frames(fast, "lftagtestsrc num-buffers=5 count=2 speed=2", nullptr, 5);
  for (int i = 0; i < 5; ++i) {
    fail_unless(gst_structure_is_equal(truth_structure(still.buffers[i]), truth_structure(normal.buffers[0])),
                "speed=0 moves");
    // Twice the speed: frame i is where frame 2i was (up to the nanoseconds of timestamps).
    const FrameTruth a = truth_of(fast.buffers[i]), b = truth_of(normal.buffers[2 * i]);
    for (int k = 0; k < 2; ++k)
      for (int j = 0; j < 4; ++j) fail_unless(cv::norm(a.markers[k].corners[j] - b.markers[k].corners[j]) < 1e-4);
  }
  fail_if(gst_structure_is_equal(truth_structure(normal.buffers[0]), truth_structure(normal.buffers[1])),
          "speed=1 does not move");
}
GST_END_TEST;

static GstMessage* pop_message(GstElement* pipeline, GstMessageType types) {
  GstBus* bus = gst_element_get_bus(pipeline);
  GstMessage* message = gst_bus_timed_pop_filtered(bus, 60 * GST_SECOND, types);
  gst_object_unref(bus);
  fail_unless(message != nullptr, "no %s message", gst_message_type_get_name(types));
  return message;
}

GST_START_TEST(test_seek) {
  Frames unseeked;
  pull_frames(unseeked, "lftagtestsrc num-buffers=61 count=2 seed=3 noise=2", nullptr, 61);

  GstElement* pipeline = gst_parse_launch("lftagtestsrc count=2 seed=3 noise=2 ! fakesink name=sink", nullptr);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PAUSED) == GST_STATE_CHANGE_ASYNC);
  fail_unless(gst_element_get_state(pipeline, nullptr, nullptr, GST_CLOCK_TIME_NONE) == GST_STATE_CHANGE_SUCCESS);
  fail_unless(gst_element_seek_simple(pipeline, GST_FORMAT_TIME,
                                      GstSeekFlags(GST_SEEK_FLAG_FLUSH | GST_SEEK_FLAG_ACCURATE), 2 * GST_SECOND));
  fail_unless(gst_element_get_state(pipeline, nullptr, nullptr, GST_CLOCK_TIME_NONE) == GST_STATE_CHANGE_SUCCESS);

  GstElement* sink = gst_bin_get_by_name(GST_BIN(pipeline), "sink");
  GstSample* sample = nullptr;
  g_object_get(sink, "last-sample", &sample, nullptr);
  fail_unless(sample != nullptr);
  GstBuffer* buffer = gst_sample_get_buffer(sample);
  fail_unless_equals_uint64(GST_BUFFER_PTS(buffer), 2 * GST_SECOND);
  // Frame 60 again: the video is a function of time.
  fail_unless(gst_structure_is_equal(truth_structure(buffer), truth_structure(unseeked.buffers[60])));
  GstVideoInfo info;
  gst_video_info_from_caps(&info, gst_sample_get_caps(sample));
  fail_unless(cv::countNonZero(grey_of(buffer, &info) != grey_of(unseeked.buffers[60], &unseeked.info)) == 0);

  gst_sample_unref(sample);
  gst_object_unref(sink);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// Collects the timestamp and the truth ids of every frame reaching a pad.
struct FrameLog {
  GMutex lock;
  std::vector<GstClockTime> pts;
  std::vector<std::vector<std::string>> frames;
  FrameLog() { g_mutex_init(&lock); }
  ~FrameLog() { g_mutex_clear(&lock); }
  std::size_t size() {
    g_mutex_lock(&lock);
    const std::size_t n = frames.size();
    g_mutex_unlock(&lock);
    return n;
  }
  std::vector<std::string> last() {
    g_mutex_lock(&lock);
    std::vector<std::string> ids = frames.empty() ? std::vector<std::string>() : frames.back();
    g_mutex_unlock(&lock);
    return ids;
  }
};

static GstPadProbeReturn log_frame(GstPad*, GstPadProbeInfo* info, gpointer data) {
  FrameLog* log = static_cast<FrameLog*>(data);
  GstBuffer* buffer = GST_PAD_PROBE_INFO_BUFFER(info);
  const std::vector<std::string> ids = ids_of(truth_of(buffer));
  g_mutex_lock(&log->lock);
  log->pts.push_back(GST_BUFFER_PTS(buffer));
  log->frames.push_back(ids);
  g_mutex_unlock(&log->lock);
  return GST_PAD_PROBE_OK;
}

// A pipeline whose element "sink" logs every frame it receives.
static GstElement* logged_pipeline(const char* launch, FrameLog* log) {
  GstElement* pipeline = gst_parse_launch(launch, nullptr);
  fail_unless(pipeline != nullptr, "cannot build %s", launch);
  GstElement* sink = gst_bin_get_by_name(GST_BIN(pipeline), "sink");
  GstPad* pad = gst_element_get_static_pad(sink, "sink");
  gst_pad_add_probe(pad, GST_PAD_PROBE_TYPE_BUFFER, log_frame, log, nullptr);
  gst_object_unref(pad);
  gst_object_unref(sink);
  return pipeline;
}

GST_START_TEST(test_live) {
  FrameLog log;
  GstElement* pipeline = logged_pipeline(
      "lftagtestsrc name=src is-live=true num-buffers=4 ! "
      "video/x-raw,width=160,height=120,framerate=30/1 ! "
      "fakesink name=sink sync=true",
      &log);
  GstElement* src = gst_bin_get_by_name(GST_BIN(pipeline), "src");
  fail_unless(gst_base_src_is_live(GST_BASE_SRC(src)));
  // A live source does not preroll.
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PAUSED) == GST_STATE_CHANGE_NO_PREROLL);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  gst_message_unref(pop_message(pipeline, GST_MESSAGE_EOS));

  GstQuery* query = gst_query_new_latency();
  fail_unless(gst_element_query(pipeline, query));
  gboolean live;
  GstClockTime min, max;
  gst_query_parse_latency(query, &live, &min, &max);
  fail_unless(live);
  fail_unless_equals_uint64(min, gst_util_uint64_scale(GST_SECOND, 1, 30));
  gst_query_unref(query);

  // GstBaseSrc moves live timestamps to the running time of the first frame; the
  // frames stay one frame interval apart.
  fail_unless_equals_int(log.pts.size(), 4);
  for (std::size_t i = 1; i < 4; ++i)
    fail_unless_equals_uint64(log.pts[i] - log.pts[0], gst_util_uint64_scale(i, GST_SECOND, 30));

  gst_object_unref(src);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);
}
GST_END_TEST;

GST_START_TEST(test_bad_property_values) {
  GstElement* src = gst_element_factory_make("lftagtestsrc", nullptr);
  fail_unless(src != nullptr);
  g_object_set(src, "ids", "5,0x10", "count", 2u, "noise", 1.5, nullptr);

  // Each is refused and changes nothing: bad ids on the bus (see test_bad_settings_fail_the_start),
  g_object_set(src, "ids", "12,abc", nullptr);
  g_object_set(src, "ids", "1,,2", nullptr);
  g_object_set(src, "ids", "0-64", nullptr);
  g_object_set(src, "ids", "9-3", nullptr);
  // values out of the declared ranges by GLib, with a warning.
  ASSERT_WARNING(g_object_set(src, "count", 65u, nullptr));
  ASSERT_WARNING(g_object_set(src, "noise", -1.0, nullptr));
  ASSERT_WARNING(g_object_set(src, "motion-blur", 1.5, nullptr));
  ASSERT_WARNING(g_object_set(src, "tag-size", 0.0, nullptr));
  ASSERT_WARNING(g_object_set(src, "family", 9, nullptr));
  gchar* ids;
  guint count;
  double noise;
  gint family;
  g_object_get(src, "ids", &ids, "count", &count, "noise", &noise, "family", &family, nullptr);
  fail_unless_equals_string(ids, "5,0x10");
  fail_unless_equals_int(count, 2);
  fail_unless(noise == 1.5);
  fail_unless_equals_int(family, 3);
  g_free(ids);

  // Unsetting ids goes back to random ones.
  g_object_set(src, "ids", nullptr, nullptr);
  g_object_get(src, "ids", &ids, nullptr);
  fail_unless(ids == nullptr);
  gst_object_unref(src);

  // family is an enum: a launch line with an unknown family is refused, naming it.
  for (const char* bad : {"9x9", "4X4", "3x3,4x4"}) {
    GError* error = nullptr;
    GstElement* pipeline =
        gst_parse_launch((std::string("lftagtestsrc family=") + bad + " ! fakesink").c_str(), &error);
    fail_unless(error != nullptr, "family=%s accepted", bad);
    fail_unless(std::string(error->message).find(bad) != std::string::npos, "%s", error->message);
    g_error_free(error);
    if (pipeline) gst_object_unref(pipeline);
  }
}
GST_END_TEST;

// The error that stops `launch` from playing: it must name `needle`.
static void expect_error(const std::string& launch, const char* needle, GQuark domain) {
  GstElement* pipeline = gst_parse_launch(launch.c_str(), nullptr);
  fail_unless(pipeline != nullptr);
  gst_element_set_state(pipeline, GST_STATE_PLAYING);
  GstMessage* message = pop_message(pipeline, GST_MESSAGE_ERROR);
  GError* error = nullptr;
  gst_message_parse_error(message, &error, nullptr);
  fail_unless(error->domain == domain, "'%s': unexpected error domain", error->message);
  fail_unless(std::string(error->message).find(needle) != std::string::npos, "'%s' does not name '%s'", error->message,
              needle);
  g_error_free(error);
  gst_message_unref(message);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);
}

GST_START_TEST(test_bad_settings_fail_the_start) {
  const std::string data = LFTAG_TEST_DATA;
  const GQuark resource = GST_RESOURCE_ERROR, core = GST_CORE_ERROR;
  expect_error("lftagtestsrc ids=16384 ! fakesink", "16384", resource);
  expect_error("lftagtestsrc ids=16384 ! fakesink", "3x3", resource);
  // Ids that cannot be read, set before the start (no bus yet): the start fails naming them.
  expect_error("lftagtestsrc ids=12,abc ! fakesink", "\"12,abc\"", resource);
  expect_error("lftagtestsrc ids=9-3 ! fakesink", "\"9-3\"", resource);
  expect_error("lftagtestsrc calibration-file=/nonexistent/camera.yml ! fakesink", "/nonexistent/camera.yml", resource);
  expect_error("lftagtestsrc calibration-file=" + data + "/malformed.yml ! fakesink", "malformed.yml", resource);
  expect_error("lftagtestsrc calibration-file=" + data + "/no_matrix.yml ! fakesink", "camera_matrix", resource);
  expect_error("lftagtestsrc calibration-file=" + data + "/nul_byte.xml ! fakesink", "nul_byte.xml", resource);
  expect_error("lftagtestsrc background=photo ! fakesink", "background-location", resource);
  expect_error("lftagtestsrc background=photo background-location=/nonexistent/street.jpg ! fakesink",
               "/nonexistent/street.jpg", resource);
  expect_error("lftagtestsrc background=photo background-location=" + data + "/malformed.yml ! fakesink",
               "malformed.yml", resource);
  // A FIFO nobody writes to is refused at once (opening it would block), and a 4 KB JPEG
  // whose fill bytes hide a frame of 32768 x 32768 by its size, before it is decoded.
  gchar* dir = g_dir_make_tmp("lftagtestsrc-XXXXXX", nullptr);
  fail_unless(dir != nullptr);
  const std::string fifo = std::string(dir) + "/street.jpg", filled = std::string(dir) + "/filled.jpg";
  fail_unless(mkfifo(fifo.c_str(), 0600) == 0);
  expect_error("lftagtestsrc background=photo background-location=" + fifo + " ! fakesink", "FIFO", resource);
  std::string jpeg = {'\xFF', '\xD8'};
  jpeg.append(4100, '\xFF');
  jpeg += std::string("\xFF\xC0\x00\x0B\x08\x80\x00\x80\x00\x01\x01\x11\x00", 13);
  fail_unless(g_file_set_contents(filled.c_str(), jpeg.data(), gssize(jpeg.size()), nullptr));
  expect_error("lftagtestsrc background=photo background-location=" + filled + " ! fakesink", "32768x32768", resource);
  g_unlink(fifo.c_str());
  g_unlink(filled.c_str());
  g_rmdir(dir);
  g_free(dir);
  // A calibration for 640x480 cannot describe a 16:9 frame.
  expect_error("lftagtestsrc calibration-file=" + data +
                   "/opencv_sample.yml ! "
                   "video/x-raw,width=1280,height=720 ! fakesink",
               "640x480", core);
}
GST_END_TEST;

GST_START_TEST(test_calibration_file) {
  const std::string data = LFTAG_TEST_DATA;
  Frames own, scaled, xml;
  // The calibration's frame size is the default; another size of its shape scales it.
  pull_frames(own, "lftagtestsrc num-buffers=1 calibration-file=" + data + "/opencv_sample.yml", nullptr, 1);
  fail_unless_equals_int(GST_VIDEO_INFO_WIDTH(&own.info), 640);
  const FrameTruth truth = truth_of(own.buffers[0]);
  fail_unless(truth.camera.fx == 628.158 && truth.camera.cy == 260.908);
  fail_unless_equals_int(truth.camera.distortion.size(), 5);
  fail_unless(truth.camera.distortion[0] == 0.0995485);

  pull_frames(scaled, "lftagtestsrc num-buffers=1 calibration-file=" + data + "/opencv_sample.yml",
              "video/x-raw,width=1280,height=960", 1);
  fail_unless(truth_of(scaled.buffers[0]).camera.fx == 2 * 628.158);

  // GStreamer's cameracalibrate writes XML with other key names.
  pull_frames(xml, "lftagtestsrc num-buffers=1 calibration-file=" + data + "/gst_cameracalibrate.xml", nullptr, 1);
  fail_unless(truth_of(xml.buffers[0]).camera.fx == 800);
}
GST_END_TEST;

GST_START_TEST(test_camera_properties) {
  Frames frames;
  pull_frames(frames, "lftagtestsrc num-buffers=1 fx=500 cy=200", "video/x-raw,width=320,height=240", 1);
  const FrameTruth truth = truth_of(frames.buffers[0]);
  fail_unless(truth.camera.fx == 500 && truth.camera.fy == 500);
  fail_unless(truth.camera.cx == 159.5 && truth.camera.cy == 200);
}
GST_END_TEST;

// "Not set" is a value no camera has (fx, fy 0; cx, cy -1), so a principal point of 0
// is 0, never the frame centre; between -1 and 0 is refused, naming the value.
GST_START_TEST(test_camera_not_set) {
  GstElement* src = gst_element_factory_make("lftagtestsrc", nullptr);
  double fx = -2, fy = -2, cx = -2, cy = -2;
  g_object_get(src, "fx", &fx, "fy", &fy, "cx", &cx, "cy", &cy, nullptr);
  fail_unless(fx == 0 && fy == 0 && cx == -1 && cy == -1, "defaults %g %g %g %g", fx, fy, cx, cy);
  g_object_set(src, "cx", 0.0, "cy", 0.0, nullptr);
  g_object_get(src, "cx", &cx, "cy", &cy, nullptr);
  fail_unless(cx == 0 && cy == 0);
  g_object_set(src, "cx", -0.5, nullptr);  // refused: 0 stays
  g_object_get(src, "cx", &cx, nullptr);
  fail_unless(cx == 0);
  g_object_set(src, "cx", -1.0, nullptr);  // not set again
  g_object_get(src, "cx", &cx, nullptr);
  fail_unless(cx == -1);
  ASSERT_WARNING(g_object_set(src, "cy", -2.0, nullptr));
  gst_object_unref(src);

  Frames zero, x_only;
  pull_frames(zero, "lftagtestsrc num-buffers=1 fx=500 cx=0 cy=0", "video/x-raw,width=320,height=240", 1);
  const FrameTruth truth = truth_of(zero.buffers[0]);
  fail_unless(truth.camera.cx == 0 && truth.camera.cy == 0, "cx %g cy %g", truth.camera.cx, truth.camera.cy);
  pull_frames(x_only, "lftagtestsrc num-buffers=1 fx=500 cx=0", "video/x-raw,width=320,height=240", 1);
  fail_unless(truth_of(x_only.buffers[0]).camera.cx == 0 && truth_of(x_only.buffers[0]).camera.cy == 119.5);

  const GQuark resource = GST_RESOURCE_ERROR;
  expect_error("lftagtestsrc fx=500 cx=-0.5 ! fakesink", "\"-0.5\"", resource);
  expect_error("lftagtestsrc fx=500 cy=-0.25 ! fakesink", "cy", resource);

  // Without fx the principal point counts for nothing: said, not silent.
  GstElement* pipeline = gst_parse_launch("lftagtestsrc num-buffers=1 cx=0 ! fakesink", nullptr);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  GstMessage* message = pop_message(pipeline, GST_MESSAGE_WARNING);
  GError* error = nullptr;
  gst_message_parse_warning(message, &error, nullptr);
  fail_unless(std::string(error->message).find("cx") != std::string::npos, "%s", error->message);
  fail_unless(std::string(error->message).find("without fx") != std::string::npos, "%s", error->message);
  g_error_free(error);
  gst_message_unref(message);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// Waits (up to a generous limit, not a timing requirement) until `done` holds.
template <class Done>
static void wait_for(Done done, const char* what) {
  for (int i = 0; i < 60000 && !done(); ++i) g_usleep(1000);
  fail_unless(done(), "%s never happened", what);
}

GST_START_TEST(test_changes_while_playing) {
  FrameLog log;
  GstElement* pipeline = logged_pipeline(
      "lftagtestsrc name=src ids=1,2 ! video/x-raw,width=160,height=120 ! "
      "fakesink name=sink sync=false",
      &log);
  GstElement* src = gst_bin_get_by_name(GST_BIN(pipeline), "src");
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);

  const std::vector<std::string> first{"1", "2"}, second{"7", "8", "9"}, third{"99999"};
  wait_for([&] { return log.size() >= 3; }, "playing");
  g_object_set(src, "ids", "7-9", nullptr);
  wait_for([&] { return log.last() == second; }, "the change of ids");

  // 99999 is not a 3x3 id: a warning, and the markers stay.
  g_object_set(src, "ids", "99999", nullptr);
  GstMessage* warning = pop_message(pipeline, GST_MESSAGE_WARNING);
  GError* error = nullptr;
  gst_message_parse_warning(warning, &error, nullptr);
  fail_unless(std::string(error->message).find("99999") != std::string::npos, "%s", error->message);
  g_error_free(error);
  gst_message_unref(warning);
  const std::size_t after_warning = log.size();
  wait_for([&] { return log.size() >= after_warning + 5; }, "frames after the warning");
  fail_unless(log.last() == second);

  // ... but it is a 4x4 id.
  g_object_set(src, "family", 4, nullptr);
  wait_for([&] { return log.last() == third; }, "the change of family");

  // A property read only when the source starts is refused out loud while playing, and
  // keeps its value (it was stored and silently ignored).
  g_object_set(src, "speed", 5.0, "calibration-file", "/some/camera.yml", nullptr);
  for (const char* name : {"speed", "calibration-file"}) {
    warning = pop_message(pipeline, GST_MESSAGE_WARNING);
    gst_message_parse_warning(warning, &error, nullptr);
    fail_unless(std::string(error->message)
                        .find(std::string("\"") + name +
                              "\" can only change in the NULL or READY "
                              "state, not in PLAYING") != std::string::npos,
                "%s", error->message);
    g_error_free(error);
    gst_message_unref(warning);
  }
  double speed = 0;
  gchar* calibration = nullptr;
  g_object_get(src, "speed", &speed, "calibration-file", &calibration, nullptr);
  fail_unless(speed == 1.0 && calibration == nullptr, "speed %g, calibration %s", speed, calibration);

  gst_element_set_state(pipeline, GST_STATE_NULL);
  // Each frame shows one whole set, and the sets follow in order.
  std::size_t stage = 0;
  const std::vector<std::string>* stages[] = {&first, &second, &third};
  for (const std::vector<std::string>& ids : log.frames) {
    while (stage < 3 && ids != *stages[stage]) ++stage;
    fail_unless(stage < 3, "a frame with unexpected ids");
  }
  fail_unless_equals_int(stage, 2);

  gst_object_unref(src);
  gst_object_unref(pipeline);
}
GST_END_TEST;

static Suite* lftagtestsrc_suite(void) {
  Suite* s = suite_create("lftagtestsrc");
  TCase* tc = tcase_create("general");
  suite_add_tcase(s, tc);
  tcase_add_test(tc, test_default_caps);
  tcase_add_test(tc, test_every_format);
  tcase_add_test(tc, test_odd_sizes);
  tcase_add_test(tc, test_truth_3x3);
  tcase_add_test(tc, test_truth_4x4_repeating_ids);
  tcase_add_test(tc, test_truth_8x8_random_ids);
  tcase_add_test(tc, test_large_ids_exact);
  tcase_add_test(tc, test_random_ids_distinct);
  tcase_add_test(tc, test_truth_survives_convert_and_scale);
  tcase_add_test(tc, test_deterministic);
  tcase_add_test(tc, test_blur_and_noise);
  tcase_add_test(tc, test_speed);
  tcase_add_test(tc, test_seek);
  tcase_add_test(tc, test_live);
  tcase_add_test(tc, test_bad_property_values);
  tcase_add_test(tc, test_bad_settings_fail_the_start);
  tcase_add_test(tc, test_calibration_file);
  tcase_add_test(tc, test_camera_properties);
  tcase_add_test(tc, test_camera_not_set);
  tcase_add_test(tc, test_changes_while_playing);
  return s;
}

LFTAG_CHECK_MAIN(lftagtestsrc)
