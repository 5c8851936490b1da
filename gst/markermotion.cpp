// SPDX-License-Identifier: LGPL-2.1-or-later
#include "markermotion.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

namespace lftag::gst {
namespace {

constexpr double kTwoPi = 2 * CV_PI;
constexpr double kDepthRatio = 4.0;            // farthest / nearest distance
constexpr double kFill = 0.8;                  // nearest: the diagonal spans 80 % of the cell
constexpr double kMaxTilt = 40 * CV_PI / 180;  // about each in-plane axis

// std::mt19937_64 is specified exactly, and so is this mapping to [a, b): the same
// seed gives the same video with any standard library.
class Random {
 public:
  explicit Random(std::uint64_t seed) : engine_(seed) {}
  std::uint64_t bits() { return engine_(); }
  double uniform(double a, double b) { return a + (b - a) * double(engine_() >> 11) * 0x1.0p-53; }

 private:
  std::mt19937_64 engine_;
};

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

}  // namespace

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t stream) { return splitmix64(seed ^ splitmix64(stream)); }

double MarkerMotion::Wave::operator()(double t) const {
  return (std::sin(kTwoPi * f1 * t + p1) + 0.5 * std::sin(kTwoPi * f2 * t + p2)) / 1.5;
}

MarkerMotion::MarkerMotion(const Camera& camera, const Family& family, const std::vector<TagId>& ids, double tag_size,
                           std::uint64_t seed)
    : camera_(camera), family_(family), tag_size_(tag_size) {
  if (camera.width <= 0 || camera.height <= 0) throw std::invalid_argument("the camera needs a frame size");
  if (!(tag_size > 0)) throw std::invalid_argument("the tag size must be positive");
  const int n = int(ids.size());
  if (n == 0) return;
  const double w = camera.width, h = camera.height;
  const int cols = std::clamp(int(std::lround(std::sqrt(n * w / h))), 1, n);
  const int rows = (n + cols - 1) / cols;

  Random random(mix_seed(seed, 1));
  auto wave = [&] {
    return Wave{random.uniform(0.05, 0.15), random.uniform(0, kTwoPi), random.uniform(0.15, 0.35),
                random.uniform(0, kTwoPi)};
  };
  for (int i = 0; i < n; ++i) {
    // The cell's pixel edges, then the largest axis-aligned rectangle of normalised
    // coordinates whose image stays inside them (lens distortion bends the edges).
    const double x0 = (i % cols) * w / cols - 0.5, x1 = (i % cols + 1) * w / cols - 0.5;
    const double y0 = (i / cols) * h / rows - 0.5, y1 = (i / cols + 1) * h / rows - 0.5;
    const int steps = 8;
    std::vector<cv::Point2d> edge;
    for (int k = 0; k <= steps; ++k) {
      const double fx = x0 + (x1 - x0) * k / steps, fy = y0 + (y1 - y0) * k / steps;
      edge.insert(edge.end(), {{x0, fy}, {x1, fy}, {fx, y0}, {fx, y1}});
    }
    const std::vector<cv::Point2d> ideal = camera.undistort(edge);
    double left = -1e9, right = 1e9, top = -1e9, bottom = 1e9;
    for (std::size_t k = 0; k < ideal.size(); k += 4) {
      left = std::max(left, (ideal[k].x - camera.cx) / camera.fx);
      right = std::min(right, (ideal[k + 1].x - camera.cx) / camera.fx);
      top = std::max(top, (ideal[k + 2].y - camera.cy) / camera.fy);
      bottom = std::min(bottom, (ideal[k + 3].y - camera.cy) / camera.fy);
    }
    Path p;
    p.id = ids[i];
    p.u0 = (left + right) / 2, p.half_u = std::max(1e-6, (right - left) / 2);
    p.v0 = (top + bottom) / 2, p.half_v = std::max(1e-6, (bottom - top) / 2);
    p.z_near = tag_size * std::sqrt(0.5) / (kFill * std::min(p.half_u, p.half_v));
    p.u = wave(), p.v = wave(), p.depth = wave(), p.tilt_x = wave(), p.tilt_y = wave(), p.wobble = wave();
    p.roll0 = random.uniform(0, kTwoPi);
    p.roll_rate = random.uniform(0.15, 0.5) * (random.bits() & 1 ? 1 : -1);
    paths_.push_back(p);
  }
}

SceneMarker MarkerMotion::marker_at(const Path& p, double t) const {
  const double z = p.z_near * std::pow(kDepthRatio, (1 + p.depth(t)) / 2);
  // Room for the centre: the cell less the marker's half diagonal at this distance.
  const double reach = tag_size_ * std::sqrt(0.5) / z;
  const double u = p.u0 + p.u(t) * std::max(0.0, p.half_u - reach);
  const double v = p.v0 + p.v(t) * std::max(0.0, p.half_v - reach);

  // Spin in the marker plane, then tilt about the camera's x and y axes.
  const double a = kMaxTilt * p.tilt_x(t), b = kMaxTilt * p.tilt_y(t);
  const double roll = p.roll0 + p.roll_rate * t + 0.5 * p.wobble(t);
  const cv::Matx33d rx(1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a));
  const cv::Matx33d ry(std::cos(b), 0, std::sin(b), 0, 1, 0, -std::sin(b), 0, std::cos(b));
  const cv::Matx33d rz(std::cos(roll), -std::sin(roll), 0, std::sin(roll), std::cos(roll), 0, 0, 0, 1);
  cv::Vec3d rvec;
  cv::Rodrigues(rx * ry * rz, rvec);

  SceneMarker m;
  m.family = family_;
  m.id = p.id;
  m.tag_size = tag_size_;
  m.rvec = rvec;
  m.tvec = {u * z, v * z, z};
  return m;
}

std::vector<SceneMarker> MarkerMotion::at(double t) const {
  std::vector<SceneMarker> markers;
  for (const Path& p : paths_) markers.push_back(marker_at(p, t));
  return markers;
}

double MarkerMotion::max_corner_shift(double t0, double t1) const {
  std::vector<cv::Point3d> corners;
  for (const cv::Point2d& c : family_.outer_corners()) corners.push_back(family_.to_marker_frame(c, tag_size_));
  double shift = 0;
  for (const Path& p : paths_) {
    const SceneMarker a = marker_at(p, t0), b = marker_at(p, t1);
    const std::vector<cv::Point2d> pa = camera_.project(corners, a.rvec, a.tvec);
    const std::vector<cv::Point2d> pb = camera_.project(corners, b.rvec, b.tvec);
    for (std::size_t k = 0; k < pa.size(); ++k) shift = std::max(shift, cv::norm(pa[k] - pb[k]));
  }
  return shift;
}

std::vector<TagId> random_ids(const Family& family, std::size_t count, std::uint64_t seed) {
  const int bits = 2 * family.data_cell_count();
  const std::uint64_t low_mask = bits >= 64 ? ~0ull : (1ull << bits) - 1;
  const std::uint64_t high_mask = bits <= 64 ? 0 : (1ull << (bits - 64)) - 1;
  const std::size_t dictionary = bits < 64 ? std::size_t(1) << bits : SIZE_MAX;
  Random random(mix_seed(seed, 2));
  std::set<TagId> used;
  std::vector<TagId> ids;
  while (ids.size() < count) {
    const std::uint64_t high = random.bits() & high_mask;
    const TagId id(high, random.bits() & low_mask);
    if (used.insert(id).second || used.size() >= dictionary) ids.push_back(id);
  }
  return ids;
}

}  // namespace lftag::gst
