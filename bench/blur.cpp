// SPDX-License-Identifier: LGPL-2.1-or-later
// Motion blur (the paper's polar plot): an upright 1 m marker at a fixed distance in the
// paper's camera, blurred by a linear PSF at angles from 0 (vertical) to 90 degrees
// (horizontal) with a growing length. Per angle, the largest blur at which every marker
// is still found. The paper stopped at 15 % of the marker edge; the sweep goes on to 30 %,
// so that systems still finding every marker at 15 % get a measured limit too, and the
// summary says where no miss came at all.
#include <optional>

#include "csv.hpp"
#include "experiment.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

constexpr double kDistance = 5.0;      // a 64 px marker: 15 % is 9.6 px of blur
constexpr double kMaxFraction = 0.30;  // of the marker edge

struct Plan {
  int markers;
  double angle_step;     // degrees
  double fraction_step;  // of the marker edge
};
constexpr Plan kFull{30, 7.5, 0.01}, kQuick{3, 45, 0.03};

}  // namespace

bool run_blur(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  const std::vector<double> angles = arange(0, 90, plan.angle_step);
  const std::vector<double> fractions = arange(0, kMaxFraction, plan.fraction_step);
  const lftag::Camera camera = paper_camera();
  const double edge = camera.fx / kDistance;

  Csv steps_csv(options.out / "blur.csv", {"system", "family", "distance_m", "blur_angle_deg", "blur_fraction",
                                           "blur_px", "markers", "found", "wrong"});
  Csv summary_csv(options.out / "blur_summary.csv", {"system", "family", "distance_m", "blur_angle_deg", "markers",
                                                     "max_fraction_all_found", "max_px_all_found", "never_missed"});
  const int n = int(options.systems.size());
  std::vector<std::unique_ptr<FiducialSystem>> systems(n);
  std::vector<std::vector<std::vector<Step>>> results(n);  // system, angle, steps
  parallel_for(n, options.threads, [&](int s, int) {
    systems[s] = make_system(options.systems[s]);
    FiducialSystem& system = *systems[s];
    system.set_camera(camera, 1.0);
    const std::vector<std::string> ids = system.marker_ids(plan.markers, options.seed);
    for (std::size_t a = 0; a < angles.size(); ++a) {
      // The blur belongs to the renderer: make one per blur length, when it is reached.
      std::optional<lftag::SceneRenderer> renderer;
      int renderer_step = -1;
      results[s].push_back(sweep(
          fractions, int(ids.size()),
          [&](int step, int m) {
            if (step != renderer_step) {
              lftag::SceneParams params;
              params.camera = camera;
              params.blur_length_px = fractions[step] * edge;
              params.blur_angle_deg = angles[a];
              renderer.emplace(params);
              renderer_step = step;
            }
            std::mt19937_64 rng = seeded(options.seed, {0xb1a4, a, std::uint64_t(step), std::uint64_t(m)});
            const Pose pose = place(camera, jittered_center(camera, rng), kDistance, cv::Vec3d());  // upright
            const std::filesystem::path missed =
                options.save_misses.empty()
                    ? std::filesystem::path()
                    : options.save_misses /
                          (system.name() + "-blur-" + std::to_string(int(std::lround(angles[a] * 10))) + "ddeg-" +
                           std::to_string(int(std::lround(fractions[step] * 100))) + "pct-marker" + std::to_string(m) +
                           ".png");
            return run_trial(system, *renderer, ids[m], 1.0, pose, missed);
          },
          [](const std::vector<Step>& steps) { return steps.back().found < steps.back().markers; }));
    }
    progress("blur: " + system.name() + " done");
  });
  for (int s = 0; s < n; ++s) {
    const FiducialSystem& system = *systems[s];
    for (std::size_t a = 0; a < angles.size(); ++a) {
      const std::vector<Step>& steps = results[s][a];
      for (const Step& st : steps)
        steps_csv.row(system.name(), system.family(), kDistance, angles[a], st.value, st.value * edge, st.markers,
                      st.found, st.wrong);
      // The sweep stopped at the first step with a miss, so all steps before it found all.
      const bool never_missed = steps.back().found == steps.back().markers;
      const int last_good = int(steps.size()) - (never_missed ? 1 : 2);
      const double fraction = last_good >= 0 ? steps[last_good].value : kNaN;
      summary_csv.row(system.name(), system.family(), kDistance, angles[a], steps.front().markers, fraction,
                      fraction * edge, int(never_missed));
    }
  }
  return true;
}

}  // namespace bench
