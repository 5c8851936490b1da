// SPDX-License-Identifier: LGPL-2.1-or-later
// Drawing detections onto images (kept apart from detection).
#pragma once

#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/camera.hpp"
#include "lftag/detector.hpp"
#include "lftag/trace.hpp"

namespace lftag {

struct DrawOptions {
  bool outline = true;  // the marker's outer border
  bool id = true;       // family and id beside the marker (under it, or over it at the frame's foot)
  bool axes = true;     // x red, y green, z blue, one tag size long
  // Line width and text size in pixels; 0 picks them from the image size.
  double line_width = 0;
  double text_height = 0;
};

// Draws onto a CV_8UC1, CV_8UC3 (BGR) or CV_8UC4 (BGRA) image, anti-aliased. Colours are
// BGR(A); a BGRA image gets opaque strokes on what it holds (use a transparent image for
// an overlay layer). `camera` projects the axes (distortion included).
void draw_detections(cv::Mat& image, const std::vector<Detection>& detections, const Camera& camera,
                     const DrawOptions& options = {});

// Debug images of one frame (the paper's figure 5): "threshold", "candidates", "keypoints",
// "hypotheses", "final", each a BGR image over the grey frame.
std::map<std::string, cv::Mat> draw_trace(const cv::Mat& grey, const DetectionTrace& trace, const Camera& camera);

}  // namespace lftag
