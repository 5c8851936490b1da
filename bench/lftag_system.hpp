// SPDX-License-Identifier: LGPL-2.1-or-later
// The LFTag detector of this project as a benchmark system: one family per system, the
// detector's default parameters.
#pragma once

#include <memory>
#include <string>
#include <utility>

#include "lftag/detector.hpp"
#include "lftag/trace.hpp"
#include "system.hpp"

namespace bench {

// A detection as the benchmarks score it.
Detected to_detected(const lftag::Detection& d);

class LftagSystem : public FiducialSystem {
 public:
  // `base`: the parameters besides the family, camera and tag size (an experiment's variant).
  explicit LftagSystem(int n, lftag::DetectorParams base = {}) : family_(n), base_(std::move(base)) {}

  std::string name() const override { return "lftag-" + family_.name(); }
  std::string family() const override { return "lftag-" + family_.name(); }
  std::string dictionary_size() const override { return family_.dictionary_size(); }
  std::vector<std::string> marker_ids(int count, std::uint64_t seed) const override;
  cv::Mat1b marker_cells(const std::string& id) const override;
  void set_camera(const lftag::Camera& camera, double tag_size) override;
  // The detector's parameters for this camera and tag size (what set_camera builds it
  // with), for an experiment that drives an lftag::Detector itself.
  lftag::DetectorParams params_for(const lftag::Camera& camera, double tag_size) const;
  std::vector<Detected> detect(const cv::Mat1b& grey) override;
  void reset_counters() override { stats_ = {}; }
  std::vector<std::pair<std::string, double>> counters() const override;

 private:
  lftag::Family family_;
  lftag::DetectorParams base_;
  std::unique_ptr<lftag::Detector> detector_;
  lftag::DetectionStats stats_;
};

}  // namespace bench
