// SPDX-License-Identifier: LGPL-2.1-or-later
#include "h264.hpp"

#include <algorithm>
#include <stdexcept>

#ifdef BENCH_HAVE_GSTREAMER
#include <mutex>

#include <gst/app/gstappsink.h>
#include <gst/app/gstappsrc.h>
#include <gst/gst.h>
#include <gst/video/video.h>
#endif

namespace bench {

#ifndef BENCH_HAVE_GSTREAMER

std::string h264_unavailable() {
  return "lftag-bench was built without gstreamer-app-1.0 and gstreamer-video-1.0 (libgstreamer-plugins-base1.0-dev)";
}

std::vector<cv::Mat1b> h264_round_trip(const std::vector<cv::Mat1b>&, int, int) {
  throw std::runtime_error(h264_unavailable());
}

#else

namespace {

// The elements and the Debian package that brings each.
const std::vector<std::pair<const char*, const char*> > kElements{{"appsrc", "gstreamer1.0-plugins-base"},
                                                                  {"appsink", "gstreamer1.0-plugins-base"},
                                                                  {"x264enc", "gstreamer1.0-plugins-ugly"},
                                                                  {"avdec_h264", "gstreamer1.0-libav"}};

const std::string& availability() {
  static const std::string message = [] {
    GError* error = nullptr;
    if (!gst_init_check(nullptr, nullptr, &error)) {
      const std::string why = std::string("GStreamer does not start: ") + (error ? error->message : "unknown error");
      if (error) g_error_free(error);
      return why;
    }
    std::string missing;
    for (const auto& [element, package] : kElements)
      if (GstElementFactory* f = gst_element_factory_find(element))
        gst_object_unref(f);
      else
        missing += std::string(missing.empty() ? "" : ", ") + element + " (" + package + ")";
    return missing.empty() ? std::string() : "GStreamer elements missing: " + missing;
  }();
  return message;
}

// Unrefs a GStreamer object at the end of a scope.
template <class T>
struct Ref {
  T* p;
  ~Ref() {
    if (p) gst_object_unref(p);
  }
};

// Stops and frees the pipeline at the end of a scope, whatever happened in it.
struct Pipeline {
  GstElement* p;
  ~Pipeline() {
    if (!p) return;
    gst_element_set_state(p, GST_STATE_NULL);
    gst_object_unref(p);
  }
};

std::string bus_error(GstElement* pipeline) {
  Ref<GstBus> bus{gst_element_get_bus(pipeline)};
  GstMessage* message = gst_bus_pop_filtered(bus.p, GST_MESSAGE_ERROR);
  if (!message) return "";
  GError* error = nullptr;
  gst_message_parse_error(message, &error, nullptr);
  std::string text = error ? error->message : "unknown error";
  if (error) g_error_free(error);
  gst_message_unref(message);
  return text;
}

}  // namespace

std::string h264_unavailable() { return availability(); }

std::vector<cv::Mat1b> h264_round_trip(const std::vector<cv::Mat1b>& frames, int kbps, int fps) {
  if (!availability().empty()) throw std::runtime_error(availability());
  if (frames.empty()) return {};
  const int width = frames[0].cols, height = frames[0].rows;
  // One thread each way: the same stream whatever the machine, and no competition
  // with the benchmark's own workers.
  const std::string description =
      "appsrc name=src format=time ! x264enc bitrate=" + std::to_string(kbps) +
      " speed-preset=veryfast tune=zerolatency key-int-max=" + std::to_string(fps) +
      " threads=1 ! avdec_h264 max-threads=1 ! video/x-raw,format=I420 ! appsink name=sink sync=false";
  GError* error = nullptr;
  GstElement* pipeline = gst_parse_launch(description.c_str(), &error);
  if (error) {
    const std::string why = error->message;
    g_error_free(error);
    if (pipeline) gst_object_unref(pipeline);
    throw std::runtime_error("h264: " + why);
  }
  Pipeline owner{pipeline};
  Ref<GstElement> src{gst_bin_get_by_name(GST_BIN(pipeline), "src")};
  Ref<GstElement> sink{gst_bin_get_by_name(GST_BIN(pipeline), "sink")};

  GstVideoInfo info;
  gst_video_info_set_format(&info, GST_VIDEO_FORMAT_I420, guint(width), guint(height));
  info.fps_n = fps, info.fps_d = 1;
  GstCaps* caps = gst_video_info_to_caps(&info);
  gst_app_src_set_caps(GST_APP_SRC(src.p), caps);
  gst_caps_unref(caps);
  if (gst_element_set_state(pipeline, GST_STATE_PLAYING) == GST_STATE_CHANGE_FAILURE)
    throw std::runtime_error("h264: the pipeline does not start: " + bus_error(pipeline));

  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].cols != width || frames[i].rows != height) throw std::invalid_argument("h264: frames differ in size");
    GstBuffer* buffer = gst_buffer_new_allocate(nullptr, info.size, nullptr);
    GstVideoFrame frame;
    gst_video_frame_map(&frame, &info, buffer, GST_MAP_WRITE);
    for (int y = 0; y < height; ++y)
      std::copy(
          frames[i].ptr(y), frames[i].ptr(y) + width,
          static_cast<guint8*>(GST_VIDEO_FRAME_PLANE_DATA(&frame, 0)) + y * GST_VIDEO_FRAME_PLANE_STRIDE(&frame, 0));
    for (int plane = 1; plane < 3; ++plane)  // neutral chroma: a grey picture
      for (int y = 0; y < GST_VIDEO_FRAME_COMP_HEIGHT(&frame, plane); ++y)
        std::fill_n(static_cast<guint8*>(GST_VIDEO_FRAME_PLANE_DATA(&frame, plane)) +
                        y * GST_VIDEO_FRAME_PLANE_STRIDE(&frame, plane),
                    GST_VIDEO_FRAME_COMP_WIDTH(&frame, plane), guint8(128));
    gst_video_frame_unmap(&frame);
    GST_BUFFER_PTS(buffer) = gst_util_uint64_scale(i, GST_SECOND, guint64(fps));
    GST_BUFFER_DURATION(buffer) = gst_util_uint64_scale(1, GST_SECOND, guint64(fps));
    if (gst_app_src_push_buffer(GST_APP_SRC(src.p), buffer) != GST_FLOW_OK) break;  // takes the buffer
  }
  gst_app_src_end_of_stream(GST_APP_SRC(src.p));

  std::vector<cv::Mat1b> out;
  while (GstSample* sample = gst_app_sink_pull_sample(GST_APP_SINK(sink.p))) {
    GstVideoInfo got;
    GstVideoFrame frame;
    if (gst_video_info_from_caps(&got, gst_sample_get_caps(sample)) &&
        gst_video_frame_map(&frame, &got, gst_sample_get_buffer(sample), GST_MAP_READ)) {
      cv::Mat1b luma(GST_VIDEO_FRAME_HEIGHT(&frame), GST_VIDEO_FRAME_WIDTH(&frame));
      for (int y = 0; y < luma.rows; ++y) {
        const guint8* row = static_cast<const guint8*>(GST_VIDEO_FRAME_PLANE_DATA(&frame, 0)) +
                            y * GST_VIDEO_FRAME_PLANE_STRIDE(&frame, 0);
        std::copy(row, row + luma.cols, luma.ptr(y));
      }
      gst_video_frame_unmap(&frame);
      out.push_back(luma);
    }
    gst_sample_unref(sample);
  }
  const std::string failure = bus_error(pipeline);
  if (!failure.empty()) throw std::runtime_error("h264: " + failure);
  if (out.size() != frames.size() || out[0].size() != frames[0].size())
    throw std::runtime_error("h264: " + std::to_string(frames.size()) + " frames in, " + std::to_string(out.size()) +
                             " out");
  return out;
}

#endif

}  // namespace bench
