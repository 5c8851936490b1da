// SPDX-License-Identifier: LGPL-2.1-or-later
// JSON conventions of the command-line contract (SPEC 5).
#pragma once

#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "lftag/tag_id.hpp"

namespace lftag::tools {

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

}  // namespace lftag::tools
