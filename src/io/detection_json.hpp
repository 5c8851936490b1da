// SPDX-License-Identifier: LGPL-2.1-or-later
// JSON conventions of the command-line contract (SPEC 5), and the JSON of one detection:
// what `lftag detect` prints, and what lftagpublish and `lftag annotate --jsonl` write.
// Header-only (nlohmann/json): the small internal library src/io (lftag_io_dep in
// src/meson.build) that the tool, the GStreamer plugin and their tests all use, so that
// neither includes the other's folder.
#pragma once

#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "lftag/detector.hpp"
#include "lftag/tag_id.hpp"

namespace lftag::io {

// A JSON number where it is exact in every JSON reader (53 bits), else a decimal string.
inline nlohmann::json id_json(TagId id) {
  if (id.fits_53_bits()) return id.low();
  return id.to_decimal();
}

inline nlohmann::json points_json(const std::vector<cv::Point2d>& points) {
  nlohmann::json out = nlohmann::json::array();
  for (const cv::Point2d& p : points) out.push_back({p.x, p.y});
  return out;
}

inline nlohmann::json vec_json(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }

// One detection, as every JSON output of the project writes it (the schema in docs/cli.md, "JSON output").
inline nlohmann::json detection_json(const Detection& d) {
  return {
      {"family", d.family.name()},
      {"id", id_json(d.id)},
      {"id_hex", d.id.to_hex()},
      {"keypoints", points_json({d.keypoints.begin(), d.keypoints.end()})},
      {"center", {d.center.x, d.center.y}},
      {"corners", points_json({d.corners.begin(), d.corners.end()})},
      {"centroids", points_json(d.centroids)},
      {"pose",
       {{"rvec", vec_json(d.rvec)},
        {"tvec", vec_json(d.tvec)},
        {"calibrated", d.calibrated},
        {"tag_size", d.tag_size},
        {"ambiguity_ratio", d.ambiguity_ratio},
        // null when there was no other solution (ratio 0), never a zero pose
        {"alternative", d.ambiguity_ratio > 0 ? nlohmann::json{{"rvec", vec_json(d.alternative_rvec)},
                                                               {"tvec", vec_json(d.alternative_tvec)},
                                                               {"reprojection_error", d.alternative_reprojection_error}}
                                              : nlohmann::json(nullptr)}}},
      {"decode_error", d.decode_error},
      {"worst_cell", d.worst_cell},
      {"noise_margin", d.noise_margin},
      {"edge_score", d.edge_score},
      {"reprojection_error", d.reprojection_error},
      {"from_outline", d.from_outline}};
}

}  // namespace lftag::io
