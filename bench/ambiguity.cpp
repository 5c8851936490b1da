// SPDX-License-Identifier: LGPL-2.1-or-later
// The planar pose's ambiguity (issue 27): how often each system chooses the wrong one of
// the two solutions, by marker size and tilt. Markers of 15 to 80 px (mean projected
// edge) tilted 0 to 60 degrees from the line of sight, about an axis and with a roll at
// random, anywhere in a 640x480 frame of a camera with fx = 500 (65 degrees across). Each
// system's chosen pose and its other solution are compared with the truth; a choice is
// wrong when the other solution is nearer the truth (trial.hpp's wrong_choice; the flip of
// a marker tilted t degrees is about 2t off). AprilTag's pose is OpenCV's IPPE for squares on its
// four corners (`ippe-corners`, every other experiment's) or the library's own
// estimate_tag_pose (`estimate-tag-pose`); both give two solutions. LFTag runs each of
// its choice rules on the same frames: `default`, `centroids` (shape_choice_ratio 0) and
// `shapes` (the squares' foreshortening whenever there are two solutions), so that the
// ratio below which the shapes decide can be chosen from one run. The trials are split
// into a tuning set and a validation set with other poses and marker ids, and each frame
// is seen clean and as a webcam would give it (kConditions). A wrong choice
// more than kFlipDeg off is a flip: what makes the z axis jump.
#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <tuple>

#include <opencv2/imgproc.hpp>

#include "apriltag_system.hpp"
#include "csv.hpp"
#include "experiment.hpp"
#include "lftag_system.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

constexpr double kTagSize = 0.1;  // metres; only the poses' scale depends on it
// The ambiguity ratios' bins of ambiguity_ratios.csv: where a system's ratio says its choice is safe.
const std::vector<double> kRatioBins{0, 1.1, 1.5, 2, 3};
const char* const kSets[2] = {"tuning", "validation"};
// Each frame as rendered (sharp, noise-free) and as a webcam gives it: a defocus of
// 0.7 px (Gaussian sigma) and sensor noise of 3 grey levels.
struct Condition {
  const char* name;
  double defocus_px, noise;
};
const Condition kConditions[] = {{"clean", 0, 0}, {"webcam", 0.7, 3}};
constexpr int kConditionCount = int(std::size(kConditions));

struct Plan {
  int markers;  // per size, tilt and set
  std::vector<double> sizes, tilts;
};

Plan plan(bool quick) {
  if (quick) return {2, {20, 60}, {0, 30}};
  return {30, {15, 20, 25, 30, 40, 50, 60, 80}, {0, 5, 10, 15, 20, 30, 40, 50, 60}};
}

lftag::Camera camera() { return lftag::Camera::pinhole(500, 500, 319.5, 239.5, 640, 480); }

struct Rule {
  std::string name;
  std::unique_ptr<FiducialSystem> system;
};

// The systems to run on one design's frames: LFTag's choice rules, or the system alone.
std::vector<Rule> rules_for(const std::string& name) {
  std::vector<Rule> rules;
  if (name.rfind("apriltag-", 0) == 0) {
    // "apriltag-36h11-d2": the family and decimation.
    const std::size_t dash = name.rfind("-d");
    const std::string family = name.substr(9, dash - 9);
    const int decimate = std::stoi(name.substr(dash + 2));
    rules.push_back({"ippe-corners", make_system(name)});
    rules.push_back({"estimate-tag-pose", std::make_unique<AprilTagSystem>(
                                              family, decimate, AprilTagSystem::PoseMethod::orthogonal_iteration)});
    return rules;
  }
  if (name.rfind("lftag-", 0) != 0) {
    rules.push_back({"own", make_system(name)});
    return rules;
  }
  const int n = lftag::Family::parse(name.substr(6)).n();
  lftag::DetectorParams centroids, shapes;
  centroids.shape_choice_ratio = 0;
  shapes.shape_choice_ratio = std::numeric_limits<double>::infinity();
  rules.push_back({"default", std::make_unique<LftagSystem>(n)});
  rules.push_back({"centroids", std::make_unique<LftagSystem>(n, centroids)});
  rules.push_back({"shapes", std::make_unique<LftagSystem>(n, shapes)});
  return rules;
}

struct Trial {
  int condition, set, size, tilt, marker;
  std::string id;
  double edge_px, tilt_deg;       // as placed
  std::vector<Outcome> outcomes;  // per rule
};

}  // namespace

