// SPDX-License-Identifier: LGPL-2.1-or-later
// The tracking experiment (issue 27, "Measured"): the video and field experiments' clips,
// frame after frame, with LFTag's tracking off (per-frame detection), on (as lftagdetect
// tracking=true: every frame searched, the tracked markers the search missed looked for
// where predicted, lftag::Tracker over the detections: tracks by family and id,
// constant-velocity prediction of a marker missed in a frame, the pose chosen by the
// track when a frame's pose is ambiguous, and the One Euro filter on the published pose),
// and sparse (full-detection-interval=10: the frames between searches only look for the
// tracked markers), beside AprilTag, which has no tracker and is the reference for jitter
// and frame time. Per system, source (video, field), set (tuning, validation) and
// condition:
// - recall per frame, tracked and sparse, measured and predicted apart; a prediction counts as
//   the marker only when its centre lies within the tolerance a detection is held to
//   (score(): a quarter of the projected edge, at least 2 px), and wrong ids;
// - wrong choices of the planar pose's two solutions (trial.hpp's wrong_choice, flipped);
// - jitter: the clips' markers all move, so jitter is the error of the frame-to-frame
//   change of the pose (measured change against the true change) between consecutive
//   frames that both measured the marker, raw and smoothed;
// - frame times (sparse: all its frames, those between searches apart, and of those the
//   frames whose visible markers were all measured where their tracks predicted them), with their
//   ratio to AprilTag 36h11 decimate 2's in the same run.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>
#include <optional>
#include <tuple>

#include <opencv2/calib3d.hpp>

#include "clip_source.hpp"
#include "csv.hpp"
#include "experiment.hpp"
#include "lftag/tracker.hpp"
#include "lftag_system.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

// The peer whose frame time the ratios are to.
const std::string kPeer = "apriltag-36h11-d2";

// The field clips: as the field experiment's full plan (5 clips of 10 frames per
// condition and set); the quick plan's 2 frames are too few to track, so 4.
constexpr int kFieldClips = 5, kFieldFrames = 10, kQuickFieldClips = 1, kQuickFieldFrames = 4;

double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// How often the sparse mode searches the whole frame (lftagdetect's
// full-detection-interval): every tenth frame, a third of a second at 30 fps.
constexpr int kSparseInterval = 10;

// One frame of an LFTag system, the only place the experiment runs the detector and the
// trackers: per-frame detection (tracking off); tracking on as lftagdetect runs it with
// tracking=true (every frame searched, then the tracked markers the search missed read
// where predicted, then Tracker::update); and the sparse mode of
// full-detection-interval=kSparseInterval (the frames between searches only read the
// tracked markers where predicted).
struct TrackedFrame {
  std::vector<lftag::Detection> detections;   // tracking off
  std::vector<lftag::TrackedMarker> markers;  // tracking on: measured, then predicted
  std::vector<lftag::TrackedMarker> sparse;   // the sparse mode
  bool searched = true;                       // whether the sparse mode searched this frame
  double off_ms = 0, on_ms = 0, sparse_ms = 0;
};

struct Trackers {
  lftag::Tracker on, sparse;
};

std::vector<lftag::TrackedMarker> tracked(lftag::Detector& detector, lftag::Tracker& tracker, const cv::Mat1b& frame,
                                          double t, bool full_search, double& ms) {
  const auto start = std::chrono::steady_clock::now();
  lftag::FrameHints hints;
  hints.expected = tracker.expected(t);
  hints.full_search = full_search || hints.expected.empty();
  std::vector<lftag::TrackedMarker> out = tracker.update(t, detector.detect(lftag::ImageView(frame), hints));
  ms = elapsed_ms(start);
  return out;
}

TrackedFrame track_frame(lftag::Detector& detector, Trackers& trackers, const cv::Mat1b& frame, int f, double t) {
  TrackedFrame out;
  const auto start = std::chrono::steady_clock::now();
  out.detections = detector.detect(lftag::ImageView(frame));
  out.off_ms = elapsed_ms(start);
  out.markers = tracked(detector, trackers.on, frame, t, true, out.on_ms);
  out.searched = f % kSparseInterval == 0 || trackers.sparse.expected(t).empty();
  out.sparse = tracked(detector, trackers.sparse, frame, t, out.searched, out.sparse_ms);
  return out;
}

