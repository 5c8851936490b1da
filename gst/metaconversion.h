// SPDX-License-Identifier: LGPL-2.1-or-later
// The plugin's metas (see lftag-meta.h for names and layout): registration, and
// conversion between library records and GstStructures in both directions, so the
// elements write them and tests (and the detector's messages) read them back.
#pragma once

#include <optional>
#include <vector>

#include <gst/gst.h>

#include <lftag/camera.hpp>
#include <lftag/detector.hpp>
#include <lftag/render.hpp>
#include <lftag/tracker.hpp>

#include "lftag-meta.h"

namespace lftag::gst {

// Registered on first use; safe to call from any thread.
const GstMetaInfo* detection_meta_info();
const GstMetaInfo* truth_meta_info();

// One "lftag/detection" or "lftag/truth" structure (the caller owns it); with `track`,
// the track's fields too (lftag-meta.h).
GstStructure* detection_structure(const Detection& detection, const TrackInfo* track = nullptr);
GstStructure* truth_structure(const MarkerTruth& truth);

// Sets `field` of `s` to a GstValueArray of detection structures: the "detections"
// of the meta, and of bus messages. `tracks`, when given, holds one track per detection.
void set_detections(GstStructure* s, const char* field, const std::vector<Detection>& detections,
                    const std::vector<TrackInfo>* tracks = nullptr);

// Attach a meta to a writable buffer.
// `analysed` false: the frame was passed on without detection (late, or unreadable).
void add_detection_meta(GstBuffer* buffer, int width, int height, const std::vector<Detection>& detections,
                        bool analysed = true, const std::vector<TrackInfo>* tracks = nullptr);
// The frame size is the camera's.
void add_truth_meta(GstBuffer* buffer, const Camera& camera, const std::vector<MarkerTruth>& markers);

// Reading back. These throw std::invalid_argument naming the field that is missing
// or malformed. A read Detection or MarkerTruth holds exactly what the structure does.
Detection detection_from_structure(const GstStructure* s);
MarkerTruth truth_from_structure(const GstStructure* s);
// The track fields of a detection structure; empty when it has none (tracking off).
std::optional<TrackInfo> track_from_structure(const GstStructure* s);

struct FrameDetections {
  int width = 0, height = 0;
  bool analysed = true;
  std::vector<Detection> detections;
  std::vector<std::optional<TrackInfo>> tracks;  // one per detection
};
struct FrameTruth {
  Camera camera;  // width and height are the frame's
  std::vector<MarkerTruth> markers;
};
// Empty when the buffer carries no such meta.
std::optional<FrameDetections> read_detection_meta(GstBuffer* buffer);
std::optional<FrameTruth> read_truth_meta(GstBuffer* buffer);

}  // namespace lftag::gst
