// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/tracker.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include <opencv2/calib3d.hpp>

namespace lftag {
namespace {

// How many poses a track keeps: its velocity is taken over them (a constant velocity is
// exact from any two; more of them average the measurement noise).
constexpr std::size_t kHistory = 3;

double angle_between(const cv::Vec3d& a, const cv::Vec3d& b) {
  cv::Matx33d ra, rb;
  cv::Rodrigues(a, ra);
  cv::Rodrigues(b, rb);
  const cv::Matx33d r = ra.t() * rb;
  return std::acos(std::clamp((r(0, 0) + r(1, 1) + r(2, 2) - 1) / 2, -1.0, 1.0));
}

// Unit quaternion (w, x, y, z) of a rotation vector, and back.
cv::Vec4d quaternion(const cv::Vec3d& r) {
  const double angle = cv::norm(r);
  if (angle < 1e-12) return {1, r[0] / 2, r[1] / 2, r[2] / 2};
  const double s = std::sin(angle / 2) / angle;
  return {std::cos(angle / 2), r[0] * s, r[1] * s, r[2] * s};
}

cv::Vec3d rotation_vector(cv::Vec4d q) {
  q *= 1.0 / cv::norm(q);
  const cv::Vec3d v(q[1], q[2], q[3]);
  const double s = cv::norm(v);
  if (s < 1e-12) return v * 2.0;
  return v * (2 * std::atan2(s, q[0]) / s);
}

// The rotation `rvec` turned on for `dt` seconds at the rate it turned from `before` to
// `after` over `span` seconds.
cv::Vec3d extrapolate_rotation(const cv::Vec3d& before, const cv::Vec3d& after, double span, double dt) {
  cv::Matx33d r0, r1, step;
  cv::Rodrigues(before, r0);
  cv::Rodrigues(after, r1);
  cv::Vec3d w;
  cv::Rodrigues(r1 * r0.t(), w);  // the turn over `span`, in the camera frame
  cv::Rodrigues(cv::Vec3d(w * (dt / span)), step);
  cv::Vec3d out;
  cv::Rodrigues(step * r1, out);
  return out;
}

template <class Points>
void move_points(const cv::Matx33d& h, Points& points) {
  for (cv::Point2d& p : points) {
    const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1);
    p = {q[0] / q[2], q[1] / q[2]};
  }
}

}  // namespace

const char* track_state_name(TrackState state) {
  switch (state) {
    case TrackState::measured: return "measured";
    case TrackState::predicted: return "predicted";
    case TrackState::lost: return "lost";
  }
  return "?";
}

void TrackerParams::validate() const {
  const auto require = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("TrackerParams: ") + what);
  };
  require(std::isfinite(lost_after) && lost_after >= 0, "lost_after must be a finite number of seconds >= 0");
  require(std::isfinite(max_ambiguity_ratio) && max_ambiguity_ratio >= 0, "max_ambiguity_ratio must be >= 0");
  require(std::isfinite(min_cutoff) && min_cutoff > 0, "min_cutoff must be > 0 Hz");
  require(std::isfinite(beta) && beta >= 0, "beta must be >= 0");
  require(std::isfinite(derivative_cutoff) && derivative_cutoff > 0, "derivative_cutoff must be > 0 Hz");
}

// ---- One Euro filter

namespace {
// The smoothing factor of an exponential filter with cutoff `hz` sampled `dt` apart.
double smoothing_factor(double hz, double dt) {
  const double tau = 1.0 / (2 * CV_PI * hz);
  return 1.0 / (1.0 + tau / dt);
}
}  // namespace

template <int N>
typename OneEuroFilter<N>::Vector OneEuroFilter<N>::operator()(double t, const Vector& x) {
  if (!started_ || !(t > t_)) {
    started_ = true;
    t_ = t;
    x_ = x;
    dx_ = Vector::all(0);
    return x;
  }
  const double dt = t - t_;
  const Vector rate = (x - x_) * (1.0 / dt);
  dx_ += (rate - dx_) * smoothing_factor(derivative_cutoff_, dt);
  const double cutoff = min_cutoff_ + beta_ * cv::norm(dx_);
  x_ += (x - x_) * smoothing_factor(cutoff, dt);
  t_ = t;
  return x_;
}