// The tracker as the element runs it with smoothing on: the default loss time, pose
// choice and One Euro parameters (1 Hz, beta 1).
lftag::TrackerParams tracker_params() {
  lftag::TrackerParams p;
  p.smoothing = true;
  return p;
}

// The pose of one marker in one frame, as each way of reporting it gave it.
struct FramePoses {
  std::optional<Pose> off, tracked, smoothed;
};

// The error of the frame-to-frame change from pose a to pose b against the truth's
// change from ta to tb: rotation (degrees) and translation (metres).
std::pair<double, double> change_error(const Pose& a, const Pose& b, const Pose& ta, const Pose& tb) {
  auto matrix = [](const cv::Vec3d& r) {
    cv::Matx33d m;
    cv::Rodrigues(r, m);
    return m;
  };
  const cv::Matx33d measured = matrix(b.rvec) * matrix(a.rvec).t(), truth = matrix(tb.rvec) * matrix(ta.rvec).t();
  cv::Vec3d diff;
  cv::Rodrigues(measured * truth.t(), diff);
  return {cv::norm(diff) * 180 / CV_PI, cv::norm((b.tvec - a.tvec) - (tb.tvec - ta.tvec))};
}

struct Jitter {
  std::vector<double> rotation_deg, translation_mm, translation_pct;
  void add(const Pose& a, const Pose& b, const Pose& ta, const Pose& tb) {
    const auto [r, t] = change_error(a, b, ta, tb);
    rotation_deg.push_back(r);
    translation_mm.push_back(1000 * t);
    translation_pct.push_back(100 * t / cv::norm(tb.tvec));
  }
  void append(const Jitter& o) {
    rotation_deg.insert(rotation_deg.end(), o.rotation_deg.begin(), o.rotation_deg.end());
    translation_mm.insert(translation_mm.end(), o.translation_mm.begin(), o.translation_mm.end());
    translation_pct.insert(translation_pct.end(), o.translation_pct.begin(), o.translation_pct.end());
  }
};

struct Tally {
  int frames = 0, markers = 0;
  int found_off = 0, found_measured = 0, found_predicted = 0, predicted_off_target = 0;
  int wrong_off = 0, wrong_on = 0;
  int found_sparse = 0, wrong_sparse = 0;  // the sparse mode: measured or predicted on target
  int with_pose_off = 0, wrong_choices_off = 0, flips_off = 0;
  int with_pose_on = 0, wrong_choices_on = 0, flips_on = 0;
  std::vector<double> prediction_error_px;
  Jitter off, tracked, smoothed;
  // The sparse mode's frames between searches; and of those, the frames whose markers
  // were all tracked (each tracked marker measured where predicted, none only predicted).
  std::vector<double> off_ms, on_ms, sparse_ms, unsearched_ms, all_tracked_ms;
  void append(const Tally& o) {
    frames += o.frames, markers += o.markers;
    found_off += o.found_off, found_measured += o.found_measured, found_predicted += o.found_predicted;
    predicted_off_target += o.predicted_off_target, wrong_off += o.wrong_off, wrong_on += o.wrong_on;
    with_pose_off += o.with_pose_off, wrong_choices_off += o.wrong_choices_off, flips_off += o.flips_off;
    with_pose_on += o.with_pose_on, wrong_choices_on += o.wrong_choices_on, flips_on += o.flips_on;
    prediction_error_px.insert(prediction_error_px.end(), o.prediction_error_px.begin(), o.prediction_error_px.end());
    off.append(o.off), tracked.append(o.tracked), smoothed.append(o.smoothed);
    off_ms.insert(off_ms.end(), o.off_ms.begin(), o.off_ms.end());
    on_ms.insert(on_ms.end(), o.on_ms.begin(), o.on_ms.end());
    sparse_ms.insert(sparse_ms.end(), o.sparse_ms.begin(), o.sparse_ms.end());
    unsearched_ms.insert(unsearched_ms.end(), o.unsearched_ms.begin(), o.unsearched_ms.end());
    all_tracked_ms.insert(all_tracked_ms.end(), o.all_tracked_ms.begin(), o.all_tracked_ms.end());
    found_sparse += o.found_sparse, wrong_sparse += o.wrong_sparse;
  }
};

