// SPDX-License-Identifier: LGPL-2.1-or-later
// Final pose (paper IV-I): PnP on all n^2 centroids, IPPE then Levenberg-Marquardt.
// A blob's centroid is the centroid of its projected square, which perspective moves off
// the projection of the square's centre; one correction with the first pose removes
// that bias before the refinement.
#include <cmath>

#include <opencv2/calib3d.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {
bool estimate_pose(const Candidate& c, const Decoding& d, const Camera& camera, const DetectorParams& params,
                   Detection& out) {
  const Family& f = c.family;
  const double size = params.tag_size;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  std::vector<UnitRect> squares;
  for (int g = 0; g < f.cell_count(); ++g) {
    const int digit = f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g));
    object.push_back(f.to_marker_frame(f.center(g, digit), size));
    image.push_back(c.blobs[d.blob_of_cell[g]].point);
    squares.push_back(f.square(g, digit));
  }
  const cv::Matx33d k = camera.matrix();  // the points are undistorted already
  cv::Vec3d rvec, tvec;
  try {
    if (!cv::solvePnP(object, image, k, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE)) return false;
    if (params.refine_pose) {
      // Move each observation from the centroid of the projected square to the
      // projection of its centre, as the IPPE pose predicts (the bias is small beside
      // the pose's error, so the first pose is good enough for it), and refine.
      std::vector<cv::Point3d> corners;
      for (const UnitRect& s : squares)
        for (const cv::Point2d u : {cv::Point2d(s.x, s.y), cv::Point2d(s.x + s.width, s.y),
                                    cv::Point2d(s.x + s.width, s.y + s.height), cv::Point2d(s.x, s.y + s.height)})
          corners.push_back(f.to_marker_frame(u, size));
      std::vector<cv::Point2d> centres, quads, corrected = image;
      cv::projectPoints(object, rvec, tvec, k, cv::noArray(), centres);
      cv::projectPoints(corners, rvec, tvec, k, cv::noArray(), quads);
      for (int g = 0; g < f.cell_count(); ++g) {
        const std::vector<cv::Point2d> quad(quads.begin() + 4 * g, quads.begin() + 4 * g + 4);
        corrected[g] -= polygon_centroid(quad) - centres[g];
      }
      cv::solvePnPRefineLM(object, corrected, k, cv::noArray(), rvec, tvec);
      image = corrected;
    }
  } catch (const cv::Exception&) {
    return false;  // a degenerate point set: not a marker we can localise
  }
  if (!std::isfinite(tvec[2]) || tvec[2] <= 0) return false;

  std::vector<cv::Point2d> reprojected;
  cv::projectPoints(object, rvec, tvec, k, cv::noArray(), reprojected);
  double sq = 0;
  for (std::size_t i = 0; i < image.size(); ++i) {
    const cv::Point2d e = reprojected[i] - image[i];
    sq += e.dot(e);
  }
  out.reprojection_error = std::sqrt(sq / image.size());
  out.rvec = rvec, out.tvec = tvec;
  out.tag_size = size;
  out.calibrated = camera.calibrated;
  std::vector<cv::Point3d> outline;
  for (const cv::Point2d& u : f.outer_corners()) outline.push_back(f.to_marker_frame(u, size));
  outline.emplace_back(0, 0, 0);
  const std::vector<cv::Point2d> projected = camera.project(outline, rvec, tvec);
  for (int i = 0; i < 4; ++i) out.corners[i] = projected[i];
  out.center = projected[4];
  return true;
}

}  // namespace lftag::detail
