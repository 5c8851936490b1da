// SPDX-License-Identifier: LGPL-2.1-or-later
#include "apriltag_system.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include <apriltag/apriltag.h>
#include <apriltag/apriltag_pose.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/common/zarray.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>

#include "trial.hpp"  // rotation_error_deg

namespace bench {

AprilTagSystem::AprilTagSystem(const std::string& family, int decimate, PoseMethod pose)
    : short_name_(family), decimate_(decimate), pose_method_(pose) {
  if (family == "16h5")
    family_ = tag16h5_create(), destroy_family_ = tag16h5_destroy;
  else if (family == "25h9")
    family_ = tag25h9_create(), destroy_family_ = tag25h9_destroy;
  else if (family == "36h11")
    family_ = tag36h11_create(), destroy_family_ = tag36h11_destroy;
  else if (family == "41h12")
    family_ = tagStandard41h12_create(), destroy_family_ = tagStandard41h12_destroy;
  else
    throw std::invalid_argument("unknown AprilTag family " + family);
  detector_ = apriltag_detector_create();
  detector_->nthreads = 1;
  detector_->quad_decimate = float(decimate);
  apriltag_detector_add_family(detector_, family_);
}

AprilTagSystem::~AprilTagSystem() {
  apriltag_detector_destroy(detector_);
  destroy_family_(family_);
}

std::string AprilTagSystem::name() const { return "apriltag-" + short_name_ + "-d" + std::to_string(decimate_); }
std::string AprilTagSystem::family() const { return family_->name; }
std::string AprilTagSystem::dictionary_size() const { return std::to_string(family_->ncodes); }

// The first ids, as the LFTag paper chose them: AprilTag's codes carry no bias by index.
std::vector<std::string> AprilTagSystem::marker_ids(int count, std::uint64_t) const {
  std::vector<std::string> ids;
  for (int i = 0; i < count && i < int(family_->ncodes); ++i) ids.push_back(std::to_string(i));
  return ids;
}

cv::Mat1b AprilTagSystem::marker_cells(const std::string& id) const {
  image_u8_t* im = apriltag_to_image(family_, std::stoi(id));
  const cv::Mat1b all = cv::Mat1b(im->height, im->width, im->buf, std::size_t(im->stride)).clone();
  image_u8_destroy(im);
  // The library's image has a one-cell white ring outside the black border of the
  // classic families; tagStandard41h12 puts data cells there instead, so all of it
  // is the marker.
  if (family_->reversed_border) return all;
  const int ring = (family_->total_width - family_->width_at_border) / 2;
  return all(cv::Rect(ring, ring, family_->width_at_border, family_->width_at_border)).clone();
}

void AprilTagSystem::set_camera(const lftag::Camera& camera, double tag_size) {
  camera_ = camera;
  // The detector reports the corners of the border square (width_at_border cells).
  const int extent = family_->reversed_border ? family_->total_width : family_->width_at_border;
  quad_size_ = tag_size * family_->width_at_border / extent;
}

// The library's pose (estimate_tag_pose) in its own pixel convention (centres at +0.5);
// its frame is SPEC 2's (x right, y down, z into the tag). Debian's library exports only
// that function, which returns one of its two local minima, so the other solution is the
// one of IPPE's two on the same corners farther from it.
void AprilTagSystem::set_library_pose(apriltag_detection* d, Detected& det) const {
  if (camera_.has_distortion()) throw std::invalid_argument("AprilTag's own pose needs an undistorted camera");
  apriltag_detection_info_t info{d, quad_size_, camera_.fx, camera_.fy, camera_.cx + 0.5, camera_.cy + 0.5};
  apriltag_pose_t p{nullptr, nullptr};
  estimate_tag_pose(&info, &p);
  if (!p.R || !p.t) return;
  cv::Matx33d r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r(i, j) = MATD_EL(p.R, i, j);
  Pose pose;
  cv::Rodrigues(r, pose.rvec);
  pose.tvec = {MATD_EL(p.t, 0, 0), MATD_EL(p.t, 1, 0), MATD_EL(p.t, 2, 0)};
  // matd_destroy is not exported either; a matd_t is one calloc'd block (common/matd.c).
  std::free(p.R), std::free(p.t);
  det.pose = pose;
  Detected ippe = det;
  set_square_pose(ippe, quad_size_, camera_);
  if (!ippe.pose || !ippe.alternative) return;
  det.alternative =
      rotation_error_deg(ippe.pose->rvec, pose.rvec) > rotation_error_deg(ippe.alternative->rvec, pose.rvec)
          ? ippe.pose
          : ippe.alternative;
}

std::vector<Detected> AprilTagSystem::detect(const cv::Mat1b& grey) {
  image_u8_t im{grey.cols, grey.rows, int(grey.step[0]), const_cast<uint8_t*>(grey.ptr<uint8_t>())};
  zarray_t* found = apriltag_detector_detect(detector_, &im);
  std::vector<Detected> out;
  for (int i = 0; i < zarray_size(found); ++i) {
    apriltag_detection_t* d;
    zarray_get(found, i, &d);
    Detected det;
    det.id = std::to_string(d->id);
    det.confidence = d->decision_margin;
    det.path = "quad";
    // AprilTag puts pixel centres at +0.5 and lists the corners from the marker's
    // bottom-left; convert to OpenCV's convention, clockwise from the top-left.
    for (int k : {3, 2, 1, 0}) det.points.emplace_back(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    det.center = cv::Point2d(d->c[0] - 0.5, d->c[1] - 0.5);
    if (pose_method_ == PoseMethod::ippe_square)
      set_square_pose(det, quad_size_, camera_);
    else
      set_library_pose(d, det);
    out.push_back(std::move(det));
  }
  apriltag_detections_destroy(found);
  return out;
}

}  // namespace bench