// The first of `detections` that is marker `id` where it is: its id, and its centre
// within `tolerance` of `center` (as score()).
int match(const std::vector<Detected>& detections, const std::string& id, cv::Point2d center, double tolerance) {
  for (std::size_t i = 0; i < detections.size(); ++i)
    if (detections[i].id == id && cv::norm(detections[i].center - center) <= tolerance) return int(i);
  return -1;
}

// Detections that are none of the frame's markers (every marker counts, cut and
// occluded ones too: a detection of them is not wrong).
int wrong_ids(const std::vector<Detected>& detections, const std::vector<std::string>& ids,
              const std::vector<cv::Point2d>& centers, const std::vector<double>& tolerances) {
  int wrong = 0;
  for (const Detected& d : detections) {
    bool matched = false;
    for (std::size_t m = 0; m < ids.size(); ++m)
      matched = matched || (d.id == ids[m] && cv::norm(d.center - centers[m]) <= tolerances[m]);
    wrong += !matched;
  }
  return wrong;
}

// Where frame `f` puts each of the clip's markers (the projected centre) and how near a
// detection must be to count as it (as score()).
void truth_targets(const RenderedClip& clip, int f, std::vector<cv::Point2d>& centers,
                   std::vector<double>& tolerances) {
  for (const Pose& p : clip.poses[std::size_t(f)]) {
    centers.push_back(clip.camera.project({{0, 0, 0}}, p.rvec, p.tvec)[0]);
    tolerances.push_back(std::max(2.0, edge_px(clip.camera, p, clip.tag_size) / 4));
  }
}

