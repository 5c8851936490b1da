// SPDX-License-Identifier: LGPL-2.1-or-later
// The tracker: prediction of a marker missed in a frame, loss after the stated time,
// crossing markers, the choice of an ambiguous pose by the evidence the track has, and the One Euro
// filter's lag on a step.
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "lftag/detector.hpp"
#include "lftag/render.hpp"
#include "lftag/tracker.hpp"

using namespace lftag;

namespace {

constexpr double kFrame = 1.0 / 30;

// A marker whose outline is the square of side `side` px with its top-left corner at
// `origin`, at tvec (x, y, 1) m, facing the camera.
Detection square(TagId id, cv::Point2d origin, double side = 40) {
  Detection d;
  d.family = Family(3);
  d.id = id;
  d.corners = {origin, origin + cv::Point2d(side, 0), origin + cv::Point2d(side, side), origin + cv::Point2d(0, side)};
  d.center = origin + cv::Point2d(side / 2, side / 2);
  d.keypoints = {origin + cv::Point2d(10, 10), origin + cv::Point2d(30, 10), origin + cv::Point2d(10, 30),
                 origin + cv::Point2d(30, 30)};
  d.centroids.assign(d.keypoints.begin(), d.keypoints.end());
  d.rvec = {0, 0, 0};
  d.tvec = {origin.x / 1000, origin.y / 1000, 1};
  return d;
}

double angle_deg(const cv::Vec3d& a, const cv::Vec3d& b) { return lftag::rotation_angle(a, b) * 180 / CV_PI; }

}  // namespace

TEST(Tracker, RotationAngleIsTheAngleBetweenTwoOrientations) {
  EXPECT_NEAR(lftag::rotation_angle({0, 0, 0}, {0, 0, 0.5}), 0.5, 1e-12);
  EXPECT_NEAR(lftag::rotation_angle({0.3, 0, 0}, {0.3, 0, 0}), 0, 1e-6);
  // Composed about one axis the angles subtract; about any axis the angle is symmetric.
  EXPECT_NEAR(lftag::rotation_angle({0, 1.0, 0}, {0, -0.5, 0}), 1.5, 1e-12);
  const cv::Vec3d a(0.2, -0.4, 1.1), b(-0.7, 0.1, 0.3);
  EXPECT_NEAR(lftag::rotation_angle(a, b), lftag::rotation_angle(b, a), 1e-12);
  EXPECT_NEAR(lftag::rotation_angle({0, 0, 0}, {CV_PI, 0, 0}), CV_PI, 1e-9);
}

TEST(Tracker, MeasuredMarkersKeepTheirTrack) {
  Tracker tracker;
  std::uint64_t id = 0;
  for (int f = 0; f < 10; ++f) {
    const auto out = tracker.update(f * kFrame, {square(TagId(7), {100.0 + 5 * f, 50})});
    ASSERT_EQ(out.size(), 1u);
    EXPECT_EQ(out[0].track.state, TrackState::measured);
    if (f == 0) id = out[0].track.id;
    EXPECT_EQ(out[0].track.id, id);
    EXPECT_DOUBLE_EQ(out[0].track.first_seen, 0);
    EXPECT_DOUBLE_EQ(out[0].track.last_seen, f * kFrame);
    EXPECT_NEAR(out[0].track.age(), f * kFrame, 1e-12);
    EXPECT_FALSE(out[0].track.smoothed);
  }
  EXPECT_EQ(id, 1u);
}

