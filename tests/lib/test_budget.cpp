// SPDX-License-Identifier: LGPL-2.1-or-later
// The per-frame budget (DetectorParams::max_candidates) and the early rejections that keep
// frames full of marker look-alikes cheap: grids of white tiles holding dark dots make
// thousands of candidates. Counts only: no assertion on time.
#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "lftag/detector.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"
#include "scenes.hpp"

using namespace lftag;
using lftag::test::random_id;
using lftag::test::rotation;

namespace {

const std::string kPhotos = "/usr/share/doc/opencv-doc/examples/data/";
const Camera kCamera = Camera::pinhole(1280, 1280, 639.5, 359.5, 1280, 720);

// A wall of tiles 3 m away, filling the frame: each tile a white square holding `dots` x
// `dots` dark dots, `pitch_px` pixels from one tile to the next, on dark grout.
SceneTarget tiled_wall(int dots, double pitch_px, double tilt_deg = 0) {
  const int pitch = 4 * dots + 4, side = pitch - 2;  // cells: 2-cell margins, dots and gaps
  cv::Mat1f tile(pitch, pitch, 0.08f);
  tile(cv::Rect(0, 0, side, side)).setTo(0.85f);
  for (int r = 0; r < dots; ++r)
    for (int c = 0; c < dots; ++c) tile(cv::Rect(2 + 4 * c, 2 + 4 * r, 2, 2)).setTo(0.08f);
  SceneTarget wall;
  const double depth = 3.0, pixels_per_cell = pitch_px / pitch;
  wall.cell_size = pixels_per_cell * depth / kCamera.fx;
  const int cols = int(1.6 * 1280 / pixels_per_cell), rows = int(1.6 * 720 / pixels_per_cell);
  wall.albedo.create(rows, cols);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) wall.albedo(y, x) = tile(y % pitch, x % pitch);
  wall.rvec = rotation(0, tilt_deg, 0);
  wall.tvec = {0, 0, depth};
  return wall;
}

// Markers of `families` spread over the frame, 80 to 130 px across, in front of `targets`.
struct Frame {
  cv::Mat1b image;
  std::vector<SceneMarker> markers;
};
Frame frame_with_markers(std::vector<SceneTarget> targets, const std::vector<int>& families, std::uint64_t seed,
                         const cv::Mat& photo = {}) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  SceneParams p;
  p.camera = kCamera;
  p.supersample = 4;
  p.photo = photo;
  Frame frame;
  for (std::size_t i = 0; i < families.size(); ++i) {
    SceneMarker m;
    m.family = Family(families[i]);
    m.id = random_id(m.family, rng);
    m.tag_size = 0.1;
    const double edge = 80 + 50 * u(rng), z = kCamera.fx * m.tag_size / edge;
    const double x = (i % 3 + 0.35 + 0.3 * u(rng)) * 1280 / 3, y = (i / 3 % 2 + 0.35 + 0.3 * u(rng)) * 720 / 2;
    m.tvec = {(x - kCamera.cx) / kCamera.fx * z, (y - kCamera.cy) / kCamera.fy * z, z};
    m.rvec = rotation(360 * u(rng), 50 * u(rng) - 25, 50 * u(rng) - 25);
    frame.markers.push_back(m);
    targets.push_back(to_target(m));
  }
  frame.image = SceneRenderer(p).render(targets);
  return frame;
}

DetectorParams all_families(int max_candidates = DetectorParams{}.max_candidates) {
  DetectorParams p;
  p.families = Family::all();
  p.camera = kCamera;
  p.max_candidates = max_candidates;
  return p;
}

int found_of(const std::vector<Detection>& found, const std::vector<SceneMarker>& markers) {
  int right = 0;
  for (const SceneMarker& m : markers)
    right += std::any_of(found.begin(), found.end(),
                         [&](const Detection& d) { return d.family == m.family && d.id == m.id; });
  return right;
}

}  // namespace