// One system over one clip: the tally of its frames.
Tally run_clip(FiducialSystem& system, const RenderedClip& clip, int s) {
  Tally k;
  auto* lftag_system = dynamic_cast<LftagSystem*>(&system);
  std::optional<lftag::Detector> detector;
  std::optional<Trackers> trackers;
  const std::vector<cv::Mat1b>& images = clip.images[std::size_t(s)];
  const std::vector<std::string>& ids = clip.ids[std::size_t(s)];
  // The first call allocates and fills caches: one untimed call on the first frame.
  if (lftag_system) {
    detector.emplace(lftag_system->params_for(clip.camera, clip.tag_size));
    trackers.emplace(Trackers{lftag::Tracker(tracker_params()), lftag::Tracker(tracker_params())});
    detector->detect(lftag::ImageView(images[0]));
  } else {
    system.set_camera(clip.camera, clip.tag_size);
    system.detect(images[0]);
  }
  const std::size_t markers = ids.size();
  std::vector<FramePoses> previous(markers);
  for (int f = 0; f < clip.frames(); ++f) {
    const double t = f / clip.fps;
    std::vector<Detected> off, measured, predicted;
    std::vector<const lftag::TrackedMarker*> measured_tracks;
    if (lftag_system) {
      const TrackedFrame frame = track_frame(*detector, *trackers, images[std::size_t(f)], f, t);
      for (const lftag::Detection& d : frame.detections) off.push_back(to_detected(d));
      for (const lftag::TrackedMarker& m : frame.markers) {
        if (m.track.state == lftag::TrackState::measured)
          measured.push_back(to_detected(m.detection));
        else if (m.track.state == lftag::TrackState::predicted)
          predicted.push_back(to_detected(m.detection));
      }
      for (const lftag::TrackedMarker& m : frame.markers)
        if (m.track.state == lftag::TrackState::measured) measured_tracks.push_back(&m);
      k.off_ms.push_back(frame.off_ms);
      k.on_ms.push_back(frame.on_ms);
      k.sparse_ms.push_back(frame.sparse_ms);
      if (!frame.searched) k.unsearched_ms.push_back(frame.sparse_ms);
      ++k.frames;
      // The measured poses and their smoothed ones, by marker (below).
      std::vector<cv::Point2d> centers;
      std::vector<double> tolerances;
      truth_targets(clip, f, centers, tolerances);
      k.wrong_off += wrong_ids(off, ids, centers, tolerances);
      std::vector<Detected> all_on = measured;
      for (const Detected& d : predicted)
        if (std::find(ids.begin(), ids.end(), d.id) == ids.end()) all_on.push_back(d);  // a track of no marker
      k.wrong_on += wrong_ids(all_on, ids, centers, tolerances);
      // The sparse mode: recall and wrong ids as tracking on's (a prediction counts on target).
      std::vector<Detected> sparse, sparse_predicted;
      for (const lftag::TrackedMarker& m : frame.sparse)
        (m.track.state == lftag::TrackState::measured ? sparse : sparse_predicted).push_back(to_detected(m.detection));
      std::vector<Detected> all_sparse = sparse;
      for (const Detected& d : sparse_predicted)
        if (std::find(ids.begin(), ids.end(), d.id) == ids.end()) all_sparse.push_back(d);  // a track of no marker
      k.wrong_sparse += wrong_ids(all_sparse, ids, centers, tolerances);
      // A frame whose markers are all tracked: every visible marker measured where its
      // track predicted it, and no track only predicted.
      bool all_tracked = !frame.searched && !sparse.empty() && sparse_predicted.empty();
      for (std::size_t m = 0; m < markers && all_tracked; ++m)
        all_tracked = !clip.visible[std::size_t(f)][m] || match(sparse, ids[m], centers[m], tolerances[m]) >= 0;
      if (all_tracked) k.all_tracked_ms.push_back(frame.sparse_ms);
      sparse.insert(sparse.end(), sparse_predicted.begin(), sparse_predicted.end());
      for (std::size_t m = 0; m < markers; ++m)
        k.found_sparse += clip.visible[std::size_t(f)][m] && match(sparse, ids[m], centers[m], tolerances[m]) >= 0;
      for (std::size_t m = 0; m < markers; ++m) {
        const Pose& truth = clip.poses[std::size_t(f)][m];
        FramePoses now;
        const int i = match(off, ids[m], centers[m], tolerances[m]);
        const int j = match(measured, ids[m], centers[m], tolerances[m]);
        if (i >= 0) now.off = off[std::size_t(i)].pose;
        if (j >= 0) {
          now.tracked = measured[std::size_t(j)].pose;
          const lftag::TrackInfo& info = measured_tracks[std::size_t(j)]->track;
          if (info.smoothed) now.smoothed = Pose{info.smoothed_rvec, info.smoothed_tvec};
        }
        if (clip.visible[std::size_t(f)][m]) {
          ++k.markers;
          if (i >= 0) {
            ++k.found_off;
            const Outcome o = score({off[std::size_t(i)]}, ids[m], truth, clip.tag_size, clip.camera);
            k.with_pose_off += std::isfinite(o.rotation_error_deg);
            k.wrong_choices_off += wrong_choice(o), k.flips_off += flipped(o);
          }
          if (j >= 0) {
            ++k.found_measured;
            const Outcome o = score({measured[std::size_t(j)]}, ids[m], truth, clip.tag_size, clip.camera);
            k.with_pose_on += std::isfinite(o.rotation_error_deg);
            k.wrong_choices_on += wrong_choice(o), k.flips_on += flipped(o);
          } else {
            const auto p =
                std::find_if(predicted.begin(), predicted.end(), [&](const Detected& d) { return d.id == ids[m]; });
            if (p != predicted.end()) {
              const double error = cv::norm(p->center - centers[m]);
              k.prediction_error_px.push_back(error);
              (error <= tolerances[m] ? k.found_predicted : k.predicted_off_target) += 1;
            }
          }
        }
        if (f > 0) {
          const Pose& before = clip.poses[std::size_t(f - 1)][m];
          if (previous[m].off && now.off) k.off.add(*previous[m].off, *now.off, before, truth);
          if (previous[m].tracked && now.tracked) k.tracked.add(*previous[m].tracked, *now.tracked, before, truth);
          if (previous[m].smoothed && now.smoothed) k.smoothed.add(*previous[m].smoothed, *now.smoothed, before, truth);
        }
        previous[m] = now;
      }
    } else {
      const auto start = std::chrono::steady_clock::now();
      off = system.detect(images[std::size_t(f)]);
      k.off_ms.push_back(elapsed_ms(start));
      ++k.frames;
      std::vector<cv::Point2d> centers;
      std::vector<double> tolerances;
      truth_targets(clip, f, centers, tolerances);
      k.wrong_off += wrong_ids(off, ids, centers, tolerances);
      for (std::size_t m = 0; m < markers; ++m) {
        const Pose& truth = clip.poses[std::size_t(f)][m];
        FramePoses now;
        const int i = match(off, ids[m], centers[m], tolerances[m]);
        if (i >= 0) now.off = off[std::size_t(i)].pose;
        if (clip.visible[std::size_t(f)][m]) {
          ++k.markers;
          if (i >= 0) {
            ++k.found_off;
            const Outcome o = score({off[std::size_t(i)]}, ids[m], truth, clip.tag_size, clip.camera);
            k.with_pose_off += std::isfinite(o.rotation_error_deg);
            k.wrong_choices_off += wrong_choice(o), k.flips_off += flipped(o);
          }
        }
        if (f > 0 && previous[m].off && now.off)
          k.off.add(*previous[m].off, *now.off, clip.poses[std::size_t(f - 1)][m], truth);
        previous[m] = now;
      }
    }
  }
  return k;
}