// A marker moving at constant velocity and missed in a frame is reported where it would
// have been, under its id and track, with all its points and its pose moved.
TEST(Tracker, PredictsAMissedMarkerAtConstantVelocity) {
  Tracker tracker;
  const cv::Point2d velocity(6, -2);  // px per frame
  for (int f = 0; f < 4; ++f) tracker.update(f * kFrame, {square(TagId(7), cv::Point2d(100, 200) + f * velocity)});
  const auto out = tracker.update(4 * kFrame, {});
  ASSERT_EQ(out.size(), 1u);
  const TrackedMarker& m = out[0];
  EXPECT_EQ(m.track.state, TrackState::predicted);
  EXPECT_EQ(m.track.id, 1u);
  EXPECT_EQ(m.detection.id, TagId(7));
  EXPECT_NEAR(m.track.last_seen, 3 * kFrame, 1e-12);
  EXPECT_NEAR(m.track.unseen(), kFrame, 1e-12);
  const Detection truth = square(TagId(7), cv::Point2d(100, 200) + 4 * velocity);
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(m.detection.corners[k].x, truth.corners[k].x, 1e-6);
    EXPECT_NEAR(m.detection.corners[k].y, truth.corners[k].y, 1e-6);
    EXPECT_NEAR(m.detection.keypoints[k].x, truth.keypoints[k].x, 1e-6);
    EXPECT_NEAR(m.detection.keypoints[k].y, truth.keypoints[k].y, 1e-6);
  }
  EXPECT_NEAR(m.detection.center.x, truth.center.x, 1e-6);
  EXPECT_NEAR(m.detection.center.y, truth.center.y, 1e-6);
  EXPECT_NEAR(cv::norm(m.detection.tvec - truth.tvec), 0, 1e-9);
  // predict() says the same without changing anything.
  const auto ahead = tracker.predict(5 * kFrame);
  ASSERT_EQ(ahead.size(), 1u);
  EXPECT_NEAR(ahead[0].detection.center.x, truth.center.x + velocity.x, 1e-6);
  EXPECT_EQ(tracker.size(), 1u);
}

// What the tracks expect in the next frame (FrameHints::expected): each live track's
// family, id and predicted outline; nothing for a time before the last frame's.
TEST(Tracker, ExpectedMarkersAreTheTracksPredictions) {
  Tracker tracker;
  const cv::Point2d velocity(4, 3);
  for (int f = 0; f < 3; ++f)
    tracker.update(f * kFrame, {square(TagId(7), cv::Point2d(100, 200) + f * velocity),
                                square(TagId(9), cv::Point2d(300, 50), 60)});
  const std::vector<ExpectedMarker> expected = tracker.expected(3 * kFrame);
  ASSERT_EQ(expected.size(), 2u);
  const Detection truth = square(TagId(7), cv::Point2d(100, 200) + 3 * velocity);
  EXPECT_EQ(expected[0].id, TagId(7));
  EXPECT_EQ(expected[0].family, Family(3));
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(cv::norm(expected[0].corners[k] - truth.corners[k]), 0, 1e-6);
  EXPECT_EQ(expected[1].id, TagId(9));
  EXPECT_NEAR(cv::norm(expected[1].corners[2] - cv::Point2d(360, 110)), 0, 1e-6);
  EXPECT_TRUE(tracker.expected(kFrame).empty());  // before the last frame: update() starts over there
  EXPECT_EQ(tracker.size(), 2u);
}

// A turning marker's rotation is extrapolated at its rate of turn.
TEST(Tracker, PredictsRotation) {
  Tracker tracker;
  for (int f = 0; f < 3; ++f) {
    Detection d = square(TagId(3), {100, 100});
    d.rvec = {0, 0.05 * f, 0};
    tracker.update(f * kFrame, {d});
  }
  const auto out = tracker.update(4 * kFrame, {});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_NEAR(angle_deg(out[0].detection.rvec, {0, 0.2, 0}), 0, 1e-6);
}

// Unseen for longer than lost_after, a track is reported lost once and dropped; the same
// marker seen again starts a new track.
TEST(Tracker, LostAfterTheStatedTime) {
  TrackerParams params;
  params.lost_after = 0.1;
  Tracker tracker(params);
  tracker.update(0, {square(TagId(5), {10, 10})});
  int f = 1;
  for (; f * kFrame <= 0.1 + 1e-9; ++f) {
    const auto out = tracker.update(f * kFrame, {});
    ASSERT_EQ(out.size(), 1u) << "frame " << f;
    EXPECT_EQ(out[0].track.state, TrackState::predicted);
    EXPECT_TRUE(tracker.lost().empty());
  }
  EXPECT_EQ(f, 4);  // 1/30, 2/30 and 3/30 s unseen are within 0.1 s
  const auto out = tracker.update(f * kFrame, {});
  EXPECT_TRUE(out.empty());
  ASSERT_EQ(tracker.lost().size(), 1u);
  EXPECT_EQ(tracker.lost()[0].track.state, TrackState::lost);
  EXPECT_EQ(tracker.lost()[0].track.id, 1u);
  EXPECT_EQ(tracker.lost()[0].detection.id, TagId(5));
  EXPECT_EQ(tracker.size(), 0u);
  EXPECT_TRUE(tracker.update((f + 1) * kFrame, {}).empty());
  EXPECT_TRUE(tracker.lost().empty());  // reported once
  const auto again = tracker.update((f + 2) * kFrame, {square(TagId(5), {10, 10})});
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(again[0].track.id, 2u);
}

