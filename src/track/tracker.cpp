// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/tracker.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "../core/rotation.hpp"

namespace lftag {
namespace {

// How many poses a track keeps: its velocity is taken over them (a constant velocity is
// exact from any two; more of them average the measurement noise).
constexpr std::size_t kHistory = 3;

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
  const cv::Matx33d r0 = detail::rotation_matrix(before), r1 = detail::rotation_matrix(after);
  const cv::Vec3d w = detail::rotation_vector(r1 * r0.t());  // the turn over `span`, in the camera frame
  return detail::rotation_vector(detail::rotation_matrix(w * (dt / span)) * r1);
}

template <class Points>
void move_points(const cv::Matx33d& h, Points& points) {
  for (cv::Point2d& p : points) {
    const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1);
    p = {q[0] / q[2], q[1] / q[2]};
  }
}

// Where a pose chain's rotation is expected at `time`: turned on at the rate of its last
// poses (constant angular velocity), or its last rotation when it has one pose.
template <class Chain>
cv::Vec3d expected_rotation(const Chain& chain, double time) {
  const auto &oldest = chain.front(), &newest = chain.back();
  const double span = newest.time - oldest.time;
  if (chain.size() < 2 || !(span > 0)) return newest.rvec;
  return extrapolate_rotation(oldest.rvec, newest.rvec, span, time - newest.time);
}

// What is left of a track's evidence about its pose chains after a measured frame: the
// evidence is mostly of the last few frames (a marker turning through face on may swap
// its chains). Chosen on the tracking experiment's tuning set (docs/BENCHMARKS.md,
// Tracking; 3x3, 4x4 and 6x6, video and field clips): wrong pose choices 103 of 7,263
// summed without forgetting, 102 with the sum bounded to +-log 3, 96 with 0.7 (per-frame
// choice: 96); on the validation set 30, 30 and 30 of 3,153 (per frame: 28).
constexpr double kEvidenceDecay = 0.7;

// `evidence` (for chain 0 over chain 1) with chain `chain` leading by at least `margin`.
double lead(double evidence, int chain, double margin) {
  return chain == 0 ? std::max(evidence, margin) : std::min(evidence, -margin);
}

}  // namespace

double rotation_angle(const cv::Vec3d& a, const cv::Vec3d& b) {
  const cv::Matx33d r = detail::rotation_matrix(a).t() * detail::rotation_matrix(b);
  return std::acos(std::clamp((r(0, 0) + r(1, 1) + r(2, 2) - 1) / 2, -1.0, 1.0));
}

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
          quaternion(d.rvec),
          {},
          0,
          0};
  t.info.id = next_id_++;
  t.info.first_seen = t.info.last_seen = t.info.time = time;
  t.history.push_back({time, d.corners, d.rvec, d.tvec});
  t.chains[0].push_back({time, d.rvec, d.tvec});
  if (d.ambiguity_ratio > 0) {
    t.chains[1].push_back({time, d.alternative_rvec, d.alternative_tvec});
    t.evidence = std::log(d.ambiguity_ratio);
  } else {
    t.evidence = lead(0, 0, std::log(std::max(params_.max_ambiguity_ratio, 1.0)));
  }
  return t;
}

// The outline moved on at the rate its corners moved over the track's history, or the
// last detection's when there is no motion to go by.
std::array<cv::Point2d, 4> Tracker::predicted_corners(const Track& track, double time) {
  const Sample& newest = track.history.back();
  const Sample& oldest = track.history.front();
  const double span = newest.time - oldest.time, dt = time - newest.time;
  if (track.history.size() < 2 || !(span > 0) || dt == 0) return track.last.corners;
  std::array<cv::Point2d, 4> corners;
  for (int k = 0; k < 4; ++k) corners[k] = newest.corners[k] + (newest.corners[k] - oldest.corners[k]) * (dt / span);
  return corners;
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
  const std::array<cv::Point2d, 4> corners = predicted_corners(track, time);
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
  // The pose from the reported chain's (the history's poses may be of either chain).
  const std::deque<ChainPose>& chain = track.chains[std::size_t(track.reported)];
  if (chain.size() >= 2 && chain.back().time > chain.front().time) {
    const double chain_span = chain.back().time - chain.front().time, chain_dt = time - chain.back().time;
    d.tvec = chain.back().tvec + (chain.back().tvec - chain.front().tvec) * (chain_dt / chain_span);
    d.rvec = extrapolate_rotation(chain.front().rvec, chain.back().rvec, chain_span, chain_dt);
  } else {
    d.tvec = newest.tvec + (newest.tvec - oldest.tvec) * (dt / span);
    d.rvec = extrapolate_rotation(oldest.rvec, newest.rvec, span, dt);
  }
  return out;
}