template class OneEuroFilter<1>;
template class OneEuroFilter<3>;
template class OneEuroFilter<4>;

// ---- Tracker

Tracker::Tracker(TrackerParams params) : params_(params) { params_.validate(); }

void Tracker::set_params(const TrackerParams& params) {
  params.validate();
  const bool filter_changed = params.smoothing != params_.smoothing || params.min_cutoff != params_.min_cutoff ||
                              params.beta != params_.beta || params.derivative_cutoff != params_.derivative_cutoff;
  params_ = params;
  if (!filter_changed) return;
  for (Track& t : tracks_) {
    t.translation = OneEuroFilter<3>(params_.min_cutoff, params_.beta, params_.derivative_cutoff);
    t.rotation = OneEuroFilter<4>(params_.min_cutoff, params_.beta, params_.derivative_cutoff);
  }
}

void Tracker::reset() {
  tracks_.clear();
  lost_.clear();
  started_ = false;
}

Tracker::Track Tracker::new_track(const Detection& d, double time) {
  Track t{TrackInfo{},
          d,
          {},
          OneEuroFilter<3>(params_.min_cutoff, params_.beta, params_.derivative_cutoff),
          OneEuroFilter<4>(params_.min_cutoff, params_.beta, params_.derivative_cutoff),
          quaternion(d.rvec)};
  t.info.id = next_id_++;
  t.info.first_seen = t.info.last_seen = t.info.time = time;
  t.history.push_back({time, d.corners, d.rvec, d.tvec});
  return t;
}

TrackedMarker Tracker::predicted(const Track& track, double time) const {
  TrackedMarker out{track.last, track.info};
  out.track.time = time;
  out.track.state = TrackState::predicted;
  out.track.flipped = false;
  out.track.smoothed = false;
  const Sample& newest = track.history.back();
  const Sample& oldest = track.history.front();
  const double span = newest.time - oldest.time, dt = time - newest.time;
  if (track.history.size() < 2 || !(span > 0) || dt == 0) return out;

  Detection& d = out.detection;
  std::array<cv::Point2d, 4> corners;
  for (int k = 0; k < 4; ++k) corners[k] = newest.corners[k] + (newest.corners[k] - oldest.corners[k]) * (dt / span);
  // The rest of the outline's points follow its corners (the last detection's points are
  // where its corners were: newest.corners).
  const std::vector<cv::Point2d> from(newest.corners.begin(), newest.corners.end()), to(corners.begin(), corners.end());
  const cv::Mat h = cv::findHomography(from, to, 0);
  if (!h.empty()) {
    const cv::Matx33d m(h);
    move_points(m, d.keypoints);
    move_points(m, d.centroids);
    std::array<cv::Point2d, 1> center{d.center};
    move_points(m, center);
    d.center = center[0];
  }
  d.corners = corners;
  d.tvec = newest.tvec + (newest.tvec - oldest.tvec) * (dt / span);
  d.rvec = extrapolate_rotation(oldest.rvec, newest.rvec, span, dt);
  return out;
}

void Tracker::choose_pose(const Track& track, Detection& d, double time, bool& flipped) const {
  flipped = false;
  if (!(d.ambiguity_ratio > 0) || !(d.ambiguity_ratio < params_.max_ambiguity_ratio)) return;
  const cv::Vec3d expected = predicted(track, time).detection.rvec;
  if (angle_between(expected, d.alternative_rvec) >= angle_between(expected, d.rvec)) return;
  std::swap(d.rvec, d.alternative_rvec);
  std::swap(d.tvec, d.alternative_tvec);
  std::swap(d.reprojection_error, d.alternative_reprojection_error);
  d.ambiguity_ratio = 1.0 / d.ambiguity_ratio;
  flipped = true;
}

