// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the calibration loader, lftag::Camera::parse(text, source), behind
// `lftag detect --calibration`, `lftag render --calibration` and the elements'
// `calibration-file`. Bad text must end in an exception, never a crash or a hang; a
// camera it returns must be usable.
#include <cstdint>
#include <exception>
#include <string>

#include "lftag/camera.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const lftag::Camera camera = lftag::Camera::parse(text, "fuzz input");
    camera.validate();
    const lftag::Camera scaled =
        camera.for_frame(camera.width > 0 ? 2 * camera.width : 640, camera.height > 0 ? 2 * camera.height : 480);
    scaled.project({{0.1, -0.2, 1.0}});
    scaled.undistort({{10.0, 20.0}});
  } catch (const std::exception&) {
  }
  return 0;
}
