// SPDX-License-Identifier: LGPL-2.1-or-later
// AprilTag 3 (Debian's libapriltag) as a benchmark peer: one family per system, one
// thread, the library's defaults (2 corrected bits) except the decimation.
#pragma once

#include <memory>
#include <string>

#include "system.hpp"

struct apriltag_family;
struct apriltag_detector;
struct apriltag_detection;

namespace bench {

class AprilTagSystem : public FiducialSystem {
 public:
  // How the pose is computed from a detection: OpenCV's IPPE for squares on the four
  // corners (every experiment's), or the library's own estimate_tag_pose (its homography
  // refined by orthogonal iteration, and the better of that and the second local minimum
  // it finds), for an undistorted camera only.
  enum class PoseMethod { ippe_square, orthogonal_iteration };

  // `family`: "16h5", "25h9", "36h11" or "41h12" (tagStandard41h12); decimate 1 or 2.
  AprilTagSystem(const std::string& family, int decimate, PoseMethod pose = PoseMethod::ippe_square);
  ~AprilTagSystem() override;
  AprilTagSystem(const AprilTagSystem&) = delete;
  AprilTagSystem& operator=(const AprilTagSystem&) = delete;

  std::string name() const override;
  std::string family() const override;
  std::string dictionary_size() const override;
  std::vector<std::string> marker_ids(int count, std::uint64_t seed) const override;
  cv::Mat1b marker_cells(const std::string& id) const override;
  void set_camera(const lftag::Camera& camera, double tag_size) override;
  std::vector<Detected> detect(const cv::Mat1b& grey) override;

 private:
  void set_library_pose(apriltag_detection* d, Detected& det) const;

  std::string short_name_;
  int decimate_;
  PoseMethod pose_method_;
  apriltag_family* family_ = nullptr;
  void (*destroy_family_)(apriltag_family*) = nullptr;
  apriltag_detector* detector_ = nullptr;
  lftag::Camera camera_;
  double quad_size_ = 0;  // edge of the square whose corners the detector reports, metres
};

}  // namespace bench
