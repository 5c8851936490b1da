// SPDX-License-Identifier: LGPL-2.1-or-later
#include "aruco_system.hpp"

namespace bench {

ArucoSystem::ArucoSystem()
    : dictionary_(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_APRILTAG_36h11)),
      params_(cv::aruco::DetectorParameters::create()) {}

std::string ArucoSystem::dictionary_size() const { return std::to_string(dictionary_->bytesList.rows); }

std::vector<std::string> ArucoSystem::marker_ids(int count, std::uint64_t) const {
  std::vector<std::string> ids;
  for (int i = 0; i < count && i < dictionary_->bytesList.rows; ++i) ids.push_back(std::to_string(i));
  return ids;
}

cv::Mat1b ArucoSystem::marker_cells(const std::string& id) const {
  // One pixel per cell, with ArUco's one-cell black border as the outer edge.
  const int cells = dictionary_->markerSize + 2;
  cv::Mat1b img;
  cv::aruco::drawMarker(dictionary_, std::stoi(id), cells, img, 1);
  return img;
}

void ArucoSystem::set_camera(const lftag::Camera& camera, double tag_size) {
  camera_ = camera;
  tag_size_ = tag_size;
}

std::vector<Detected> ArucoSystem::detect(const cv::Mat1b& grey) {
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(grey, dictionary_, corners, ids, params_);
  std::vector<Detected> out;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    Detected det;
    det.id = std::to_string(ids[i]);
    // ArUco lists the outer corners clockwise from the marker's top-left.
    for (const cv::Point2f& p : corners[i]) det.points.emplace_back(p.x, p.y);
    det.center = quad_center(det.points);
    set_square_pose(det, tag_size_, camera_);
    out.push_back(std::move(det));
  }
  return out;
}

}  // namespace bench