bool run_ambiguity(const Options& options) {
  const Plan p = plan(options.quick);
  lftag::SceneParams params;
  params.camera = camera();
  const lftag::SceneRenderer renderer(params);
  std::vector<lftag::SceneRenderer> noisy;  // per condition: its noise
  for (const Condition& c : kConditions) {
    params.noise_sigma = c.noise;
    noisy.emplace_back(params);
  }
  const int n = int(options.systems.size());
  std::vector<std::vector<std::string>> rule_names(n);
  std::vector<std::vector<Trial>> trials(n);
  parallel_for(n, options.threads, [&](int s, int) {
    std::vector<Rule> rules = rules_for(options.systems[s]);
    for (Rule& r : rules) {
      r.system->set_camera(renderer.params().camera, kTagSize);
      rule_names[s].push_back(r.name);
    }
    const FiducialSystem& design = *rules[0].system;
    const std::vector<std::string> ids = design.marker_ids(2 * p.markers, options.seed);
    for (int set = 0; set < 2; ++set)
      for (std::size_t a = 0; a < p.sizes.size(); ++a)
        for (std::size_t t = 0; t < p.tilts.size(); ++t)
          for (int m = 0; m < p.markers; ++m) {
            std::mt19937_64 rng = seeded(options.seed, {0xa3b1, std::uint64_t(set), a, t, std::uint64_t(m)});
            auto uniform = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
            const double edge = p.sizes[a];
            const cv::Point2d center(uniform(edge, 639 - edge), uniform(edge, 479 - edge));
            const Pose pose = facing_pose(renderer.params().camera, center, edge, p.tilts[t], uniform(0, 360),
                                          uniform(0, 360), kTagSize);
            const std::string& id = ids[std::size_t(set * p.markers + m)];
            const cv::Mat1f linear = renderer.render_linear({design.target(id, kTagSize, pose.rvec, pose.tvec)});
            for (int c = 0; c < kConditionCount; ++c) {
              Trial trial{c,
                          set,
                          int(a),
                          int(t),
                          m,
                          id,
                          edge_px(renderer.params().camera, pose, kTagSize),
                          tilt_from_sight_deg(pose),
                          {}};
              cv::Mat1f defocused = linear;
              if (kConditions[c].defocus_px > 0)
                cv::GaussianBlur(linear, defocused, cv::Size(), kConditions[c].defocus_px);
              const cv::Mat1b image = noisy[c].quantize(defocused, rng());
              for (Rule& r : rules)
                trial.outcomes.push_back(score(r.system->detect(image), id, pose, kTagSize, renderer.params().camera));
              trials[s].push_back(std::move(trial));
            }
          }
    progress("ambiguity: " + options.systems[s] + " done");
  });

  Csv trials_csv(options.out / "ambiguity.csv", {"system", "rule", "condition", "set", "size_px", "tilt_deg", "marker",
                                                 "id", "edge_px", "tilt_placed_deg", "found", "rotation_error_deg",
                                                 "alternative_rotation_error_deg", "ambiguity_ratio", "wrong_choice"});
  Csv summary_csv(
      options.out / "ambiguity_summary.csv",
      {"system", "rule", "condition", "set", "size_px", "tilt_deg", "markers", "found", "with_alternative", "wrong",
       "wrong_pct", "flips", "flips_pct", "median_rotation_deg", "p90_rotation_deg", "wrong_ratio_max"});
  Csv ratios_csv(options.out / "ambiguity_ratios.csv",
                 {"system", "rule", "condition", "set", "ratio_from", "ratio_to", "found", "wrong", "flips"});
  for (int s = 0; s < n; ++s) {
    for (std::size_t r = 0; r < rule_names[s].size(); ++r) {
      // Cells of size x tilt, then each size over all tilts, each tilt over all sizes, and
      // everything (NaN stands for "all").
      struct Tally {
        int markers = 0, found = 0, with_alternative = 0, wrong = 0, flips = 0;
        double wrong_ratio_max = kNaN;
        std::vector<double> rotation;
      };
      std::map<std::tuple<int, int, int, int>, Tally> tallies;      // condition, set, size, tilt (-1: all)
      std::map<std::tuple<int, int, std::size_t>, Tally> by_ratio;  // condition, set, ratio bin
      for (const Trial& t : trials[s]) {
        const Outcome& o = t.outcomes[r];
        const bool wrong = wrong_choice(o), flip = flipped(o);
        if (o.found && std::isfinite(o.ambiguity_ratio)) {
          std::size_t bin = 0;
          while (bin + 1 < kRatioBins.size() && o.ambiguity_ratio >= kRatioBins[bin + 1]) ++bin;
          Tally& y = by_ratio[{t.condition, t.set, bin}];
          ++y.found, y.wrong += wrong, y.flips += flip;
        }
        trials_csv.row(options.systems[s], rule_names[s][r], kConditions[t.condition].name, kSets[t.set],
                       p.sizes[t.size], p.tilts[t.tilt], t.marker, t.id, t.edge_px, t.tilt_deg, int(o.found),
                       o.rotation_error_deg, o.alternative_rotation_error_deg, o.ambiguity_ratio, int(wrong));
        const int c = t.condition;
        for (const auto& key : {std::make_tuple(c, t.set, t.size, t.tilt), std::make_tuple(c, t.set, t.size, -1),
                                std::make_tuple(c, t.set, -1, t.tilt), std::make_tuple(c, t.set, -1, -1)}) {
          Tally& y = tallies[key];
          ++y.markers;
          if (!o.found || !std::isfinite(o.rotation_error_deg)) continue;
          ++y.found;
          y.rotation.push_back(o.rotation_error_deg);
          y.with_alternative += std::isfinite(o.alternative_rotation_error_deg);
          if (wrong) {
            ++y.wrong;
            y.flips += flip;
            if (!(y.wrong_ratio_max >= o.ambiguity_ratio)) y.wrong_ratio_max = o.ambiguity_ratio;
          }
        }
      }
      for (const auto& [key, y] : tallies) {
        const auto [condition, set, size, tilt] = key;
        summary_csv.row(options.systems[s], rule_names[s][r], kConditions[condition].name, kSets[set],
                        size < 0 ? kNaN : p.sizes[size], tilt < 0 ? kNaN : p.tilts[tilt], y.markers, y.found,
                        y.with_alternative, y.wrong, y.found ? 100.0 * y.wrong / y.found : kNaN, y.flips,
                        y.found ? 100.0 * y.flips / y.found : kNaN, quantile(y.rotation, 0.5),
                        quantile(y.rotation, 0.9), y.wrong_ratio_max);
      }
      for (const auto& [key, y] : by_ratio) {
        const auto [condition, set, bin] = key;
        const double to = bin + 1 < kRatioBins.size() ? kRatioBins[bin + 1] : kNaN;
        ratios_csv.row(options.systems[s], rule_names[s][r], kConditions[condition].name, kSets[set], kRatioBins[bin],
                       to, y.found, y.wrong, y.flips);
      }
    }
  }
  return true;
}

}  // namespace bench
