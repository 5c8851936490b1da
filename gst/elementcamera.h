/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The camera settings lftagdetect and lftagtestsrc share: a calibration file loaded when
 * the element starts, else fx, fy, cx, cy (and distortion) set by hand, else the
 * library's default camera for the frame size. */
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <gst/gst.h>

#include "lftag/camera.hpp"

namespace lftag::gst {

/* The hand-set camera properties; 0 means unset. */
struct PinholeSettings {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::vector<double> distortion;
};

/* The camera a width x height frame is seen with: the calibration (scaled to the frame),
 * else the hand-set pinhole (fy defaults to fx, the principal point to the frame centre),
 * else Camera::default_for (uncalibrated). Throws when the calibration cannot fit the
 * frame. */
Camera frame_camera(const PinholeSettings& pinhole, const std::optional<Camera>& calibration, int width, int height);

/* Loads the calibration file at `path` into `calibration`. On failure posts an element
 * error on `element` that names the file and what is wrong (missing, or malformed) and
 * returns FALSE, so that the state change fails. */
gboolean load_calibration(GstElement* element, const std::string& path, std::optional<Camera>& calibration);

}  // namespace lftag::gst
