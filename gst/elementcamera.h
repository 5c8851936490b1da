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

/* The camera properties both elements install, with consecutive property ids from the
 * element's first camera id: fx, fy, cx, cy, calibration-file and, with a lens,
 * distortion. */
enum CameraProperty : guint {
  kCameraFx,
  kCameraFy,
  kCameraCx,
  kCameraCy,
  kCameraCalibrationFile,
  kCameraDistortion,
  kCameraProperties /* how many ids they take */
};

/* What the element's own documentation of two properties says (the default camera, what
 * a calibration's image size means to it). */
struct CameraPropertyText {
  const char* fx;
  const char* calibration_file;
};

/* Installs the camera properties from `first_id`; fx to distortion with `pinhole_flags`,
 * calibration-file mutable in READY (it is loaded at start). */
void install_camera_properties(GObjectClass* klass, guint first_id, GParamFlags pinhole_flags,
                               const CameraPropertyText& text, bool with_distortion);

/* The camera properties' values; under the element's object lock. */
struct CameraSettings {
  PinholeSettings pinhole;
  std::string calibration_file;
  std::string distortion_text; /* as set, for reading back */
  /* Refused values (refuse_value), until a good value clears them; the element checks
   * them with no_refused_values() at start. */
  std::string cx_error, cy_error, distortion_error;
};

/* set_property of the camera property `which`: a value that is neither "not set" nor
 * valid (a principal point between -1 and 0, distortion text that does not read) is
 * refused with refuse_value() and kept in `settings` as a refusal; a good value is
 * stored, under `element`'s object lock, and clears it. */
void set_camera_property(GstElement* element, CameraSettings& settings, CameraProperty which, const GValue* value);
/* get_property of the camera property `which`; the caller holds the object lock. */
void get_camera_property(const CameraSettings& settings, CameraProperty which, GValue* value);

/* "k1,k2,p1,p2[,k3[,k4,k5,k6]]" as OpenCV orders them, with a decimal point whatever the
 * locale. Throws std::invalid_argument saying what is wrong. */
std::vector<double> parse_distortion(const std::string& text);

/* The camera a width x height frame is seen with: the calibration (scaled to the frame),
 * else the hand-set pinhole (PinholeSettings::camera_for), else Camera::default_for
 * (uncalibrated). Throws when the calibration cannot fit the frame. */
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