TEST(Budget, SkipsTheCandidatesOverTheBudgetAndCountsThem) {
  // 16 px tiles of four dots: about 4,000 2x2 candidates.
  const Frame frame = frame_with_markers({tiled_wall(2, 16)}, {3}, 1);
  DetectionStats open_stats;
  Detector open(all_families(0));
  open.detect(ImageView(frame.image), &open_stats);
  ASSERT_GT(open_stats.topology, 2000) << "the wall no longer makes candidates";
  EXPECT_EQ(open_stats.skipped_by_budget, 0);

  for (int budget : {1, 40, 200}) {
    Detector detector(all_families(budget));
    DetectionStats stats;
    DetectionTrace trace;
    detector.detect(ImageView(frame.image), &stats, &trace);
    EXPECT_EQ(stats.topology, open_stats.topology) << budget;
    EXPECT_EQ(stats.skipped_by_budget, stats.topology - budget) << budget;
    EXPECT_EQ(stats.second_looks, 0) << "no second look once the budget is spent";
    // Every candidate has its verdict, the skipped ones "budget".
    EXPECT_EQ(std::int64_t(trace.verdicts.size()), stats.topology);
    EXPECT_EQ(std::count_if(trace.verdicts.begin(), trace.verdicts.end(),
                            [](const CandidateVerdict& v) { return v.stage == Stage::budget; }),
              stats.skipped_by_budget);
    // Summed over frames like the other counters.
    DetectionStats sum;
    sum += stats;
    sum += stats;
    EXPECT_EQ(sum.skipped_by_budget, 2 * stats.skipped_by_budget);
  }
  EXPECT_STREQ(stage_name(Stage::budget), "budget");
}

TEST(Budget, RealMarkersInATiledWallAreStillFound) {
  // Markers of six families in front of walls of 4, 9 and 16 dots a tile, face-on and
  // tilted: the budget cuts the frame, and every marker is examined first and found.
  struct Wall {
    int dots;
    double pitch, tilt;
  };
  Detector detector(all_families());
  int seed = 10;
  for (const Wall& w : {Wall{2, 10, 0}, Wall{2, 16, 20}, Wall{3, 16, 0}, Wall{4, 20, -15}}) {
    const Frame frame = frame_with_markers({tiled_wall(w.dots, w.pitch, w.tilt)}, {2, 3, 4, 5, 6, 8}, ++seed);
    DetectionStats stats;
    const std::vector<Detection> found = detector.detect(ImageView(frame.image), &stats);
    const std::string what = std::to_string(w.dots * w.dots) + " dots, " + std::to_string(int(w.pitch)) + " px";
    EXPECT_EQ(found_of(found, frame.markers), 6) << what;
    EXPECT_EQ(found.size(), 6u) << what;
    EXPECT_GT(stats.skipped_by_budget, 0) << what << ": the wall no longer exceeds the budget";
    EXPECT_EQ(stats.topology - stats.skipped_by_budget, detector.params().max_candidates) << what;
  }
}