TEST(Tracker, LostAfterZeroIsNeverPredicted) {
  TrackerParams params;
  params.lost_after = 0;
  Tracker tracker(params);
  tracker.update(0, {square(TagId(5), {10, 10})});
  EXPECT_TRUE(tracker.update(kFrame, {}).empty());
  EXPECT_EQ(tracker.lost().size(), 1u);
}

// Two markers that pass through each other keep their tracks (tracks follow ids, never
// places), and one hidden while they overlap is predicted under its own id.
TEST(Tracker, CrossingMarkersKeepTheirTracks) {
  Tracker tracker;
  std::uint64_t track_a = 0, track_b = 0;
  for (int f = 0; f <= 20; ++f) {
    std::vector<Detection> found;
    found.push_back(square(TagId(1), {100.0 + 10 * f, 100}));
    if (f != 10) found.push_back(square(TagId(2), {300.0 - 10 * f, 104}));  // hidden behind 1 at f = 10
    const auto out = tracker.update(f * kFrame, found);
    ASSERT_EQ(out.size(), 2u);
    for (const TrackedMarker& m : out) {
      std::uint64_t& expected = m.detection.id == TagId(1) ? track_a : track_b;
      if (f == 0) expected = m.track.id;
      EXPECT_EQ(m.track.id, expected) << "frame " << f;
      EXPECT_EQ(m.track.state, f == 10 && m.detection.id == TagId(2) ? TrackState::predicted : TrackState::measured);
    }
    if (f == 10) {
      EXPECT_NEAR(out[1].detection.corners[0].x, 200, 1e-6);
    }
  }
  EXPECT_NE(track_a, track_b);
}

// The same id twice in one frame: the first continues the track, the second is untracked.
// A marker misread once (id 9 where marker 1 is, as a shadow can make a 2x2 read) is
// not carried on as a prediction once its place is read as marker 1 again: it ends,
// reported lost, while a track measured in several frames stays predicted when another
// marker covers it (above).
TEST(Tracker, AMisreadingOfAnotherMarkerEndsWhereThatMarkerIsRead) {
  Tracker tracker;
  tracker.update(0, {square(TagId(1), {100, 100})});
  tracker.update(kFrame, {square(TagId(9), {101, 100})});
  const auto out = tracker.update(2 * kFrame, {square(TagId(1), {102, 100})});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].detection.id, TagId(1));
  EXPECT_EQ(out[0].track.state, TrackState::measured);
  ASSERT_EQ(tracker.lost().size(), 1u);
  EXPECT_EQ(tracker.lost()[0].detection.id, TagId(9));
  // Elsewhere a single detection is predicted as before.
  tracker.update(3 * kFrame, {square(TagId(1), {103, 100}), square(TagId(9), {400, 100})});
  const auto later = tracker.update(4 * kFrame, {square(TagId(1), {104, 100})});
  ASSERT_EQ(later.size(), 2u);
  EXPECT_EQ(later[1].detection.id, TagId(9));
  EXPECT_EQ(later[1].track.state, TrackState::predicted);
}

TEST(Tracker, DuplicateIdStartsNoTrack) {
  Tracker tracker;
  const auto out = tracker.update(0, {square(TagId(1), {0, 0}), square(TagId(1), {300, 0})});
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].track.id, 1u);
  EXPECT_EQ(out[1].track.id, 0u);
  EXPECT_EQ(tracker.size(), 1u);
}

