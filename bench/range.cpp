// SPDX-License-Identifier: LGPL-2.1-or-later
// Detection range in the LFTag paper's set-up (its range table and figure 8): the paper's
// camera, a 1 m marker facing the camera at the image centre with a random in-plane
// rotation and sub-pixel offset, 30 markers per family, stepped away until a system
// finds nothing for a while. First-missed and 20 %-missed distances per system; wrong
// ids are counted apart, never as found.
#include <cmath>

#include "csv.hpp"
#include "experiment.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

struct Plan {
  int markers;
  double start, stop, step;  // metres
  int empty_steps;           // stop a system after this many steps without a detection
};
constexpr Plan kFull{30, 2.0, 80.0, 0.1, 10}, kQuick{5, 2.0, 80.0, 1.0, 2};

}  // namespace

bool run_range(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  const std::vector<double> distances = arange(plan.start, plan.stop, plan.step);
  const lftag::Camera camera = paper_camera();
  lftag::SceneParams params;
  params.camera = camera;
  const lftag::SceneRenderer renderer(params);

  Csv steps_csv(options.out / "range.csv",
                {"system", "family", "dictionary_size", "distance_m", "edge_px", "markers", "found", "wrong"});
  Csv summary_csv(options.out / "range_summary.csv", {"system", "family", "dictionary_size", "markers",
                                                      "first_missed_m", "missed20_m", "last_found_m", "wrong"});
  const std::vector<SystemSweep> swept =
      sweep_systems(options.systems, options.threads, options.seed, "range", camera, distances, plan.markers,
                    plan.empty_steps, [&](FiducialSystem& system, const std::string& id, int step, int m) {
                      std::mt19937_64 rng = seeded(options.seed, {0x4a46e, std::uint64_t(step), std::uint64_t(m)});
                      const double roll = std::uniform_real_distribution<double>(0, 360)(rng);
                      const cv::Vec3d rvec = lftag::rotation_from_angles(roll, 0, 0);
                      const Pose pose = place(camera, jittered_center(camera, rng), distances[step], rvec);
                      const std::filesystem::path missed =
                          options.save_misses.empty()
                              ? std::filesystem::path()
                              : options.save_misses / (system.name() + "-range-" +
                                                       std::to_string(int(std::lround(distances[step] * 10))) +
                                                       "dm-marker" + std::to_string(m) + ".png");
                      return run_trial(system, renderer, id, 1.0, pose, missed);
                    });
  for (const SystemSweep& sw : swept) {
    const FiducialSystem& system = *sw.system;
    for (const Step& st : sw.steps)
      steps_csv.row(system.name(), system.family(), system.dictionary_size(), st.value, camera.fx / st.value,
                    st.markers, st.found, st.wrong);
    const Limits l = limits(sw.steps);
    summary_csv.row(system.name(), system.family(), system.dictionary_size(), sw.steps.front().markers, l.first_missed,
                    l.missed20, l.last_found, l.wrong);
  }
  return true;
}

}  // namespace bench
