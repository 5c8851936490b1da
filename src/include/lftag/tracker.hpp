// SPDX-License-Identifier: LGPL-2.1-or-later
// Tracking markers from frame to frame: one track per marker (family and id), a
// constant-velocity model of its outline and pose, and an optional One Euro filter on
// the published pose.
//
//   lftag::Tracker tracker;                          // lost after 0.5 s unseen
//   for (each frame at time t, in seconds)
//     for (const lftag::TrackedMarker& m : tracker.update(t, detector.detect(view)))
//       std::cout << m.track.id << " " << lftag::track_state_name(m.track.state) << "\n";
//
// A marker is only ever tracked under the id it was decoded with: a track is found again
// by its family and id, never by where it is, so a marker missed in a frame is reported
// as predicted under the id it had, and two markers that cross keep their tracks.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/detector.hpp"

namespace lftag {

enum class TrackState {
  measured,   // detected in this frame
  predicted,  // not detected in this frame: where the motion model puts it
  lost,       // unseen for longer than TrackerParams::lost_after, or a track of one detection
              // whose predicted centre this frame measured inside another marker: ended
};
const char* track_state_name(TrackState state);  // "measured", "predicted", "lost"

// The angle in radians, 0 to pi, of the rotation between two orientations given as
// rotation vectors (Rodrigues): how far apart two poses' orientations are.
double rotation_angle(const cv::Vec3d& a, const cv::Vec3d& b);

struct TrackerParams {
  // Seconds a track may go unseen and still be reported (as predicted); once longer
  // unseen it is lost, reported once, and dropped. 0: lost in the first frame it is
  // missed (never predicted).
  double lost_after = 0.5;
  // A detection whose pose is ambiguous (Detection::ambiguity_ratio under this) takes the
  // solution the track's accumulated evidence favours: the track follows both solutions
  // of the planar pose from frame to frame (two chains, each frame's two solutions going
  // to the chains whose predicted rotations they are nearer), sums for each chain the log
  // of the reprojection errors of the solutions it was given, and reports the chain with
  // the smaller sum. A detection at or above this ratio keeps the detector's choice and
  // puts its chain in the lead. 0: the detector's choice always stands.
  double max_ambiguity_ratio = 3.0;
  // The One Euro filter on the published pose (TrackInfo::smoothed_rvec/tvec); off by
  // default. The filter's cutoff frequency is min_cutoff + beta * speed, in hertz, where
  // the speed is the filtered rate of change of the translation (m/s) or of the rotation
  // (unit quaternion per second): a still marker is smoothed hard (lag about
  // 1 / (2 pi min_cutoff) seconds), a fast one little.
  bool smoothing = false;
  double min_cutoff = 1.0;         // Hz, > 0
  double beta = 1.0;               // >= 0
  double derivative_cutoff = 1.0;  // Hz, > 0: the cutoff of the speed's own filter

  // Throws std::invalid_argument naming the first parameter out of range.
  void validate() const;
};

// The One Euro filter (Casiez, Roussel and Vogel, CHI 2012) of a vector of N values:
// an exponential smoother whose cutoff frequency rises with the signal's speed.
template <int N>
class OneEuroFilter {
 public:
  using Vector = cv::Vec<double, N>;
  OneEuroFilter(double min_cutoff, double beta, double derivative_cutoff)
      : min_cutoff_(min_cutoff), beta_(beta), derivative_cutoff_(derivative_cutoff) {}
  // The filtered value of `x` sampled at time `t` (seconds). The first sample, and one at
  // a time not after the last, passes unchanged and restarts the filter.
  Vector operator()(double t, const Vector& x);
  void reset() { started_ = false; }

