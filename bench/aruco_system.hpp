// SPDX-License-Identifier: LGPL-2.1-or-later
// OpenCV ArUco (the contrib module of Debian's OpenCV 4.6) as a benchmark peer:
// DICT_APRILTAG_36h11 with the default detector parameters.
#pragma once

#include <string>

#include <opencv2/aruco.hpp>

#include "system.hpp"

namespace bench {

class ArucoSystem : public FiducialSystem {
 public:
  ArucoSystem();

  std::string name() const override { return "aruco-36h11"; }
  std::string family() const override { return "DICT_APRILTAG_36h11"; }
  std::string dictionary_size() const override;
  std::vector<std::string> marker_ids(int count, std::uint64_t seed) const override;
  cv::Mat1b marker_cells(const std::string& id) const override;
  void set_camera(const lftag::Camera& camera, double tag_size) override;
  std::vector<Detected> detect(const cv::Mat1b& grey) override;

 private:
  cv::Ptr<cv::aruco::Dictionary> dictionary_;
  cv::Ptr<cv::aruco::DetectorParameters> params_;
  lftag::Camera camera_;
  double tag_size_ = 0;
};

}  // namespace bench