// Time going back (a seek) starts over.
TEST(Tracker, TimeGoingBackStartsOver) {
  Tracker tracker;
  tracker.update(1.0, {square(TagId(1), {0, 0})});
  const auto out = tracker.update(0.5, {});
  EXPECT_TRUE(out.empty());
  EXPECT_TRUE(tracker.lost().empty());
  EXPECT_EQ(tracker.size(), 0u);
}

// After frames with one solution only (as sure as settled ones), an ambiguous pose takes
// the solution on the track's chain; a settled one stays.
TEST(Tracker, AmbiguousPoseFollowsTheTrack) {
  const cv::Vec3d tilted(0.4, 0, 0), flip(-0.4, 0, 0);
  for (double ratio : {1.2, 5.0}) {
    Tracker tracker;
    for (int f = 0; f < 3; ++f) {
      Detection d = square(TagId(9), {100, 100});
      d.rvec = tilted;
      tracker.update(f * kFrame, {d});
    }
    Detection d = square(TagId(9), {100, 100});
    d.rvec = flip;
    d.tvec = {0.1, 0.1, 1.01};
    d.alternative_rvec = tilted;
    d.alternative_tvec = {0.1, 0.1, 1.0};
    d.reprojection_error = 0.10;
    d.alternative_reprojection_error = 0.10 * ratio;
    d.ambiguity_ratio = ratio;
    const auto out = tracker.update(3 * kFrame, {d});
    ASSERT_EQ(out.size(), 1u);
    if (ratio < 3) {
      EXPECT_TRUE(out[0].track.flipped);
      EXPECT_NEAR(angle_deg(out[0].detection.rvec, tilted), 0, 1e-9);
      EXPECT_NEAR(out[0].detection.tvec[2], 1.0, 1e-12);
      EXPECT_NEAR(angle_deg(out[0].detection.alternative_rvec, flip), 0, 1e-9);
      EXPECT_NEAR(out[0].detection.ambiguity_ratio, 1 / ratio, 1e-12);
      EXPECT_NEAR(out[0].detection.reprojection_error, 0.10 * ratio, 1e-12);
    } else {
      EXPECT_FALSE(out[0].track.flipped);
      EXPECT_NEAR(angle_deg(out[0].detection.rvec, flip), 0, 1e-9);
    }
  }
}

namespace {

// A detection of marker 9 whose best solution is `best` (reprojection error 0.1 px) and
// whose other is `other`, `ratio` times worse.
Detection ambiguous(const cv::Vec3d& best, const cv::Vec3d& other, double ratio) {
  Detection d = square(TagId(9), {100, 100});
  d.rvec = best;
  d.alternative_rvec = other;
  d.tvec = {0.1, 0.1, 1.0};
  d.alternative_tvec = {0.1, 0.1, 1.01};
  d.reprojection_error = 0.10;
  d.alternative_reprojection_error = 0.10 * ratio;
  d.ambiguity_ratio = ratio;
  return d;
}

// A marker turning about its x axis, tilted 0.3 rad and 0.02 rad more each frame, and its
// flip (tilted the other way), the planar pose's other solution.
cv::Vec3d turning(int f) { return {0.3 + 0.02 * f, 0, 0}; }
cv::Vec3d turning_flip(int f) { return {-(0.3 + 0.02 * f), 0, 0}; }

}  // namespace

// The first frames' per-frame choice is the flip; later frames that fit the true pose
// better (settled, or only ambiguous but clearly better) outweigh them, and the track
// then stays on the true pose through frames that again favour the flip a little.
TEST(Tracker, EvidenceOvercomesAnEarlyFlip) {
  for (double later : {2.5, 5.0}) {
    Tracker tracker;
    int f = 0;
    for (; f < 4; ++f) {  // the flip fits 1.2 times better
      const auto out = tracker.update(f * kFrame, {ambiguous(turning_flip(f), turning(f), 1.2)});
      ASSERT_EQ(out.size(), 1u);
    }
    for (; f < 8; ++f) {  // the truth fits `later` times better
      const auto out = tracker.update(f * kFrame, {ambiguous(turning(f), turning_flip(f), later)});
      ASSERT_EQ(out.size(), 1u);
      if (f >= 5) {  // the first such frame may not yet outweigh the four before
        EXPECT_NEAR(angle_deg(out[0].detection.rvec, turning(f)), 0, 1e-9) << "later " << later << " frame " << f;
        EXPECT_FALSE(out[0].track.flipped);
      }
    }
    for (; f < 11; ++f) {  // the flip fits 1.2 times better again
      const auto out = tracker.update(f * kFrame, {ambiguous(turning_flip(f), turning(f), 1.2)});
      ASSERT_EQ(out.size(), 1u);
      EXPECT_NEAR(angle_deg(out[0].detection.rvec, turning(f)), 0, 1e-9) << "later " << later << " frame " << f;
      EXPECT_NEAR(angle_deg(out[0].detection.alternative_rvec, turning_flip(f)), 0, 1e-9);
      EXPECT_TRUE(out[0].track.flipped);
      EXPECT_NEAR(out[0].detection.ambiguity_ratio, 1 / 1.2, 1e-12);
    }
  }
}