void Tracker::smooth(Track& track, TrackedMarker& out) {
  if (!params_.smoothing) return;
  const double t = out.track.time;
  cv::Vec4d q = quaternion(out.detection.rvec);
  if (q.dot(track.last_quaternion) < 0) q = -q;  // the same rotation, on the filter's side
  track.last_quaternion = q;
  out.track.smoothed = true;
  out.track.smoothed_tvec = track.translation(t, out.detection.tvec);
  out.track.smoothed_rvec = rotation_vector(track.rotation(t, q));
  track.info.smoothed = true;
  track.info.smoothed_rvec = out.track.smoothed_rvec;
  track.info.smoothed_tvec = out.track.smoothed_tvec;
}

std::vector<TrackedMarker> Tracker::update(double time, const std::vector<Detection>& detections) {
  if (started_ && time < last_time_) reset();
  started_ = true;
  last_time_ = time;
  lost_.clear();

  std::vector<bool> seen(tracks_.size(), false);
  std::vector<TrackedMarker> out;
  out.reserve(detections.size() + tracks_.size());
  for (const Detection& detection : detections) {
    const auto it = std::find_if(tracks_.begin(), tracks_.end(), [&](const Track& t) {
      return t.last.family == detection.family && t.last.id == detection.id;
    });
    if (it == tracks_.end()) {
      tracks_.push_back(new_track(detection, time));
      seen.push_back(true);
      TrackedMarker m{detection, tracks_.back().info};
      smooth(tracks_.back(), m);
      out.push_back(std::move(m));
      continue;
    }
    const std::size_t index = std::size_t(it - tracks_.begin());
    if (seen[index]) {  // the same id twice in one frame: neither is the other's track
      TrackedMarker m{detection, TrackInfo{}};
      m.track.first_seen = m.track.last_seen = m.track.time = time;
      out.push_back(std::move(m));
      continue;
    }
    seen[index] = true;
    Track& track = *it;
    TrackedMarker m{detection, {}};
    choose_pose(track, m.detection, time, m.track.flipped);
    track.info.state = TrackState::measured;
    track.info.last_seen = track.info.time = time;
    track.last = m.detection;
    if (!track.history.empty() && track.history.back().time == time) track.history.pop_back();
    track.history.push_back({time, m.detection.corners, m.detection.rvec, m.detection.tvec});
    while (track.history.size() > kHistory) track.history.pop_front();
    const bool flipped = m.track.flipped;
    m.track = track.info;
    m.track.flipped = flipped;
    m.track.smoothed = false;
    smooth(track, m);
    out.push_back(std::move(m));
  }

  std::vector<Track> kept;
  kept.reserve(tracks_.size());
  for (std::size_t i = 0; i < tracks_.size(); ++i) {
    Track& track = tracks_[i];
    if (seen[i]) {
      kept.push_back(std::move(track));
      continue;
    }
    if (time - track.info.last_seen > params_.lost_after) {
      TrackedMarker m{track.last, track.info};
      m.track.state = TrackState::lost;
      m.track.time = time;
      m.track.flipped = false;
      lost_.push_back(std::move(m));
      continue;
    }
    TrackedMarker m = predicted(track, time);
    track.info.state = TrackState::predicted;
    track.info.time = time;
    smooth(track, m);
    out.push_back(std::move(m));
    kept.push_back(std::move(track));
  }
  tracks_ = std::move(kept);
  return out;
}

std::vector<TrackedMarker> Tracker::predict(double time) const {
  std::vector<TrackedMarker> out;
  for (const Track& t : tracks_) out.push_back(predicted(t, time));
  return out;
}

std::vector<ExpectedMarker> Tracker::expected(double time) const {
  std::vector<ExpectedMarker> out;
  if (started_ && time < last_time_) return out;
  for (const Track& t : tracks_) {
    const Detection d = predicted(t, time).detection;
    out.push_back({d.family, d.id, d.corners});
  }
  return out;
}

}  // namespace lftag