void Tracker::choose_pose(Track& track, Detection& d, double time, bool& flipped) const {
  flipped = false;
  auto& chains = track.chains;
  const bool alternative = d.ambiguity_ratio > 0;
  // Which chain the detector's own pose continues: the assignment of the two solutions to
  // the two chains whose rotations are nearer the chains' predictions.
  const cv::Vec3d p0 = expected_rotation(chains[0], time);
  int own = 0;
  if (chains[1].empty()) {
    own = alternative && rotation_angle(p0, d.alternative_rvec) < rotation_angle(p0, d.rvec) ? 1 : 0;
  } else {
    const cv::Vec3d p1 = expected_rotation(chains[1], time);
    if (alternative) {
      const double kept = rotation_angle(p0, d.rvec) + rotation_angle(p1, d.alternative_rvec);
      const double swapped = rotation_angle(p0, d.alternative_rvec) + rotation_angle(p1, d.rvec);
      own = swapped < kept ? 1 : 0;
    } else {
      own = rotation_angle(p1, d.rvec) < rotation_angle(p0, d.rvec) ? 1 : 0;
    }
  }
  auto push = [&](int chain, const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
    auto& c = chains[std::size_t(chain)];
    if (!c.empty() && c.back().time == time) c.pop_back();
    c.push_back({time, rvec, tvec});
    while (c.size() > kHistory) c.pop_front();
  };
  push(own, d.rvec, d.tvec);
  if (!alternative) {
    // Nothing to choose between (the other solution was behind the camera): as sure as a
    // settled pose, so its chain leads by at least the log of the settled ratio. The other
    // chain carries on unmeasured.
    track.evidence = lead(track.evidence, own, std::log(std::max(params_.max_ambiguity_ratio, 1.0)));
    track.reported = own;
    return;
  }
  push(1 - own, d.alternative_rvec, d.alternative_tvec);

  // The evidence: the log of the ratio of the two solutions' reprojection errors, for the
  // chain that took the detector's pose, summed over the track's measured frames with
  // the older frames' sum forgotten by kEvidenceDecay each frame.
  const double step = std::log(d.ambiguity_ratio) * (own == 0 ? 1 : -1);
  track.evidence = kEvidenceDecay * track.evidence + step;
  const bool settled = !(d.ambiguity_ratio < params_.max_ambiguity_ratio);
  if (settled) {
    // A settled pose stands, and its chain leads by at least this frame's evidence, so that
    // one settled frame corrects a chain that ambiguous ones had put in the lead (in the
    // ambiguity experiment 3 of 9,943 choices at a ratio of 3 or more were wrong,
    // docs/detector.md).
    track.evidence = lead(track.evidence, own, std::abs(step));
    track.reported = own;
    return;
  }
  const int favoured = track.evidence > 0 ? 0 : track.evidence < 0 ? 1 : own;
  track.reported = favoured;
  if (favoured == own) return;
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
    TrackedMarker m = predicted(track, time);
    // Two markers cannot lie in one place: a track of a single detection whose predicted
    // centre this frame measured inside another marker was a misreading of that marker
    // (a track measured in several frames is hidden by it, and predicted).
    const bool single = track.info.last_seen == track.info.first_seen;
    const bool superseded = single && std::any_of(detections.begin(), detections.end(), [&](const Detection& d) {
                              const std::vector<cv::Point2f> outline(d.corners.begin(), d.corners.end());
                              return (d.family != track.last.family || d.id != track.last.id) &&
                                     cv::pointPolygonTest(outline, cv::Point2f(m.detection.center), false) >= 0;
                            });
    if (superseded || time - track.info.last_seen > params_.lost_after) {
      m = TrackedMarker{track.last, track.info};
      m.track.state = TrackState::lost;
      m.track.time = time;
      m.track.flipped = false;
      lost_.push_back(std::move(m));
      continue;
    }
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
  for (const Track& t : tracks_) out.push_back({t.last.family, t.last.id, predicted_corners(t, time)});
  return out;
}

}  // namespace lftag
