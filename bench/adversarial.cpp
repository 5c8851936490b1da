// SPDX-License-Identifier: LGPL-2.1-or-later
// Adversarial frames (issue 11): regular grids of small white squares each holding dark
// dots (tiles, a perforated sheet, a window facade) make thousands of candidates that
// pass the paper's constraints, and a frame that costs a hundred times an ordinary one
// stalls a live pipeline. Each grid variant is rendered at 1280x720 behind real markers
// of several families, and timed against an ordinary frame (the same markers on a photo)
// in the same run: per variant, the median time, its ratio to the ordinary frame's, the
// candidates, those skipped by the per-frame budget, and whether every real marker was
// found.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>

#include <opencv2/imgcodecs.hpp>

#include "csv.hpp"
#include "experiment.hpp"
#include "sources.hpp"
#include "trial.hpp"

#include "lftag/detector.hpp"

namespace bench {
namespace {

const cv::Size kSize{1280, 720};
constexpr double kTagSize = 0.1;    // metres
constexpr double kGridDepth = 3.0;  // metres: behind every marker

// A grid of tiles seen by the camera. `dots` x `dots` dots per tile; `inverted` swaps ink
// and paper (black squares holding white dots, on white). A tile is drawn in cells: a
// 2-cell margin, 2-cell dots 2 cells apart, a 2-cell margin, then 2 cells of grout: a
// pitch of 4 * dots + 4 cells, `pitch_px` pixels where the plane meets the optical axis.
struct Variant {
  std::string name;
  int dots = 0;  // 0: the ordinary frame (no grid, a photo behind the markers)
  bool inverted = false;
  double pitch_px = 0;
  double tilt_deg = 0, pan_deg = 0;  // of the grid's plane
};

const std::vector<Variant> kVariants{
    {"ordinary", 0},
    {"white-4-10px", 2, false, 10},  // the reproducer: 128 x 72 tiles of 4 dots
    {"white-4-16px", 2, false, 16},
    {"white-4-24px", 2, false, 24},
    {"white-9-16px", 3, false, 16},
    {"white-9-24px", 3, false, 24},
    {"white-16-20px", 4, false, 20},
    {"black-4-16px", 2, true, 16},
    {"black-9-24px", 3, true, 24},
    {"white-4-12px-tilted", 2, false, 12, 25, 15},
    {"white-9-20px-tilted", 3, false, 20, -20, 25},
};

// The families of the real markers in every frame, and the detector configurations.
const std::vector<int> kMarkerFamilies{2, 3, 4, 5, 6, 8};

struct Config {
  std::string name;
  std::string families;
  bool budget;  // the default budget, or none
};
const std::vector<Config> kConfigs{
    {"all", "2x2,3x3,4x4,5x5,6x6,7x7,8x8", true},
    {"default", "3x3,4x4", true},
    {"all-no-budget", "2x2,3x3,4x4,5x5,6x6,7x7,8x8", false},
};

struct Plan {
  int frames;  // per variant: marker placements
  int runs;    // timed runs of each frame
};
constexpr Plan kFull{3, 7}, kQuick{1, 1};

// The quick mode: the ordinary frame and two walls, without the (slow) unbudgeted set-up.
bool in_quick(const std::string& name) {
  return name == "ordinary" || name == "white-4-10px" || name == "white-9-16px" || name == "all" || name == "default";
}

struct Truth {
  lftag::Family family{3};
  lftag::TagId id;
  cv::Point2d center;
  double edge = 0;
};

struct Frame {
  cv::Mat1b image;
  std::vector<Truth> markers;
};

cv::Mat1f tile_albedo(const Variant& v, cv::Size cells) {
  const float ink = 0.08f, paper = 0.85f;
  const int pitch = 4 * v.dots + 4, side = pitch - 2;
  cv::Mat1f tile(pitch, pitch, v.inverted ? paper : ink);  // grout
  tile(cv::Rect(0, 0, side, side)).setTo(v.inverted ? ink : paper);
  for (int r = 0; r < v.dots; ++r)
    for (int c = 0; c < v.dots; ++c) tile(cv::Rect(2 + 4 * c, 2 + 4 * r, 2, 2)).setTo(v.inverted ? paper : ink);
  cv::Mat1f albedo(cells);
  for (int y = 0; y < cells.height; ++y)
    for (int x = 0; x < cells.width; ++x) albedo(y, x) = tile(y % pitch, x % pitch);
  return albedo;
}

Frame make_frame(const Variant& v, const std::vector<Source>& photos, int index, std::uint64_t seed) {
  std::mt19937_64 rng = seeded(seed, {0xad5e, std::uint64_t(index)});
  std::uniform_real_distribution<double> unit(0, 1);
  lftag::SceneParams params;
  params.camera = lftag::Camera::default_for(kSize.width, kSize.height);
  std::vector<lftag::SceneTarget> targets;
  if (v.dots == 0) {
    params.photo = cv::imread(photos[std::size_t(index) % photos.size()].path.string(), cv::IMREAD_GRAYSCALE);
  } else {
    // The plane covers the frame with room for its tilt.
    const int pitch_cells = 4 * v.dots + 4;
    lftag::SceneTarget grid;
    grid.cell_size = v.pitch_px / pitch_cells * kGridDepth / params.camera.fx;
    const double extent = 1.8 / params.camera.fx * kGridDepth / grid.cell_size;  // cells per frame pixel, with room
    grid.albedo = tile_albedo(v, cv::Size(int(kSize.width * extent), int(kSize.height * extent)));
    grid.rvec = lftag::rotation_from_angles(0, v.tilt_deg, v.pan_deg);
    grid.tvec = {0, 0, kGridDepth};
    targets.push_back(grid);
  }
  // One marker of each family in its own cell of a 3 x 2 layout, 70 to 140 px across,
  // turned at random and tilted by up to 30 degrees.
  Frame frame;
  const double cell_w = kSize.width / 3.0, cell_h = kSize.height / 2.0;
  for (std::size_t k = 0; k < kMarkerFamilies.size(); ++k) {
    lftag::SceneMarker m;
    m.family = lftag::Family(kMarkerFamilies[k]);
    for (int d = 0; d < m.family.data_cell_count(); ++d) m.id = m.id.with_digit(d, int(rng() % 4));
    m.tag_size = kTagSize;
    const double edge = 70 + 70 * unit(rng);
    const cv::Point2d center((k % 3 + 0.3 + 0.4 * unit(rng)) * cell_w, (k / 3 + 0.3 + 0.4 * unit(rng)) * cell_h);
    const cv::Vec3d rvec = lftag::rotation_from_angles(360 * unit(rng), 60 * unit(rng) - 30, 60 * unit(rng) - 30);
    const Pose pose = place(params.camera, center, params.camera.fx * kTagSize / edge, rvec);
    m.rvec = pose.rvec, m.tvec = pose.tvec;
    targets.push_back(lftag::to_target(m));
    const lftag::MarkerTruth t = lftag::make_truth(params.camera, m);
    frame.markers.push_back({m.family, m.id, t.center, t.edge_px});
  }
  frame.image = lftag::SceneRenderer(params).render(targets);
  return frame;
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

struct Result {
  std::vector<double> times;
  lftag::DetectionStats stats;  // of the first run of every frame
  int markers = 0, found = 0, wrong = 0;
};

}  // namespace

bool run_adversarial(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  std::vector<Source> photos;
  for (const Source& s : list_sources(options.data))
    if (!s.video) photos.push_back(s);

  std::vector<Variant> variants;
  for (const Variant& v : kVariants)
    if (!options.quick || in_quick(v.name)) variants.push_back(v);
  std::map<std::string, std::vector<Frame>> frames;
  for (const Variant& v : variants) {
    progress("adversarial: rendering " + v.name);
    for (int f = 0; f < plan.frames; ++f) frames[v.name].push_back(make_frame(v, photos, f, options.seed));
  }

  Csv csv(options.out / "adversarial.csv",
          {"config", "families", "budget", "variant", "frames", "runs", "median_ms", "q1_ms", "q3_ms", "ratio",
           "candidates", "examined", "skipped_by_budget", "second_looks", "second_looks_skipped",
           "markers", "found", "all_found", "wrong", "candidates_ms", "decoding_ms", "second_look_ms"});
  bool first = true;
  for (const Config& config : kConfigs) {
    if (options.quick && !in_quick(config.name)) continue;
    lftag::DetectorParams params;
    params.families = lftag::Family::parse_list(config.families);
    params.camera = lftag::Camera::default_for(kSize.width, kSize.height);
    params.tag_size = kTagSize;
    if (!config.budget) params.max_candidates = 0;
    lftag::Detector detector(params);
    detector.detect(lftag::ImageView(frames["ordinary"][0].image));  // warm-up

    std::map<std::string, Result> results;
    // Runs interleave the variants, so that a busy moment of the machine does not fall
    // on one variant alone.
    for (int run = 0; run < plan.runs; ++run)
      for (const Variant& v : variants)
        for (const Frame& frame : frames[v.name]) {
          Result& r = results[v.name];
          lftag::DetectionStats stats;
          const auto start = std::chrono::steady_clock::now();
          const std::vector<lftag::Detection> found = detector.detect(lftag::ImageView(frame.image), &stats);
          r.times.push_back(elapsed_ms(start));
          if (run > 0) continue;
          r.stats += stats;
          std::vector<bool> used(found.size());
          for (const Truth& t : frame.markers) {
            if (!std::count(params.families.begin(), params.families.end(), t.family)) continue;
            ++r.markers;
            for (std::size_t i = 0; i < found.size(); ++i)
              if (!used[i] && found[i].family == t.family && found[i].id == t.id &&
                  cv::norm(found[i].center - t.center) < std::max(2.0, t.edge / 4)) {
                used[i] = true;
                ++r.found;
                break;
              }
          }
          r.wrong += int(std::count(used.begin(), used.end(), false));
        }

    const double ordinary = quantile(results["ordinary"].times, 0.5);
    if (first) std::printf("%-14s %-22s %9s %7s %10s %9s %8s %7s\n", "config", "variant", "median_ms", "ratio",
                           "candidates", "examined", "skipped", "found");
    first = false;
    for (const Variant& v : variants) {
      const Result& r = results[v.name];
      const lftag::DetectionStats& s = r.stats;
      const double n = double(std::max<std::int64_t>(1, s.frames));
      const double median = quantile(r.times, 0.5);
      const double examined = double(s.topology - s.skipped_by_budget);
      csv.row(config.name, config.families, config.budget ? "default" : "none", v.name, int(frames[v.name].size()),
              plan.runs, median, quantile(r.times, 0.25), quantile(r.times, 0.75), median / ordinary,
              double(s.topology) / n, examined / n, double(s.skipped_by_budget) / n, double(s.second_looks) / n,
              double(s.second_looks_skipped) / n, r.markers, r.found, int(r.found == r.markers), r.wrong,
              s.candidates_ms / n, (s.keypoints_ms + s.hypotheses_ms + s.decode_ms + s.pose_ms) / n,
              s.second_look_ms / n);
      std::printf("%-14s %-22s %9.2f %7.2f %10.0f %9.0f %8.0f %4d/%-2d\n", config.name.c_str(), v.name.c_str(), median,
                  median / ordinary, double(s.topology) / n, examined / n, double(s.skipped_by_budget) / n, r.found,
                  r.markers);
    }
    std::fflush(stdout);
  }
  return true;
}

}  // namespace bench
