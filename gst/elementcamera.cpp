// SPDX-License-Identifier: LGPL-2.1-or-later
#include "elementcamera.h"

#include <exception>
#include <string>

#include "propertystate.h"

namespace lftag::gst {

std::optional<double> focal_from_property(double value) {
  if (value == kUnsetFocal) return std::nullopt;
  return value;
}

std::optional<double> principal_from_property(double value) {
  if (value == kUnsetPrincipal) return std::nullopt;
  return value;
}

double focal_to_property(const std::optional<double>& focal) { return focal.value_or(kUnsetFocal); }

double principal_to_property(const std::optional<double>& principal) { return principal.value_or(kUnsetPrincipal); }

std::string refuse_principal(GstElement* element, const char* property, double value) {
  if (value >= 0 || value == kUnsetPrincipal) return {};
  gchar text[G_ASCII_DTOSTR_BUF_SIZE];
  g_ascii_dtostr(text, sizeof text, value);
  return refuse_value(element, property, text,
                      "a principal point is 0 to 1e6 pixels, or -1 for \"not set\" (the frame centre)");
}

Camera frame_camera(const PinholeSettings& pinhole, const std::optional<Camera>& calibration, int width, int height) {
  if (calibration) return calibration->for_frame(width, height);
  if (pinhole.fx) {
    Camera camera =
        Camera::pinhole(*pinhole.fx, pinhole.fy.value_or(*pinhole.fx), pinhole.cx.value_or((width - 1) / 2.0),
                        pinhole.cy.value_or((height - 1) / 2.0), width, height);
    camera.distortion = pinhole.distortion;
    return camera;
  }
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
