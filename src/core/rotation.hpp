// SPDX-License-Identifier: LGPL-2.1-or-later
// Rotation vectors (axis times angle, as OpenCV's poses carry them) to matrices and back,
// by Eigen's angle-axis: the pose refinement and the tracker turn them over tens of times
// a marker, where cv::Rodrigues (general: arrays, Jacobians, an SVD back) cost a twentieth
// of a tracked marker's time. Not part of the library's API.
#pragma once

#include <cfloat>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace lftag::detail {

inline cv::Matx33d rotation_matrix(const cv::Vec3d& rvec) {
  const Eigen::Vector3d v(rvec[0], rvec[1], rvec[2]);
  const double angle = v.norm();
  if (angle < DBL_EPSILON) return cv::Matx33d::eye();
  const Eigen::Matrix3d r = Eigen::AngleAxisd(angle, v / angle).toRotationMatrix();
  return {r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0), r(2, 1), r(2, 2)};
}

inline cv::Vec3d rotation_vector(const cv::Matx33d& m) {
  Eigen::Matrix3d r;
  r << m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2), m(2, 0), m(2, 1), m(2, 2);
  const Eigen::AngleAxisd a(r);
  const Eigen::Vector3d v = a.axis() * a.angle();
  return {v[0], v[1], v[2]};
}

}  // namespace lftag::detail
