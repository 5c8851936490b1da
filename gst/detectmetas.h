/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The metas lftagdetect attaches to a frame: the LFTagMeta and one region-of-interest
 * meta per detection. */
#pragma once

#include <vector>

#include <gst/video/video.h>
#include <opencv2/core.hpp>

#include <lftag/detector.hpp>
#include <lftag/tracker.hpp>

namespace lftag::gst {

/* The pixels of a detection: its outer corners' bounding box, clipped to the frame. */
cv::Rect bounding_box(const Detection& detection, int width, int height);

/* Replaces the LFTagMeta and "lftag" region metas of a writable buffer with those of
 * `detections` (region ids numbered on from the buffer's other regions); `tracks`, when
 * given, holds each detection's track. */
void attach_detections(GstBuffer* buffer, int width, int height, const std::vector<Detection>& detections,
                       const std::vector<TrackInfo>* tracks = nullptr);

/* The same for a frame passed on without analysis: an LFTagMeta with "analysed" FALSE
 * and no detections, and no regions. */
void attach_unanalysed(GstBuffer* buffer, int width, int height);

}  // namespace lftag::gst
