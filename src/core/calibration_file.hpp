// SPDX-License-Identifier: LGPL-2.1-or-later
// The calibration-file reader behind Camera::load and Camera::parse. Calibration files are
// user input: they are parsed here with libyaml, libxml2 and nlohmann-json under fixed
// limits, never by OpenCV's cv::FileStorage (whose parser crashes, hangs or allocates
// without bound on malformed input).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

#include "lftag/camera.hpp"

namespace lftag::detail {

// The limits of the reader (docs/cli.md, "Calibration files", says the same).
inline constexpr std::size_t kMaxCalibrationBytes = 1 << 20;  // 1 MiB
inline constexpr int kMaxCalibrationDepth = 32;               // nested mappings and sequences
inline constexpr int kMaxEntryValues = 256;                   // scalars in one entry that is read
// Bounds on what the parsers are handed, checked as they go or by a linear pass before
// them, so that no file under kMaxCalibrationBytes costs more than a few milliseconds:
inline constexpr int kMaxCalibrationNodes = 20000;  // XML elements, attributes, comments and
                                                    // references; YAML nodes; JSON values and keys
inline constexpr int kMaxXmlAttributes = 8;         // on one XML element (libxml2 is quadratic in them)
inline constexpr int kMaxYamlDirectives = 8;        // '%' lines (libyaml is quadratic in %TAG)
inline constexpr std::size_t kMaxNumberChars = 64;  // characters of a number

// Reads OpenCV FileStorage text (YAML, XML or JSON, told apart by their first character).
// Throws std::runtime_error saying what is wrong and what was expected (no file name: the
// caller adds it).
Camera read_calibration(std::string_view text);

// Why `path` is not a regular file ("does not exist", "is a FIFO", "is a directory", "is
// a character device", "is a symbolic link loop", ...), or empty when it is one. Nothing
// is opened: opening a FIFO waits for a writer, and opening a device can act on it.
// Camera::load and the image reader (image_file.cpp) both ask it first.
std::string not_a_regular_file(const std::string& path);
// Whether that reason says what the path is (a FIFO, a directory...), which a message
// can follow with what was expected.
inline bool names_a_kind(const std::string& reason) {
  return reason.rfind("is ", 0) == 0 && reason.find("does not exist") == std::string::npos;
}

}  // namespace lftag::detail
