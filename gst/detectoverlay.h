/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* lftagdetect's overlay: detections drawn as a GstVideoOverlayComposition, either blended
 * into the frame or attached as a GstVideoOverlayCompositionMeta for a downstream element
 * that draws it (a video sink or compositor that says so in the allocation query). */
#pragma once

#include <vector>

#include <gst/video/video.h>
#include <opencv2/core.hpp>

#include <lftag/camera.hpp>
#include <lftag/draw.hpp>

namespace lftag::gst {

class DetectOverlay {
 public:
  /* One rectangle per marker, covering only what was drawn around it (so that blending
   * touches the markers' surroundings, not the span between them). The caller owns the
   * composition. */
  GstVideoOverlayComposition* compose(int width, int height, const DrawOptions& options, const Camera& camera,
                                      const std::vector<Detection>& detections);
  /* Forgets the layer (a new frame size, or a half-drawn layer after an error). */
  void reset();

 private:
  cv::Mat4b layer_;  // transparent BGRA, cleared where each rectangle was taken
  cv::Mat1b alpha_;  // the layer's alpha, where it is searched
};

/* Whether the element downstream of `srcpad` takes GstVideoOverlayCompositionMeta for
 * frames of `caps` (it lists the meta in its answer to an allocation query). */
bool downstream_takes_compositions(GstPad* srcpad, GstCaps* caps);

/* Attaches `composition` to a writable buffer, after the rectangles of a composition
 * it already carries (upstream's overlay stays under ours). */
void attach_composition(GstBuffer* buffer, GstVideoOverlayComposition* composition);

}  // namespace lftag::gst
