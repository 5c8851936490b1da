// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftagjson.h"

#include "json.hpp"  // src/tools: the JSON of a detection
#include "metaconversion.h"

namespace lftag::gst {
namespace {

nlohmann::ordered_json time_json(GstClockTime t) {
  if (!GST_CLOCK_TIME_IS_VALID(t)) return nullptr;
  return std::uint64_t(t);
}

}  // namespace

std::optional<nlohmann::ordered_json> buffer_json(GstBuffer* buffer, const GstSegment& segment, guint64 frame) {
  const std::optional<FrameDetections> found = read_detection_meta(buffer);
  if (!found) return std::nullopt;

  const GstClockTime pts = GST_BUFFER_PTS(buffer);
  const bool in_time = segment.format == GST_FORMAT_TIME && GST_CLOCK_TIME_IS_VALID(pts);
  nlohmann::ordered_json out;
  out["frame"] = std::uint64_t(frame);
  out["pts"] = time_json(pts);
  out["time"] = GST_CLOCK_TIME_IS_VALID(pts) ? nlohmann::ordered_json(double(pts) / GST_SECOND) : nullptr;
  out["dts"] = time_json(GST_BUFFER_DTS(buffer));
  out["duration"] = time_json(GST_BUFFER_DURATION(buffer));
  out["running_time"] = in_time ? time_json(gst_segment_to_running_time(&segment, GST_FORMAT_TIME, pts)) : nullptr;
  out["stream_time"] = in_time ? time_json(gst_segment_to_stream_time(&segment, GST_FORMAT_TIME, pts)) : nullptr;
  out["width"] = found->width;
  out["height"] = found->height;
  // false: passed on without detection (late under late-frames=skip, or unreadable), so
  // its empty detections say nothing about markers.
  out["analysed"] = found->analysed;
  nlohmann::ordered_json detections = nlohmann::ordered_json::array();
  for (const Detection& d : found->detections) detections.push_back(nlohmann::ordered_json(tools::detection_json(d)));
  out["detections"] = std::move(detections);
  return out;
}

}  // namespace lftag::gst