double mean(const std::vector<double>& v) {
  return v.empty() ? kNaN : std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
}
double percent(int part, int whole) { return whole > 0 ? 100.0 * part / whole : kNaN; }

}  // namespace

bool run_tracking(const Options& options) {
  // LFTag systems and the peer; the others have nothing this experiment adds to theirs.
  std::vector<std::string> names;
  for (const std::string& name : options.systems)
    if (name.rfind("lftag-", 0) == 0 || name == kPeer)
      names.push_back(name);
    else
      progress("tracking: " + name + " left out (LFTag systems and " + kPeer + " only)");
  if (names.empty()) throw std::invalid_argument("tracking: no LFTag system or " + kPeer + " selected");
  const int n = int(names.size());
  const int threads = std::max(1, options.threads);
  std::vector<std::vector<std::unique_ptr<FiducialSystem>>> workers(threads);
  for (auto& w : workers)
    for (const std::string& name : names) w.push_back(make_system(name));

  // [system][(source, set, condition)]
  using Key = std::tuple<std::string, std::string, std::string>;
  std::vector<std::map<Key, Tally>> tallies(n);
  const std::pair<const char*, std::unique_ptr<ClipSource>> sources[] = {
      {"video", video_clips(options)},
      {"field", options.quick ? field_clips(options, kQuickFieldClips, kQuickFieldFrames)
                              : field_clips(options, kFieldClips, kFieldFrames)}};
  for (const auto& named : sources) {
    // Not a structured binding: C++17 lets no lambda capture one (clang refuses).
    const std::string source_label = named.first;
    ClipSource* const source = named.second.get();
    // A batch of clips rendered on every worker, then tracked and timed on this thread
    // alone, as the field experiment times its frames: a frame timed beside another
    // worker's rendering (H.264 coding runs threads of its own) is slowed by it.
    for (int first = 0; first < source->size(); first += threads) {
      const int count = std::min(threads, source->size() - first);
      std::vector<RenderedClip> batch(static_cast<std::size_t>(count));
      parallel_for(count, threads, [&](int k, int worker) {
        batch[std::size_t(k)] = source->render(first + k, workers[std::size_t(worker)]);
      });
      for (const RenderedClip& clip : batch)
        for (int s = 0; s < n; ++s) {
          const Tally tally = run_clip(*workers[0][std::size_t(s)], clip, s);
          tallies[s][{source_label, clip.set, "all"}].append(tally);
          if (source_label == "field") tallies[s][{source_label, clip.set, clip.condition}].append(tally);
        }
      const int done = first + count;
      if (done % 10 < count || done == source->size())
        progress("tracking: " + source_label + " " + std::to_string(done) + " / " + std::to_string(source->size()) +
                 " clips");
    }
  }

  Csv summary(options.out / "tracking_summary.csv", {"system",
                                                     "family",
                                                     "source",
                                                     "set",
                                                     "condition",
                                                     "frames",
                                                     "markers",
                                                     "found_per_frame",
                                                     "recall_per_frame_pct",
                                                     "found_measured",
                                                     "found_predicted",
                                                     "recall_tracked_pct",
                                                     "predicted_off_target",
                                                     "median_prediction_error_px",
                                                     "wrong_per_frame",
                                                     "wrong_tracked",
                                                     "with_pose_off",
                                                     "wrong_choices_off",
                                                     "flips_off",
                                                     "wrong_choice_off_pct",
                                                     "with_pose_on",
                                                     "wrong_choices_on",
                                                     "flips_on",
                                                     "wrong_choice_on_pct",
                                                     "found_sparse",
                                                     "recall_sparse_pct",
                                                     "wrong_sparse"});
  Csv jitter(options.out / "tracking_jitter.csv",
             {"system", "family", "source", "set", "pose", "pairs", "mean_rotation_deg", "p95_rotation_deg",
              "p99_rotation_deg", "mean_translation_mm", "p95_translation_mm", "p99_translation_mm",
              "mean_translation_pct", "p95_translation_pct", "p99_translation_pct"});
  Csv times(options.out / "tracking_times.csv", {"system", "family", "source", "set", "tracking", "frames", "mean_ms",
                                                 "p99_ms", "mean_over_peer", "p99_over_peer"});
  const auto peer = std::find(names.begin(), names.end(), kPeer);
  for (int s = 0; s < n; ++s) {
    const std::string family = workers[0][std::size_t(s)]->family();
    const bool tracks = names[std::size_t(s)].rfind("lftag-", 0) == 0;
    for (const auto& entry : tallies[s]) {
      const Key& key = entry.first;
      const Tally& k = entry.second;
      const std::string &source = std::get<0>(key), &set = std::get<1>(key), &condition = std::get<2>(key);
      summary.row(names[s], family, source, set, condition, k.frames, k.markers, k.found_off,
                  percent(k.found_off, k.markers), tracks ? k.found_measured : kNaN, tracks ? k.found_predicted : kNaN,
                  tracks ? percent(k.found_measured + k.found_predicted, k.markers) : kNaN,
                  tracks ? k.predicted_off_target : kNaN, quantile(k.prediction_error_px, 0.5), k.wrong_off,
                  tracks ? k.wrong_on : kNaN, k.with_pose_off, k.wrong_choices_off, k.flips_off,
                  percent(k.wrong_choices_off, k.with_pose_off), tracks ? k.with_pose_on : kNaN,
                  tracks ? k.wrong_choices_on : kNaN, tracks ? k.flips_on : kNaN,
                  tracks ? percent(k.wrong_choices_on, k.with_pose_on) : kNaN, tracks ? k.found_sparse : kNaN,
                  tracks ? percent(k.found_sparse, k.markers) : kNaN, tracks ? k.wrong_sparse : kNaN);
      if (condition != "all") continue;
      auto jitter_row = [&](const char* pose, const Jitter& j) {
        jitter.row(names[s], family, source, set, pose, int(j.rotation_deg.size()), mean(j.rotation_deg),
                   quantile(j.rotation_deg, 0.95), quantile(j.rotation_deg, 0.99), mean(j.translation_mm),
                   quantile(j.translation_mm, 0.95), quantile(j.translation_mm, 0.99), mean(j.translation_pct),
                   quantile(j.translation_pct, 0.95), quantile(j.translation_pct, 0.99));
      };
      jitter_row("raw", k.off);
      if (tracks) jitter_row("tracked", k.tracked), jitter_row("smoothed", k.smoothed);
      // The peer's times in the same source and set.
      double peer_mean = kNaN, peer_p99 = kNaN;
      if (peer != names.end()) {
        const auto found = tallies[std::size_t(peer - names.begin())].find(key);
        if (found != tallies[std::size_t(peer - names.begin())].end())
          peer_mean = mean(found->second.off_ms), peer_p99 = quantile(found->second.off_ms, 0.99);
      }
      auto times_row = [&](const char* tracking, const std::vector<double>& v) {
        times.row(names[s], family, source, set, tracking, int(v.size()), mean(v), quantile(v, 0.99),
                  mean(v) / peer_mean, quantile(v, 0.99) / peer_p99);
      };
      times_row(tracks ? "off" : "none", k.off_ms);
      if (tracks)
        times_row("on", k.on_ms), times_row("sparse", k.sparse_ms), times_row("between-searches", k.unsearched_ms),
            times_row("all-tracked", k.all_tracked_ms);
    }
  }
  return true;
}

}  // namespace bench