TEST(Budget, TheDefaultNeverCutsAnOrdinaryScene) {
  // Markers on photos, a sheet of 48 markers, and the photos themselves: nothing skipped,
  // and the same detections as without a budget.
  auto check = [&](const cv::Mat1b& image, const std::string& what) {
    // The default camera of the image's size.
    DetectorParams with = all_families(), without = all_families(0);
    with.camera = without.camera = std::nullopt;
    Detector detector(with), open(without);
    DetectionStats stats, open_stats;
    const std::vector<Detection> found = detector.detect(ImageView(image), &stats);
    const std::vector<Detection> all = open.detect(ImageView(image), &open_stats);
    EXPECT_EQ(stats.skipped_by_budget, 0) << what;
    EXPECT_EQ(stats.second_looks_skipped, 0) << what;
    EXPECT_LE(stats.topology, with.max_candidates / 2) << what;  // well within it
    EXPECT_EQ(found.size(), all.size()) << what;
    for (std::size_t i = 0; i < std::min(found.size(), all.size()); ++i) EXPECT_EQ(found[i].id, all[i].id) << what;
    return found;
  };
  int seed = 100;
  for (const char* name : {"building.jpg", "board.jpg", "fruits.jpg", "left01.jpg", "chessboard.png"}) {
    const cv::Mat photo = cv::imread(kPhotos + name, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(photo.empty()) << name;
    check(photo, name);
    const Frame frame = frame_with_markers({}, {2, 3, 4, 5, 6, 8}, ++seed, photo);
    EXPECT_EQ(found_of(check(frame.image, std::string("markers on ") + name), frame.markers), 6) << name;
  }
  // A printed sheet: 8 x 6 markers of 3x3, 60 px apart.
  SceneParams p;
  p.camera = kCamera;
  p.supersample = 4;
  std::vector<SceneMarker> sheet;
  std::mt19937_64 rng(7);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 8; ++c) {
      SceneMarker m;
      m.id = random_id(m.family, rng);
      m.tag_size = 0.04;
      m.tvec = {(c - 3.5) * 0.06, (r - 2.5) * 0.06, 0.8};
      m.rvec = rotation(0, 10, 0);
      sheet.push_back(m);
    }
  const RenderedScene scene = render_scene(p, sheet);
  EXPECT_EQ(found_of(check(scene.image, "sheet of 48"), sheet), 48);
}

namespace {

// A near 3x3 marker (id 1234) the frame's own candidates find and a far one (4321) that
// only a second look finds, in the paper's camera, with the detector's parameters for it.
struct NearAndFar {
  RenderedScene scene;
  DetectorParams params;
};
NearAndFar near_and_far() {
  SceneParams p;
  p.camera = lftag::test::paper_camera();
  SceneMarker near, far;
  near.id = 1234;
  near.tvec = {-1.0, 0, 8};
  far.id = 4321;
  far.margin_units = 6;
  far.tvec = {1.5, 0.3, 22};
  NearAndFar out{render_scene(p, {near, far}), {}};
  out.params.families = {Family(3)};
  out.params.camera = p.camera;
  out.params.tag_size = 1.0;
  return out;
}

}  // namespace

TEST(Budget, TheSecondLookSharesTheBudget) {
  // The near marker takes the frame's only candidate; the far one is then not looked
  // for, and the skipped look is counted.
  const auto [scene, initial] = near_and_far();
  DetectorParams params = initial;
  DetectionStats stats;
  const std::vector<Detection> all = Detector(params).detect(ImageView(scene.image), &stats);
  ASSERT_EQ(all.size(), 2u) << "the set-up no longer needs a second look";
  ASSERT_GT(stats.second_look_found, 0);
  EXPECT_EQ(stats.second_looks_skipped, 0);

  params.max_candidates = 1;
  DetectionStats cut;
  const std::vector<Detection> one = Detector(params).detect(ImageView(scene.image), &cut);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_EQ(one[0].id, TagId(1234));
  EXPECT_EQ(cut.second_looks, 0);
  EXPECT_GT(cut.second_looks_skipped, 0);

  // max_second_looks cuts are counted as well.
  params.max_candidates = 0;
  params.max_second_looks = 0;
  DetectionStats none;
  Detector(params).detect(ImageView(scene.image), &none);
  EXPECT_EQ(none.second_looks, 0);
  EXPECT_EQ(none.second_looks_skipped, stats.second_looks);
}

TEST(Budget, ParameterIsValidated) {
  DetectorParams p;
  EXPECT_EQ(p.max_candidates, 128);
  p.max_candidates = -1;
  EXPECT_THROW(Detector{p}, std::invalid_argument);
  p.max_candidates = 0;
  EXPECT_NO_THROW(Detector{p});
}

