// SPDX-License-Identifier: LGPL-2.1-or-later
// Smooth 6-DoF paths for lftagtestsrc: markers that stay in view while they drift
// across the frame, come closer and recede (4:1 in distance), spin and tilt by up to
// 40 degrees about each in-plane axis. Every path is a smooth function of time drawn
// from a seed, so a frame depends only on its timestamp.
#pragma once

#include <cstdint>
#include <vector>

#include <lftag/camera.hpp>
#include <lftag/family.hpp>
#include <lftag/render.hpp>

namespace lftag::gst {

class MarkerMotion {
 public:
  // One marker per id, all of `family` with an outer edge of `tag_size` metres. The
  // frame of `camera` is split into a grid of cells, one per marker, and each marker
  // keeps to its cell, so markers never overlap and none hides another.
  MarkerMotion(const Camera& camera, const Family& family, const std::vector<TagId>& ids, double tag_size,
               std::uint64_t seed);

  std::size_t size() const { return paths_.size(); }
  // The markers at time `t`, seconds.
  std::vector<SceneMarker> at(double t) const;
  // The largest distance, in pixels, that an outer corner of any marker travels
  // between t0 and t1 (for motion blur).
  double max_corner_shift(double t0, double t1) const;

 private:
  // A smooth signal in [-1, 1]: two sines with incommensurate frequencies.
  struct Wave {
    double f1, p1, f2, p2;
    double operator()(double t) const;
  };
  struct Path {
    TagId id;
    double u0, v0, half_u, half_v;  // the cell, normalised image coordinates
    double z_near;                  // metres: the marker's diagonal fills most of the cell
    Wave u, v, depth, tilt_x, tilt_y, wobble;
    double roll0, roll_rate;  // radians, radians per second
  };

  SceneMarker marker_at(const Path& path, double t) const;

  Camera camera_;
  Family family_;
  double tag_size_;
  std::vector<Path> paths_;
};

// A well-mixed seed for stream `stream` of `seed` (the noise of each frame, say).
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream);

// `count` ids drawn from `family` with `seed`, distinct unless the family has fewer ids.
std::vector<TagId> random_ids(const Family& family, std::size_t count, std::uint64_t seed);

}  // namespace lftag::gst