// After a settled start, a run of ambiguous frames whose per-frame choice is the flip in
// every third frame (and a frame with no alternative, and a missed frame, among them):
// the track reports the true pose in every frame, flipping exactly the frames whose
// detector chose the flip.
TEST(Tracker, StaysOnTheTruePoseThroughAmbiguousFrames) {
  Tracker tracker;
  for (int f = 0; f < 30; ++f) {
    std::vector<Detection> found;
    if (f < 3) {
      found.push_back(ambiguous(turning(f), turning_flip(f), 5.0));
    } else if (f == 12) {
      Detection d = ambiguous(turning(f), turning_flip(f), 0);
      d.alternative_reprojection_error = 0;
      found.push_back(d);
    } else if (f != 20) {
      const bool flip = f % 3 == 0;
      found.push_back(flip ? ambiguous(turning_flip(f), turning(f), 1.2) : ambiguous(turning(f), turning_flip(f), 1.4));
    }
    const auto out = tracker.update(f * kFrame, found);
    ASSERT_EQ(out.size(), 1u);
    EXPECT_EQ(out[0].track.state, f == 20 ? TrackState::predicted : TrackState::measured);
    EXPECT_NEAR(angle_deg(out[0].detection.rvec, turning(f)), 0, f == 20 ? 1e-6 : 1e-9) << "frame " << f;
    EXPECT_EQ(out[0].track.flipped, f >= 3 && f != 12 && f != 20 && f % 3 == 0) << "frame " << f;
  }
}

TEST(Tracker, RefusesBadParams) {
  for (auto change : std::vector<void (*)(TrackerParams&)>{
           [](TrackerParams& p) { p.lost_after = -1; }, [](TrackerParams& p) { p.lost_after = NAN; },
           [](TrackerParams& p) { p.min_cutoff = 0; }, [](TrackerParams& p) { p.beta = -0.1; },
           [](TrackerParams& p) { p.derivative_cutoff = 0; }, [](TrackerParams& p) { p.max_ambiguity_ratio = -1; }}) {
    TrackerParams p;
    change(p);
    EXPECT_THROW(Tracker{p}, std::invalid_argument);
  }
}

// ---- the One Euro filter

// Seconds until the filter's output of a unit step (at t = 0, sampled at 30 Hz from a
// steady 0) first reaches `level`.
double step_lag(OneEuroFilter<1>& filter, double level) {
  filter(-kFrame, cv::Vec<double, 1>(0.0));
  for (int f = 0; f < 300; ++f) {
    const double t = f * kFrame;
    if (filter(t, cv::Vec<double, 1>(1.0))[0] >= level) return t;
  }
  return 1e9;
}

