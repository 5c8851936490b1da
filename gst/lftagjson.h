// SPDX-License-Identifier: LGPL-2.1-or-later
// A buffer's LFTag detections as one line of JSON: what lftagpublish writes and
// `lftag annotate --jsonl` keeps. The detections are src/io/detection_json.hpp's, the same
// objects `lftag detect` prints.
#pragma once

#include <optional>
#include <string>

#include <gst/gst.h>
#include <lftag/tracker.hpp>
#include <nlohmann/json.hpp>

namespace lftag::gst {

// The record of `buffer`, the `frame`-th of its stream (from 0), or nothing when the
// buffer carries no LFTagMeta. Keys, in this order: "frame", "pts", "time" (pts in
// seconds), "dts", "duration", "running_time", "stream_time" (nanoseconds, null when
// unknown; the last two from `segment`, when it is in time), "width", "height" (the
// analysed frame), "analysed" (false for a frame passed on without detection) and
// "detections" (each with a "track" object, track_json, when lftagdetect tracked it).
// Throws std::invalid_argument on a malformed meta.
// A marker's track: "id", "state" ("measured" or "predicted"), "age", "first_seen",
// "last_seen" (seconds), "pose_flipped" and "smoothed_pose" ({"rvec", "tvec"}, or null
// without smoothing).
nlohmann::ordered_json track_json(const TrackInfo& track);

std::optional<nlohmann::ordered_json> buffer_json(GstBuffer* buffer, const GstSegment& segment, guint64 frame);

}  // namespace lftag::gst
