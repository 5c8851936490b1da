// SPDX-License-Identifier: LGPL-2.1-or-later
#include "elementcamera.h"

#include <exception>

namespace lftag::gst {

Camera frame_camera(const PinholeSettings& pinhole, const std::optional<Camera>& calibration, int width, int height) {
  if (calibration) return calibration->for_frame(width, height);
  if (pinhole.fx > 0) {
    Camera camera = Camera::pinhole(pinhole.fx, pinhole.fy > 0 ? pinhole.fy : pinhole.fx,
                                    pinhole.cx > 0 ? pinhole.cx : (width - 1) / 2.0,
                                    pinhole.cy > 0 ? pinhole.cy : (height - 1) / 2.0, width, height);
    camera.distortion = pinhole.distortion;
    return camera;
  }
  return Camera::default_for(width, height);
}

gboolean load_calibration(GstElement* element, const std::string& path, std::optional<Camera>& calibration) {
  calibration.reset();
  if (!g_file_test(path.c_str(), G_FILE_TEST_IS_REGULAR)) {
    GST_ELEMENT_ERROR(element, RESOURCE, NOT_FOUND, ("Calibration file \"%s\" does not exist.", path.c_str()),
                      (nullptr));
    return FALSE;
  }
  try {
    calibration = Camera::load(path);
  } catch (const std::exception& e) {
    GST_ELEMENT_ERROR(element, RESOURCE, SETTINGS, ("Invalid %s.", e.what()), (nullptr));
    return FALSE;
  }
  return TRUE;
}

}  // namespace lftag::gst
