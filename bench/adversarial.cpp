// SPDX-License-Identifier: LGPL-2.1-or-later
// Adversarial frames: regular grids of small white squares each holding dark dots
// (tiles, a perforated sheet, a window facade) make thousands of candidates that pass
// the paper's constraints; fields of marker look-alikes (markers whose squares are moved
// off their places by half a unit), small and blurred look-alikes, and torn 6x6 markers
// make second looks and outline reads that align and fail. A frame that costs a hundred
// times an ordinary one stalls a live pipeline. Each variant is rendered at 1280x720
// behind real markers of several families, and timed against an ordinary frame (the
// same markers on a photo) in the same run: per variant, the median, mean, 99th
// percentile and largest time, the median's ratio to the ordinary frame's, the
// candidates, those skipped by the per-frame budget and the deadline, and whether every
// real marker was found.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "csv.hpp"
#include "experiment.hpp"
#include "sources.hpp"
#include "trial.hpp"

#include "lftag/detector.hpp"
#include "lftag/trace.hpp"

namespace bench {
namespace {

const cv::Size kSize{1280, 720};
constexpr double kTagSize = 0.1;    // metres
constexpr double kGridDepth = 3.0;  // metres: behind every marker

// A grid of tiles seen by the camera. `dots` x `dots` dots per tile; `inverted` swaps ink
// and paper (black squares holding white dots, on white). A tile is drawn in cells: a
// 2-cell margin, 2-cell dots 2 cells apart, a 2-cell margin, then 2 cells of grout: a
// pitch of 4 * dots + 4 cells, `pitch_px` pixels where the plane meets the optical axis.
// What lies behind the real markers: a photo, a grid of dotted tiles, a field of
// look-alikes or of torn 6x6 markers on a plane, look-alikes scattered over a photo, or a
// frame of a real video in low light (sensor noise over the whole frame).
enum class Kind { ordinary, grid, lookalikes, torn, scattered, low_light };

struct Variant {
  std::string name;
  int dots = 0;  // grid: dots per tile side
  bool inverted = false;
  double pitch_px = 0;               // grid and fields: tile pitch at the plane's centre
  double tilt_deg = 0, pan_deg = 0;  // of the plane
  Kind kind = Kind::grid;
  double defocus_px = 0;  // Gaussian blur of the whole frame (sigma)
};

const std::vector<Variant> kVariants{
    {"ordinary", 0, false, 0, 0, 0, Kind::ordinary},
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
    {"lookalikes-60px", 0, false, 60, 15, -10, Kind::lookalikes},
    {"lookalikes-on-photo", 0, false, 0, 0, 0, Kind::scattered},
    {"lookalikes-18px-blurred", 0, false, 18, -10, 20, Kind::lookalikes, 1.2},
    {"torn-6x6-80px", 0, false, 80, 10, 15, Kind::torn},
    {"low-light-video", 0, false, 0, 0, 0, Kind::low_light},
};

// The families of the real markers in every frame, and the detector configurations.
const std::vector<int> kMarkerFamilies{2, 3, 4, 5, 6, 8};

// The element's and the command line's set-ups (the budget and kLiveDeadlineMs), the same
// without the deadline, and with neither.
struct Config {
  std::string name;
  std::string families;
  bool budget;    // the default budget, or none
  bool deadline;  // kLiveDeadlineMs, or none
};
const std::vector<Config> kConfigs{
    {"all", "2x2,3x3,4x4,5x5,6x6,7x7,8x8", true, true},
    {"default", "3x3,4x4", true, true},
    {"all-no-deadline", "2x2,3x3,4x4,5x5,6x6,7x7,8x8", true, false},
    {"default-no-deadline", "3x3,4x4", true, false},
    {"all-no-budget", "2x2,3x3,4x4,5x5,6x6,7x7,8x8", false, false},
};

struct Plan {
  int frames;  // per variant: marker placements
  int runs;    // timed runs of each frame
};
constexpr Plan kFull{3, 7}, kQuick{1, 1};

// The quick mode: the ordinary frame, two walls and a field of look-alikes, with the
// element's set-ups only.
bool in_quick(const std::string& name) {
  return name == "ordinary" || name == "white-4-10px" || name == "white-9-16px" || name == "lookalikes-60px" ||
         name == "low-light-video" || name == "all" || name == "default";
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

// A marker of `family` with a random id at two cells per unit, within `margin` units of
// white. A look-alike has each square moved by half a unit in a random direction and
// half a unit larger or smaller at random: a white region holding n x n black squares,
// which no id fits.
cv::Mat1f marker_cells(const lftag::Family& family, std::mt19937_64& rng, bool lookalike, int margin = 2) {
  lftag::TagId id;
  for (int d = 0; d < family.data_cell_count(); ++d) id = id.with_digit(d, int(rng() % 4));
  cv::Mat1b bits;
  cv::resize(family.unit_bitmap(id), bits, cv::Size(), 2, 2, cv::INTER_NEAREST);
  const float ink = 0.06f, paper = 0.88f;
  cv::Mat1f cells(bits.rows + 4 * margin, bits.cols + 4 * margin, paper);
  cv::Mat1f inside = cells(cv::Rect(2 * margin, 2 * margin, bits.cols, bits.rows));
  for (int y = 0; y < bits.rows; ++y)
    for (int x = 0; x < bits.cols; ++x) inside(y, x) = bits(y, x) ? paper : ink;
  if (!lookalike) return cells;
  for (const lftag::UnitRect& r : family.black_squares(id)) {
    const cv::Rect square(int(2 * r.x), int(2 * r.y), int(2 * r.width), int(2 * r.height));
    inside(square).setTo(paper);
  }
  for (const lftag::UnitRect& r : family.black_squares(id)) {
    const int dx = int(rng() % 3) - 1, dy = int(rng() % 3) - 1, grow = int(rng() % 3) - 1;
    const cv::Rect moved(int(2 * r.x) + dx - (grow > 0), int(2 * r.y) + dy - (grow > 0), int(2 * r.width) + 2 * grow,
                         int(2 * r.height) + 2 * grow);
    inside(moved & cv::Rect(4, 4, bits.cols - 8, bits.rows - 8)).setTo(ink);
  }
  return cells;
}

// A real 6x6 marker torn along a random line through it: the far side moved away from the
// tear by one to three units and along it by up to two, white paper showing in between.
cv::Mat1f torn_cells(std::mt19937_64& rng) {
  const cv::Mat1f whole = marker_cells(lftag::Family(6), rng, false);
  std::uniform_real_distribution<double> unit(0, 1);
  const double angle = CV_PI * unit(rng);
  const cv::Point2d normal(std::cos(angle), std::sin(angle));
  const cv::Point2d centre(whole.cols * (0.3 + 0.4 * unit(rng)), whole.rows * (0.3 + 0.4 * unit(rng)));
  const cv::Point2d shift = normal * (2 + 4 * unit(rng)) + cv::Point2d(-normal.y, normal.x) * (8 * unit(rng) - 4);
  cv::Mat1f torn(whole.size(), whole(0, 0));
  for (int y = 0; y < whole.rows; ++y)
    for (int x = 0; x < whole.cols; ++x) {
      const double side = (x - centre.x) * normal.x + (y - centre.y) * normal.y;
      if (side < 0) {
        torn(y, x) = whole(y, x);
        continue;
      }
      const int sx = int(std::lround(x - shift.x)), sy = int(std::lround(y - shift.y));
      const bool from_far_side = sx >= 0 && sy >= 0 && sx < whole.cols && sy < whole.rows &&
                                 (sx - centre.x) * normal.x + (sy - centre.y) * normal.y >= 0;
      if (from_far_side) torn(y, x) = whole(sy, sx);
    }
  return torn;
}

// A plane covered by tiles of look-alikes of every family 3x3 to 8x8, or of torn 6x6
// markers, each tile `tile` cells square.
cv::Mat1f field_albedo(const Variant& v, cv::Size cells, int tile, std::mt19937_64& rng) {
  cv::Mat1f albedo(cells, 0.88f);
  for (int y = 0; y + tile <= cells.height; y += tile)
    for (int x = 0; x + tile <= cells.width; x += tile) {
      const cv::Mat1f m =
          v.kind == Kind::torn ? torn_cells(rng) : marker_cells(lftag::Family(3 + int(rng() % 6)), rng, true);
      const cv::Rect at(x + (tile - m.cols) / 2, y + (tile - m.rows) / 2, m.cols, m.rows);
      m.copyTo(albedo(at));
    }
  return albedo;
}

Frame make_frame(const Variant& v, const std::vector<Source>& photos, const std::vector<Source>& video_sources,
                 FrameReader& videos, int index, std::uint64_t seed) {
  std::mt19937_64 rng = seeded(seed, {0xad5e, std::uint64_t(index)});
  std::uniform_real_distribution<double> unit(0, 1);
  lftag::SceneParams params;
  params.camera = lftag::Camera::default_for(kSize.width, kSize.height);
  std::vector<lftag::SceneTarget> targets;
  if (v.kind == Kind::ordinary || v.kind == Kind::scattered) {
    params.photo = cv::imread(photos[std::size_t(index) % photos.size()].path.string(), cv::IMREAD_GRAYSCALE);
  }
  if (v.kind == Kind::low_light) {
    // Paper at about 70 grey levels over a black level of 10 (exposure 0.26 of the
    // others'), sensor noise of 6 levels: the real low-light video of the hardening issue.
    const int source = index % int(video_sources.size());
    params.photo = videos.read(source, (20 + 37 * index) % video_sources[std::size_t(source)].frames);
    params.exposure = 0.26;
    params.noise_sigma = 6;
  }
  if (v.kind == Kind::scattered) {
    // 40 look-alikes of every family over the photo, 40 to 120 px, turned and tilted.
    for (int k = 0; k < 40; ++k) {
      lftag::SceneTarget t;
      const lftag::Family family(3 + int(rng() % 6));
      t.albedo = marker_cells(family, rng, true);
      const double size_m = kTagSize * t.albedo.cols / (2.0 * family.side());
      t.cell_size = size_m / t.albedo.cols;
      const double edge = 40 + 80 * unit(rng);
      const cv::Point2d centre(kSize.width * unit(rng), kSize.height * unit(rng));
      const Pose pose = place(params.camera, centre, params.camera.fx * size_m / edge,
                              lftag::rotation_from_angles(360 * unit(rng), 100 * unit(rng) - 50, 100 * unit(rng) - 50));
      t.rvec = pose.rvec, t.tvec = pose.tvec;
      targets.push_back(t);
    }
  } else if (v.kind == Kind::lookalikes || v.kind == Kind::torn) {
    // Tiles of the largest look-alike (8x8: 54 units, 108 cells, and its margin), or of a
    // torn 6x6 (42 units) with room for the tear.
    const int tile = v.kind == Kind::torn ? 2 * (42 + 4) + 8 : 2 * (54 + 4) + 4;
    lftag::SceneTarget field;
    field.cell_size = v.pitch_px / tile * kGridDepth / params.camera.fx;
    const double extent = 1.8 / params.camera.fx * kGridDepth / field.cell_size;
    field.albedo = field_albedo(v, cv::Size(int(kSize.width * extent), int(kSize.height * extent)), tile, rng);
    field.rvec = lftag::rotation_from_angles(0, v.tilt_deg, v.pan_deg);
    field.tvec = {0, 0, kGridDepth};
    targets.push_back(field);
  } else if (v.kind == Kind::grid) {
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
  if (v.defocus_px > 0 || v.kind == Kind::low_light) {
    if (v.defocus_px > 0) params.noise_sigma = 2;
    cv::Mat1f linear = lftag::SceneRenderer(params).render_linear(targets);
    if (v.defocus_px > 0) cv::GaussianBlur(linear, linear, cv::Size(), v.defocus_px);
    if (v.kind == Kind::low_light) linear += 10;
    frame.image = lftag::SceneRenderer(params).quantize(linear, seed + std::uint64_t(index));
  } else {
    frame.image = lftag::SceneRenderer(params).render(targets);
  }
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
  std::vector<Source> photos, video_sources;
  for (const Source& s : list_sources(options.data)) (s.video ? video_sources : photos).push_back(s);
  FrameReader videos(video_sources);

  std::vector<Variant> variants;
  for (const Variant& v : kVariants)
    if (!options.quick || in_quick(v.name)) variants.push_back(v);
  std::map<std::string, std::vector<Frame>> frames;
  for (const Variant& v : variants) {
    progress("adversarial: rendering " + v.name);
    for (int f = 0; f < plan.frames; ++f)
      frames[v.name].push_back(make_frame(v, photos, video_sources, videos, f, options.seed));
  }

  Csv csv(options.out / "adversarial.csv", {"config",
                                            "families",
                                            "budget",
                                            "variant",
                                            "frames",
                                            "runs",
                                            "median_ms",
                                            "q1_ms",
                                            "q3_ms",
                                            "ratio",
                                            "candidates",
                                            "examined",
                                            "skipped_by_budget",
                                            "second_looks",
                                            "second_looks_skipped",
                                            "markers",
                                            "found",
                                            "all_found",
                                            "wrong",
                                            "candidates_ms",
                                            "decoding_ms",
                                            "second_look_ms",
                                            "deadline_ms",
                                            "mean_ms",
                                            "p99_ms",
                                            "max_ms",
                                            "outline_reads",
                                            "past_deadline",
                                            "skipped_by_deadline"});
  bool first = true;
  for (const Config& config : kConfigs) {
    if (options.quick && !in_quick(config.name)) continue;
    lftag::DetectorParams params;
    params.families = lftag::Family::parse_list(config.families);
    params.camera = lftag::Camera::default_for(kSize.width, kSize.height);
    params.tag_size = kTagSize;
    if (!config.budget) params.max_candidates = 0;
    params.deadline_ms = config.deadline ? lftag::kLiveDeadlineMs : 0;
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
    if (first)
      std::printf("%-19s %-24s %9s %7s %7s %7s %10s %9s %8s %6s %7s\n", "config", "variant", "median_ms", "mean_ms",
                  "p99_ms", "max_ms", "candidates", "examined", "skipped", "cut", "found");
    first = false;
    for (const Variant& v : variants) {
      const Result& r = results[v.name];
      const lftag::DetectionStats& s = r.stats;
      const double n = double(std::max<std::int64_t>(1, s.frames));
      const double median = quantile(r.times, 0.5);
      const double examined = double(s.topology - s.skipped_by_budget);
      double mean = 0;
      for (const double t : r.times) mean += t / double(r.times.size());
      const double p99 = quantile(r.times, 0.99), largest = *std::max_element(r.times.begin(), r.times.end());
      csv.row(config.name, config.families, config.budget ? "default" : "none", v.name, int(frames[v.name].size()),
              plan.runs, median, quantile(r.times, 0.25), quantile(r.times, 0.75), median / ordinary,
              double(s.topology) / n, examined / n, double(s.skipped_by_budget) / n, double(s.second_looks) / n,
              double(s.second_looks_skipped) / n, r.markers, r.found, int(r.found == r.markers), r.wrong,
              s.candidates_ms / n, (s.keypoints_ms + s.hypotheses_ms + s.decode_ms + s.pose_ms) / n,
              s.second_look_ms / n, params.deadline_ms, mean, p99, largest, double(s.outline_reads) / n,
              double(s.past_deadline) / n, double(s.skipped_by_deadline) / n);
      std::printf("%-19s %-24s %9.2f %7.2f %7.2f %7.2f %10.0f %9.0f %8.0f %6.2f %4d/%-2d\n", config.name.c_str(),
                  v.name.c_str(), median, mean, p99, largest, double(s.topology) / n, examined / n,
                  double(s.skipped_by_budget) / n, double(s.past_deadline) / n, r.found, r.markers);
    }
    std::fflush(stdout);
  }
  return true;
}

}  // namespace bench
