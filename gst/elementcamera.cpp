// SPDX-License-Identifier: LGPL-2.1-or-later
#include "elementcamera.h"

#include <cmath>
#include <exception>
#include <sstream>
#include <stdexcept>
#include <string>

#include "propertystate.h"

namespace lftag::gst {

namespace {

/* A property value read into the settings: empty for the "not set" value, and back. */
std::optional<double> focal_from_property(double value) {
  if (value == kUnsetFocal) return std::nullopt;
  return value;
}

std::optional<double> principal_from_property(double value) {
  if (value == kUnsetPrincipal) return std::nullopt;
  return value;
}

const char* optional_string(const std::string& text) { return text.empty() ? nullptr : text.c_str(); }

}  // namespace

void install_camera_properties(GObjectClass* klass, guint first_id, GParamFlags pinhole_flags,
                               const CameraPropertyText& text, bool with_distortion) {
  const auto ready = GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_READY);
  g_object_class_install_property(
      klass, first_id + kCameraFx,
      g_param_spec_double("fx", "Focal length x", text.fx, 0.0, kMaxProperty, kUnsetFocal, pinhole_flags));
  g_object_class_install_property(
      klass, first_id + kCameraFy,
      g_param_spec_double("fy", "Focal length y",
                          "Vertical focal length in pixels, with fx. 0 (the default) is \"not set\": equal to fx", 0.0,
                          kMaxProperty, kUnsetFocal, pinhole_flags));
  g_object_class_install_property(
      klass, first_id + kCameraCx,
      g_param_spec_double("cx", "Principal point x",
                          "Principal point x in pixels, with fx: 0 to 1e6, pixel centres at integers "
                          "(0 is the left pixel column). -1 (the default) is \"not set\": the frame centre; "
                          "values between -1 and 0 are refused",
                          kUnsetPrincipal, kMaxProperty, kUnsetPrincipal, pinhole_flags));
  g_object_class_install_property(
      klass, first_id + kCameraCy,
      g_param_spec_double("cy", "Principal point y",
                          "Principal point y in pixels, with fx: 0 to 1e6, pixel centres at integers "
                          "(0 is the top pixel row). -1 (the default) is \"not set\": the frame centre; "
                          "values between -1 and 0 are refused",
                          kUnsetPrincipal, kMaxProperty, kUnsetPrincipal, pinhole_flags));
  g_object_class_install_property(
      klass, first_id + kCameraCalibrationFile,
      g_param_spec_string("calibration-file", "Calibration file", text.calibration_file, nullptr, ready));
  if (with_distortion)
    g_object_class_install_property(
        klass, first_id + kCameraDistortion,
        g_param_spec_string("distortion", "Distortion",
                            "Lens distortion with fx: k1,k2,p1,p2[,k3[,k4,k5,k6]] as OpenCV orders "
                            "them, comma-separated (unset: none)",
                            nullptr, pinhole_flags));
}

void set_camera_property(GstElement* element, CameraSettings& settings, CameraProperty which, const GValue* value) {
  /* Values are checked outside the lock; a refused value changes nothing but the refusal. */
  const char* text = G_VALUE_HOLDS_STRING(value) ? g_value_get_string(value) : nullptr;
  std::vector<double> distortion;
  std::string refusal;
  if (which == kCameraCx || which == kCameraCy) {
    const double v = g_value_get_double(value);
    if (v < 0 && v != kUnsetPrincipal) {
      gchar number[G_ASCII_DTOSTR_BUF_SIZE];
      g_ascii_dtostr(number, sizeof number, v);
      refusal = refuse_value(element, which == kCameraCx ? "cx" : "cy", number,
                             "a principal point is 0 to 1e6 pixels, or -1 for \"not set\" (the frame centre)");
    }
  } else if (which == kCameraDistortion) {
    try {
      if (text && *text) distortion = parse_distortion(text);
    } catch (const std::exception& e) {
      refusal = refuse_value(element, "distortion", text, e.what());
    }
  }

  GST_OBJECT_LOCK(element);
  CameraSettings& s = settings;
  switch (which) {
    case kCameraFx: s.pinhole.fx = focal_from_property(g_value_get_double(value)); break;
    case kCameraFy: s.pinhole.fy = focal_from_property(g_value_get_double(value)); break;
    case kCameraCx:
      if (refusal.empty()) s.pinhole.cx = principal_from_property(g_value_get_double(value));
      s.cx_error = refusal;
      break;
    case kCameraCy:
      if (refusal.empty()) s.pinhole.cy = principal_from_property(g_value_get_double(value));
      s.cy_error = refusal;
      break;
    case kCameraCalibrationFile: s.calibration_file = text ? text : ""; break;
    case kCameraDistortion:
      if (refusal.empty()) {
        s.distortion_text = distortion.empty() ? "" : text;
        s.pinhole.distortion = std::move(distortion);
      }
      s.distortion_error = refusal;
      break;
    case kCameraProperties: break;
  }
  GST_OBJECT_UNLOCK(element);
}

