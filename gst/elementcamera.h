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

/* "Not set" in the properties fx, fy, cx and cy is a documented value outside the range
 * of valid ones, as GStreamer properties do: 0 for fx and fy (no focal length is 0) and
 * -1 for cx and cy, which take principal points from 0 to kMaxProperty (so that a
 * principal point of 0 means 0). Inside the elements "not set" is an empty optional. */
constexpr double kUnsetFocal = 0.0;
constexpr double kUnsetPrincipal = -1.0;
constexpr double kMaxProperty = 1e6;

/* A property value read into the settings: empty for the "not set" value. */
std::optional<double> focal_from_property(double value);
std::optional<double> principal_from_property(double value);
/* The settings written back into a property value. */
double focal_to_property(const std::optional<double>& focal);
double principal_to_property(const std::optional<double>& principal);
/* For set_property of cx or cy: a value between -1 and 0 is neither "not set" nor a
 * principal point. Refuses it with refuse_value() (a warning; the old value stays) and
 * returns the refusal, which the element keeps until a good value clears it and checks
 * with no_refused_values() at start; returns empty when the value is accepted. */
std::string refuse_principal(GstElement* element, const char* property, double value);

/* The hand-set camera properties; empty when not set. */
struct PinholeSettings {
  std::optional<double> fx, fy, cx, cy;
  std::vector<double> distortion;
};

/* The camera a width x height frame is seen with: the calibration (scaled to the frame),
 * else the hand-set pinhole (fy defaults to fx, the principal point to the frame centre),
 * else Camera::default_for (uncalibrated). Throws when the calibration cannot fit the
 * frame. */
Camera frame_camera(const PinholeSettings& pinhole, const std::optional<Camera>& calibration, int width, int height);

/* A warning naming the hand-set properties frame_camera() ignores (fy, cx, cy and
 * distortion without fx; all of them with a calibration file), so that none is dropped
 * silently; empty when it ignores none. */
std::string ignored_pinhole(const PinholeSettings& pinhole, bool calibrated);

/* Loads the calibration file at `path` into `calibration`. On failure posts an element
 * error on `element` with Camera::load's message, which names the file and what is wrong
 * (missing, not a regular file, malformed), and returns FALSE, so that the state change
 * fails. */
gboolean load_calibration(GstElement* element, const std::string& path, std::optional<Camera>& calibration);

}  // namespace lftag::gst
