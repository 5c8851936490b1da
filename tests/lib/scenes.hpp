// SPDX-License-Identifier: LGPL-2.1-or-later
// Helpers shared by the tests that render scenes.
#pragma once

#include <random>

#include <opencv2/calib3d.hpp>

#include "lftag/render.hpp"

namespace lftag::test {

inline cv::Vec3d rotation(double roll, double tilt, double pan) { return rotation_from_angles(roll, tilt, pan); }

inline TagId random_id(const Family& f, std::mt19937_64& rng) {
  TagId id;
  for (int k = 0; k < f.data_cell_count(); ++k) id = id.with_digit(k, int(rng() & 3));
  return id;
}

// The paper's simulation camera: 640x480, fx = fy = 320.
inline Camera paper_camera() { return Camera::pinhole(320, 320, 319.5, 239.5, 640, 480); }

// Angle between two rotation vectors, degrees.
inline double rotation_error_deg(const cv::Vec3d& a, const cv::Vec3d& b) {
  cv::Matx33d ra, rb;
  cv::Rodrigues(a, ra);
  cv::Rodrigues(b, rb);
  cv::Vec3d d;
  cv::Rodrigues(ra.t() * rb, d);
  return cv::norm(d) * 180 / CV_PI;
}

}  // namespace lftag::test
