// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftagjson.h"

#include "detection_json.hpp"  // src/io: the JSON of a detection
#include "metaconversion.h"

namespace lftag::gst {
namespace {

nlohmann::ordered_json time_json(GstClockTime t) {
  if (!GST_CLOCK_TIME_IS_VALID(t)) return nullptr;
  return std::uint64_t(t);
}

}  // namespace

nlohmann::ordered_json track_json(const TrackInfo& t) {
  nlohmann::ordered_json out;
  out["id"] = std::uint64_t(t.id);
  out["state"] = track_state_name(t.state);
  out["age"] = t.age();
  out["first_seen"] = t.first_seen;
  out["last_seen"] = t.last_seen;
  out["pose_flipped"] = t.flipped;
  out["smoothed_pose"] = t.smoothed ? nlohmann::ordered_json{{"rvec", io::vec_json(t.smoothed_rvec)},
                                                             {"tvec", io::vec_json(t.smoothed_tvec)}}
                                    : nlohmann::ordered_json(nullptr);
  return out;
}

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
  for (std::size_t i = 0; i < found->detections.size(); ++i) {
    nlohmann::ordered_json d(io::detection_json(found->detections[i]));
    // Only with tracking: what lftagdetect's tracker said of this marker.
    if (i < found->tracks.size() && found->tracks[i]) d["track"] = track_json(*found->tracks[i]);
    detections.push_back(std::move(d));
  }
  out["detections"] = std::move(detections);
  return out;
}

}  // namespace lftag::gst
