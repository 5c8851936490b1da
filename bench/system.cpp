// SPDX-License-Identifier: LGPL-2.1-or-later
#include "system.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace bench {

lftag::SceneTarget FiducialSystem::target(const std::string& id, double tag_size, const cv::Vec3d& rvec,
                                          const cv::Vec3d& tvec) const {
  const cv::Mat1b cells = marker_cells(id);
  if (cells.empty() || cells.rows != cells.cols) throw std::logic_error(name() + ": marker cells must be square");
  // The margin is rarely a whole number of the design's cells (0.75 of a 16h5 cell), so
  // split every cell into k x k until it is; the rendered geometry stays exact.
  auto margin_cells = [&](int k) { return kMarginFraction * cells.cols * k; };
  int k = 1;
  while (k < 64 && std::abs(margin_cells(k) - std::round(margin_cells(k))) > 1e-9) ++k;
  const int margin = int(std::round(margin_cells(k)));
  cv::Mat1b fine;
  cv::resize(cells, fine, cells.size() * k, 0, 0, cv::INTER_NEAREST);
  cv::Mat1f albedo(fine.rows + 2 * margin, fine.cols + 2 * margin, kPaper);
  for (int y = 0; y < fine.rows; ++y)
    for (int x = 0; x < fine.cols; ++x) albedo(y + margin, x + margin) = fine(y, x) ? kPaper : kInk;
  return {albedo, tag_size / fine.cols, rvec, tvec};
}

void set_square_pose(Detected& det, double size, const lftag::Camera& camera) {
  const std::vector<cv::Point2d>& corners = det.points;
  if (corners.size() != 4) return;
  // IPPE_SQUARE wants the object points (-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2);
  // with y down (SPEC 2) those are bottom-left, bottom-right, top-right, top-left.
  const double h = size / 2;
  const std::vector<cv::Point3d> object{{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
  const std::vector<cv::Point2d> image{corners[3], corners[2], corners[1], corners[0]};
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat errors;
  // solvePnPGeneric sorts the solutions by reprojection error: the first is solvePnP's.
  if (cv::solvePnPGeneric(object, image, cv::Mat(camera.matrix()), camera.distortion_mat(), rvecs, tvecs, false,
                          cv::SOLVEPNP_IPPE_SQUARE, cv::noArray(), cv::noArray(), errors) == 0)
    return;
  det.pose = Pose{cv::Vec3d(rvecs[0]), cv::Vec3d(tvecs[0])};
  if (rvecs.size() > 1) {
    det.alternative = Pose{cv::Vec3d(rvecs[1]), cv::Vec3d(tvecs[1])};
    det.ambiguity_ratio = errors.at<double>(1) / std::max(errors.at<double>(0), 1e-12);
  }
}

cv::Point2d quad_center(const std::vector<cv::Point2d>& c) {
  // Solve c0 + s (c2 - c0) = c1 + t (c3 - c1) for s.
  const cv::Point2d d0 = c[2] - c[0], d1 = c[3] - c[1], r = c[1] - c[0];
  const double den = d0.x * d1.y - d0.y * d1.x;
  if (std::abs(den) < 1e-12) return (c[0] + c[1] + c[2] + c[3]) / 4;
  const double s = (r.x * d1.y - r.y * d1.x) / den;
  return c[0] + s * d0;
}

}  // namespace bench