 private:
  double min_cutoff_, beta_, derivative_cutoff_;
  bool started_ = false;
  double t_ = 0;
  Vector x_, dx_;
};

extern template class OneEuroFilter<1>;
extern template class OneEuroFilter<3>;
extern template class OneEuroFilter<4>;

// The track of a marker as one frame reports it.
struct TrackInfo {
  std::uint64_t id = 0;  // from 1, in order of the tracks' starts; never reused by a tracker
  TrackState state = TrackState::measured;
  double first_seen = 0;  // seconds: the frame the track started
  double last_seen = 0;   // seconds: the last frame it was detected in
  double time = 0;        // seconds: this frame
  double age() const { return time - first_seen; }
  double unseen() const { return time - last_seen; }
  // The detector's pose was replaced by its other solution, the one on the track's
  // favoured chain (see TrackerParams::max_ambiguity_ratio; the detection's rvec/tvec and
  // alternative_* are then swapped).
  bool flipped = false;
  // The One Euro filter's pose (with TrackerParams::smoothing); the raw one stays in the
  // Detection.
  bool smoothed = false;
  cv::Vec3d smoothed_rvec, smoothed_tvec;
};

struct TrackedMarker {
  // Measured: the detection (with its pose possibly flipped, see TrackInfo::flipped).
  // Predicted: the last detection moved to where the model puts it now: corners, key
  // points, centroids and centre by the outline's motion, rvec and tvec by the pose's.
  Detection detection;
  TrackInfo track;
};

class Tracker {
 public:
  // Throws std::invalid_argument when a parameter is out of range.
  explicit Tracker(TrackerParams params = {});
  const TrackerParams& params() const { return params_; }
  // New parameters for the tracks under way (the smoother restarts when its own change).
  void set_params(const TrackerParams& params);

  // The frame at `time` (seconds; a time before the last frame's starts over, as after a
  // seek) with its detections. Returns every detection, measured (a second detection of
  // the same marker in one frame starts no track and is reported untracked: id 0), then
  // every track that was not detected but is not yet lost, predicted, in the order the
  // tracks started. The tracks that this frame lost are in lost().
  std::vector<TrackedMarker> update(double time, const std::vector<Detection>& detections);
  // The tracks the last update() ended, with their last detection (state lost).
  const std::vector<TrackedMarker>& lost() const { return lost_; }
  // Where every live track is predicted at `time`, without changing anything.
  std::vector<TrackedMarker> predict(double time) const;
  // The markers of the live tracks, where they are predicted at `time`, for the detector
  // to look for first (FrameHints::expected); none for a time before the last frame's
  // (update() starts over there).
  std::vector<ExpectedMarker> expected(double time) const;
  std::size_t size() const { return tracks_.size(); }
  // Ends every track without reporting it (a new stream).
  void reset();

 private:
  struct Sample {
    double time;
    std::array<cv::Point2d, 4> corners;
    cv::Vec3d rvec, tvec;
  };
  struct ChainPose {
    double time;
    cv::Vec3d rvec, tvec;
  };
  struct Track {
    TrackInfo info;
    Detection last;              // the last detection
    std::deque<Sample> history;  // the last poses, newest last
    OneEuroFilter<3> translation;
    OneEuroFilter<4> rotation;  // a unit quaternion, kept on one hemisphere
    cv::Vec4d last_quaternion;
    // The planar pose's two solutions followed from frame to frame (the last poses of
    // each, newest last; the second is empty until a detection had an alternative), the
    // evidence for the first over the second (sum of log reprojection error ratios), and
    // the chain reported.
    std::array<std::deque<ChainPose>, 2> chains;
    double evidence = 0;
    int reported = 0;
  };
  Track new_track(const Detection& d, double time);
  TrackedMarker predicted(const Track& track, double time) const;
  static std::array<cv::Point2d, 4> predicted_corners(const Track& track, double time);
  void smooth(Track& track, TrackedMarker& out);
  void choose_pose(Track& track, Detection& d, double time, bool& flipped) const;

  TrackerParams params_;
  std::vector<Track> tracks_;
  std::vector<TrackedMarker> lost_;
  std::uint64_t next_id_ = 1;
  double last_time_ = 0;
  bool started_ = false;
};

}  // namespace lftag