// Without the speed term it is an exponential smoother of time constant 1 / (2 pi
// min_cutoff): 0.159 s at 1 Hz to reach 1 - 1/e of a step (here within a frame), 0.37 s to
// 90 %. The speed term shortens the lag, and the output settles on the step.
TEST(OneEuroFilter, LagOnAStep) {
  OneEuroFilter<1> slow(1.0, 0.0, 1.0);
  const double tau = 1 / (2 * CV_PI);
  const double lag63 = step_lag(slow, 1 - std::exp(-1.0));
  EXPECT_GE(lag63, tau - 2 * kFrame);
  EXPECT_LE(lag63, tau + kFrame);
  OneEuroFilter<1> slow90(1.0, 0.0, 1.0);
  const double lag90 = step_lag(slow90, 0.9);
  EXPECT_NEAR(lag90, tau * std::log(10.0), 2 * kFrame);

  OneEuroFilter<1> fast(1.0, 1.0, 1.0);
  EXPECT_LT(step_lag(fast, 0.9), lag90 - 2 * kFrame);

  OneEuroFilter<1> higher(4.0, 0.0, 1.0);  // four times the cutoff, a quarter of the lag
  EXPECT_NEAR(step_lag(higher, 0.9), lag90 / 4, 1.5 * kFrame);

  OneEuroFilter<1> settle(1.0, 0.0, 1.0);
  settle(0, cv::Vec<double, 1>(0.0));
  double y = 0;
  for (int f = 1; f <= 60; ++f) y = settle(f * kFrame, cv::Vec<double, 1>(1.0))[0];
  EXPECT_NEAR(y, 1.0, 2e-3);
}

TEST(OneEuroFilter, SteadyInputPassesAndRestartsOnTimeGoingBack) {
  OneEuroFilter<3> filter(1.0, 0.5, 1.0);
  const cv::Vec3d x(1, 2, 3);
  for (int f = 0; f < 5; ++f) EXPECT_EQ(filter(f * kFrame, x), x);
  EXPECT_EQ(filter(0, cv::Vec3d(5, 5, 5)), cv::Vec3d(5, 5, 5));  // restarted
}

// With smoothing, the track carries the filtered pose and the detection the raw one.
TEST(Tracker, SmoothedPoseBesideTheRaw) {
  TrackerParams params;
  params.smoothing = true;
  params.beta = 0;
  Tracker tracker(params);
  for (int f = 0; f < 10; ++f) tracker.update(f * kFrame, {square(TagId(1), {0, 0})});
  Detection moved = square(TagId(1), {0, 0});
  moved.tvec[2] = 2.0;  // a step of 1 m
  moved.rvec = {0, 0.2, 0};
  const auto out = tracker.update(10 * kFrame, {moved});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].track.smoothed);
  EXPECT_DOUBLE_EQ(out[0].detection.tvec[2], 2.0);
  const double first = out[0].track.smoothed_tvec[2];
  EXPECT_GT(first, 1.0);
  EXPECT_LT(first, 1.3);  // alpha at 1 Hz and 30 fps is 0.17
  EXPECT_GT(angle_deg(out[0].track.smoothed_rvec, {0, 0, 0}), 0.5);
  EXPECT_LT(angle_deg(out[0].track.smoothed_rvec, {0, 0, 0}), 0.3 * 0.2 * 180 / CV_PI);
  double z = first;
  for (int f = 11; f < 60; ++f) z = tracker.update(f * kFrame, {moved})[0].track.smoothed_tvec[2];
  EXPECT_NEAR(z, 2.0, 1e-2);
}

// On rendered frames: a marker moving across the frame, blanked out in one frame, is
// predicted within a pixel of where it is.
TEST(Tracker, RenderedMarkerBlankedForAFrame) {
  SceneParams scene;
  SceneRenderer renderer(scene);
  Detector detector;
  Tracker tracker;
  SceneMarker marker;
  marker.id = TagId(1234);
  marker.tag_size = 0.5;
  marker.rvec = rotation_from_angles(0, 10, 0);
  for (int f = 0; f < 6; ++f) {
    marker.tvec = {-0.6 + 0.05 * f, 0.1, 2.5};
    const MarkerTruth truth = make_truth(scene.camera, marker);
    cv::Mat1b frame = renderer.render({to_target(marker)});
    if (f == 5) frame.setTo(128);
    const auto out = tracker.update(f * kFrame, detector.detect(ImageView(frame)));
    ASSERT_EQ(out.size(), 1u) << "frame " << f;
    EXPECT_EQ(out[0].track.id, 1u);
    EXPECT_EQ(out[0].track.state, f == 5 ? TrackState::predicted : TrackState::measured);
    EXPECT_LT(cv::norm(out[0].detection.center - truth.center), f == 5 ? 1.0 : 0.3) << "frame " << f;
  }
}