TEST(Deadline, CutsTheSecondLooksAndNeverAddsADetection) {
  // The near marker found in the frame, the far one only a second look finds.
  const auto [scene, initial] = near_and_far();
  DetectorParams params = initial;
  DetectionStats open_stats;
  const std::vector<Detection> all = Detector(params).detect(ImageView(scene.image), &open_stats);
  ASSERT_EQ(all.size(), 2u) << "the set-up no longer needs a second look";
  ASSERT_GT(open_stats.second_looks, 0);
  EXPECT_EQ(open_stats.past_deadline, 0);
  EXPECT_EQ(open_stats.skipped_by_deadline, 0);
  const auto same_place = [](const Detection& a, const Detection& b) {
    return a.family == b.family && a.id == b.id && cv::norm(a.center - b.center) < 1e-9;
  };

  // A deadline spent before the second look: the frame's own candidate is still examined
  // and found, nothing of the second look runs, and the frame says it was cut.
  params.deadline_ms = 1e-3;
  DetectionStats stats;
  const std::vector<Detection> cut = Detector(params).detect(ImageView(scene.image), &stats);
  ASSERT_EQ(cut.size(), 1u);
  EXPECT_EQ(cut[0].id, TagId(1234));
  EXPECT_EQ(stats.past_deadline, 1);
  EXPECT_EQ(stats.second_looks + stats.outline_reads, 0);
  EXPECT_LT(stats.topology, open_stats.topology);  // the second look's candidates were not made
  EXPECT_STREQ(stage_name(Stage::deadline), "deadline");

  // Cut anywhere (half the frame's time without a deadline), it finds only what the
  // unbounded detection finds, where it finds it.
  params.deadline_ms = open_stats.total_ms() / 2;
  for (const Detection& d : Detector(params).detect(ImageView(scene.image)))
    EXPECT_TRUE(std::any_of(all.begin(), all.end(), [&](const Detection& a) { return same_place(a, d); }))
        << d.family.name() << " " << d.id.to_decimal();

  // A deadline never reached changes nothing.
  params.deadline_ms = 1e6;
  DetectionStats late;
  const std::vector<Detection> same = Detector(params).detect(ImageView(scene.image), &late);
  ASSERT_EQ(same.size(), all.size());
  for (std::size_t i = 0; i < all.size(); ++i) EXPECT_TRUE(same_place(same[i], all[i])) << i;
  EXPECT_EQ(late.past_deadline, 0);
  // Summed over frames like the other counters.
  DetectionStats sum;
  sum += stats;
  sum += stats;
  EXPECT_EQ(sum.past_deadline, 2);
}

TEST(Deadline, NeverCutsTheFramesOwnCandidates) {
  // Markers of four families before a wall of nine-dot tiles (about 3,000 candidates, 128
  // examined): with a deadline spent before the first candidate, every candidate the
  // budget allows is still examined, and every marker found.
  const Frame frame = frame_with_markers({tiled_wall(3, 16)}, {3, 4, 6, 8}, 21);
  DetectorParams params = all_families();
  params.deadline_ms = 1e-3;
  DetectionStats stats;
  DetectionTrace trace;
  const std::vector<Detection> found = Detector(params).detect(ImageView(frame.image), &stats, &trace);
  EXPECT_EQ(found_of(found, frame.markers), 4);
  EXPECT_EQ(stats.topology - stats.skipped_by_budget, params.max_candidates);
  EXPECT_EQ(std::count_if(trace.verdicts.begin(), trace.verdicts.end(),
                          [](const CandidateVerdict& v) { return v.stage == Stage::deadline; }),
            0);
}

TEST(Deadline, ParameterIsValidated) {
  DetectorParams p;
  EXPECT_EQ(p.deadline_ms, 0);  // a library call does all its work
  EXPECT_EQ(kLiveDeadlineMs, 20);
  for (double bad : {-1.0, std::nan(""), HUGE_VAL, 1e8}) {
    p.deadline_ms = bad;
    EXPECT_THROW(Detector{p}, std::invalid_argument) << bad;
  }
  p.deadline_ms = kLiveDeadlineMs;
  EXPECT_NO_THROW(Detector{p});
}
