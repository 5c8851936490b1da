// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag_system.hpp"

#include "experiment.hpp"

namespace bench {

// Random ids over the whole dictionary, as the paper chose LFTag's test markers; built
// digit by digit, so any family's ids stay exact.
std::vector<std::string> LftagSystem::marker_ids(int count, std::uint64_t seed) const {
  std::mt19937_64 rng = seeded(seed, {0x1f7a9, std::uint64_t(family_.n())});
  std::vector<std::string> ids;
  for (int i = 0; i < count; ++i) {
    lftag::TagId id;
    for (int k = 0; k < family_.data_cell_count(); ++k) id = id.with_digit(k, int(rng() % 4));
    ids.push_back(id.to_decimal());
  }
  return ids;
}

cv::Mat1b LftagSystem::marker_cells(const std::string& id) const {
  return family_.unit_bitmap(lftag::TagId::parse(id));
}

lftag::DetectorParams LftagSystem::params_for(const lftag::Camera& camera, double tag_size) const {
  lftag::DetectorParams params = base_;
  params.families = {family_};
  params.camera = camera;
  params.tag_size = tag_size;
  return params;
}

void LftagSystem::set_camera(const lftag::Camera& camera, double tag_size) {
  detector_ = std::make_unique<lftag::Detector>(params_for(camera, tag_size));
}

Detected to_detected(const lftag::Detection& d) {
  Detected det;
  det.id = d.id.to_decimal();
  det.points.assign(d.keypoints.begin(), d.keypoints.end());
  det.center = d.center;
  det.pose = Pose{d.rvec, d.tvec};
  if (d.ambiguity_ratio > 0) {
    det.alternative = Pose{d.alternative_rvec, d.alternative_tvec};
    det.ambiguity_ratio = d.ambiguity_ratio;
  }
  det.confidence = d.noise_margin;
  det.path = d.from_outline ? "outline" : "topology";
  return det;
}

std::vector<Detected> LftagSystem::detect(const cv::Mat1b& grey) {
  lftag::DetectionStats stats;
  std::vector<Detected> out;
  for (const lftag::Detection& d : detector_->detect(lftag::ImageView(grey), &stats)) out.push_back(to_detected(d));
  stats_ += stats;
  return out;
}

std::vector<std::pair<std::string, double>> LftagSystem::counters() const {
  const lftag::DetectionStats& s = stats_;
  return {{"frames", double(s.frames)},
          {"regions", double(s.regions)},
          {"topology", double(s.topology)},
          {"area", double(s.area)},
          {"geometry", double(s.geometry)},
          {"angle", double(s.angle)},
          {"collinearity", double(s.collinearity)},
          {"residual", double(s.residual)},
          {"unambiguous", double(s.unambiguous)},
          {"decoded", double(s.decoded)},
          {"bowed", double(s.bowed)},
          {"second_looks", double(s.second_looks)},
          {"second_look_found", double(s.second_look_found)},
          {"outline_reads", double(s.outline_reads)},
          {"outline_found", double(s.outline_found)},
          {"borders", double(s.borders)},
          {"border_found", double(s.border_found)},
          {"outline_reads_skipped", double(s.outline_reads_skipped)},
          {"threshold_ms", s.threshold_ms},
          {"regions_ms", s.regions_ms},
          {"candidates_ms", s.candidates_ms},
          {"keypoints_ms", s.keypoints_ms},
          {"hypotheses_ms", s.hypotheses_ms},
          {"decode_ms", s.decode_ms},
          {"pose_ms", s.pose_ms},
          {"borders_ms", s.borders_ms},
          {"second_look_ms", s.second_look_ms},
          {"total_ms", s.total_ms()}};
}

}  // namespace bench
