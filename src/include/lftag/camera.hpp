// SPDX-License-Identifier: LGPL-2.1-or-later
// OpenCV pinhole camera with (k1, k2, p1, p2[, k3[, k4, k5, k6]]) distortion.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace lftag {

struct Camera {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;       // 0 when unknown
  std::vector<double> distortion;  // empty: no distortion
  // False for the default camera: decoding works, but metric poses assume a guessed focal length.
  bool calibrated = false;

  // The documented default for a frame without calibration: square pixels, a
  // horizontal focal length equal to the frame width (a 53 degree field of view),
  // principal point at the frame centre (pixel centres at integer coordinates).
  static Camera default_for(int width, int height);
  static Camera pinhole(double fx, double fy, double cx, double cy, int width = 0, int height = 0);

  // The ranges validate() accepts, and so calibration files too.
  static constexpr double kMinFocal = 1e-3, kMaxFocal = 1e7;  // fx, fy, pixels
  static constexpr double kMaxPrincipal = 1e7;                // |cx|, |cy|, pixels
  static constexpr double kMaxDistortion = 1e4;               // |each coefficient|
  static constexpr int kMaxImageSide = 65536;                 // width, height (0: unknown)

  // Reads an OpenCV FileStorage file (YAML, XML or JSON) with `camera_matrix` and
  // `distortion_coefficients` (OpenCV's calibration samples) or `cameraMatrix` and
  // `distCoeffs` (GStreamer's cameracalibrate), plus optional `image_width`/`image_height`.
  // The file is untrusted input: it is parsed with libyaml, libxml2 or nlohmann-json
  // under limits (at most 1 MiB, no YAML aliases, no XML DTD or entities, bounded
  // nesting; docs/cli.md, "Calibration files"), never with cv::FileStorage, and its
  // values must pass validate(). Throws std::runtime_error naming the file, what is
  // wrong with it and what was expected.
  static Camera load(const std::string& path);
  // Same, from text in memory (`source` names it in messages).
  static Camera parse(const std::string& text, const std::string& source = "calibration");
  // Writes the OpenCV calibration-sample format (YAML, XML or JSON by the extension).
  void save(const std::string& path) const;

  // The camera for a frame of another size: intrinsics scale with the frame when the
  // calibration's own size is known and differs. Throws if the aspect ratio changes.
  Camera for_frame(int frame_width, int frame_height) const;

  bool has_distortion() const;
  cv::Matx33d matrix() const;
  cv::Mat distortion_mat() const;  // 1 x N CV_64F (N >= 4) or empty

  // Pixel coordinates -> ideal (undistorted) pixel coordinates of the same camera matrix.
  std::vector<cv::Point2d> undistort(const std::vector<cv::Point2d>& pixels) const;
  // Camera-frame 3-D points -> pixel coordinates, distortion applied.
  std::vector<cv::Point2d> project(const std::vector<cv::Point3d>& points, const cv::Vec3d& rvec = {},
                                   const cv::Vec3d& tvec = {}) const;

  // Throws std::invalid_argument when the parameters cannot describe a camera: fx, fy
  // outside [kMinFocal, kMaxFocal], cx, cy outside +-kMaxPrincipal, width or height
  // outside [0, kMaxImageSide], a distortion of other than 0, 4, 5 or 8 coefficients or
  // one beyond +-kMaxDistortion; NaN and infinities everywhere.
  void validate() const;

  friend bool operator==(const Camera& a, const Camera& b);
  friend bool operator!=(const Camera& a, const Camera& b) { return !(a == b); }
};

// A camera set by hand, any part of it left unset: the command line's --fx, --fy, --cx and
// --cy, the elements' fx, fy, cx, cy and distortion.
struct PinholeSettings {
  std::optional<double> fx, fy, cx, cy;
  std::vector<double> distortion;

  // The camera of a width x height frame: fy defaults to fx, the principal point to the
  // frame's centre ((width - 1) / 2, pixel centres at integers). Empty without fx, which
  // the others need.
  std::optional<Camera> camera_for(int width, int height) const;

  friend bool operator==(const PinholeSettings& a, const PinholeSettings& b);
  friend bool operator!=(const PinholeSettings& a, const PinholeSettings& b) { return !(a == b); }
};

}  // namespace lftag