void get_camera_property(const CameraSettings& s, CameraProperty which, GValue* value) {
  switch (which) {
    case kCameraFx: g_value_set_double(value, s.pinhole.fx.value_or(kUnsetFocal)); break;
    case kCameraFy: g_value_set_double(value, s.pinhole.fy.value_or(kUnsetFocal)); break;
    case kCameraCx: g_value_set_double(value, s.pinhole.cx.value_or(kUnsetPrincipal)); break;
    case kCameraCy: g_value_set_double(value, s.pinhole.cy.value_or(kUnsetPrincipal)); break;
    case kCameraCalibrationFile: g_value_set_string(value, optional_string(s.calibration_file)); break;
    case kCameraDistortion: g_value_set_string(value, optional_string(s.distortion_text)); break;
    case kCameraProperties: break;
  }
}

std::vector<double> parse_distortion(const std::string& text) {
  std::vector<double> values;
  std::istringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    gchar* end = nullptr;
    const double v = g_ascii_strtod(item.c_str(), &end);
    if (end == item.c_str() || item.find_first_not_of(" \t", end - item.c_str()) != std::string::npos ||
        !std::isfinite(v))
      throw std::invalid_argument("'" + item + "' is not a number");
    values.push_back(v);
  }
  if (values.size() != 4 && values.size() != 5 && values.size() != 8)
    throw std::invalid_argument(
        "it needs 4, 5 or 8 comma-separated coefficients "
        "(k1,k2,p1,p2[,k3[,k4,k5,k6]]), not " +
        std::to_string(values.size()));
  return values;
}

Camera frame_camera(const PinholeSettings& pinhole, const std::optional<Camera>& calibration, int width, int height) {
  if (calibration) return calibration->for_frame(width, height);
  if (std::optional<Camera> hand_set = pinhole.camera_for(width, height)) return *hand_set;
  return Camera::default_for(width, height);
}

std::string ignored_pinhole(const PinholeSettings& pinhole, bool calibrated) {
  const bool used = !calibrated && pinhole.fx;  // fx, and then the others, count
  std::string names;
  auto add = [&names](bool set, const char* name) {
    if (set) names += (names.empty() ? "" : ", ") + std::string(name);
  };
  add(calibrated && pinhole.fx, "fx");
  add(!used && pinhole.fy, "fy");
  add(!used && pinhole.cx, "cx");
  add(!used && pinhole.cy, "cy");
  add(!used && !pinhole.distortion.empty(), "distortion");
  if (names.empty()) return {};
  const bool one = names.find(',') == std::string::npos;
  return "Camera propert" + std::string(one ? "y " : "ies ") + names + (one ? " is" : " are") + " ignored" +
         (calibrated ? ": calibration-file gives the camera" : " without fx");
}

gboolean load_calibration(GstElement* element, const std::string& path, std::optional<Camera>& calibration) {
  calibration.reset();
  // Camera::load says what the path is when it is no regular file (it does not exist, is
  // a FIFO, a directory, a device, a symbolic link loop) before opening anything, as
  // lftag --calibration does.
  try {
    calibration = Camera::load(path);
  } catch (const std::exception& e) {
    std::string message = e.what();
    if (!message.empty()) message[0] = g_ascii_toupper(message[0]);
    if (g_file_test(path.c_str(), G_FILE_TEST_EXISTS))
      GST_ELEMENT_ERROR(element, RESOURCE, SETTINGS, ("%s.", message.c_str()), (nullptr));
    else
      GST_ELEMENT_ERROR(element, RESOURCE, NOT_FOUND, ("%s.", message.c_str()), (nullptr));
    return FALSE;
  }
  return TRUE;
}

}  // namespace lftag::gst
