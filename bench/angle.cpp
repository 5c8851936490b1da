// SPDX-License-Identifier: LGPL-2.1-or-later
// Grazing angle (the paper's table of first missed angles): a 1 m marker at a fixed
// distance in the paper's camera, turned by a random in-plane rotation and then tilted
// away about the camera's horizontal axis in growing steps.
#include "csv.hpp"
#include "experiment.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

// 2 m: the marker spans 160 px face-on, a quarter of the frame width.
constexpr double kDistance = 2.0;

struct Plan {
  int markers;
  double step;      // degrees, from 0 up to 89.5
  int empty_steps;  // stop a system after this many steps without a detection
};
constexpr Plan kFull{30, 0.5, 6}, kQuick{5, 4.0, 2};

}  // namespace

bool run_angle(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  const std::vector<double> angles = arange(0, 89.5, plan.step);
  const lftag::Camera camera = paper_camera();
  lftag::SceneParams params;
  params.camera = camera;
  const lftag::SceneRenderer renderer(params);

  Csv steps_csv(options.out / "angle.csv",
                {"system", "family", "distance_m", "angle_deg", "markers", "found", "wrong"});
  Csv summary_csv(options.out / "angle_summary.csv", {"system", "family", "distance_m", "markers", "first_missed_deg",
                                                      "missed20_deg", "last_found_deg", "wrong"});
  const std::vector<SystemSweep> swept =
      sweep_systems(options.systems, options.threads, options.seed, "angle", camera, angles, plan.markers,
                    plan.empty_steps, [&](FiducialSystem& system, const std::string& id, int step, int m) {
                      std::mt19937_64 rng = seeded(options.seed, {0xa691e, std::uint64_t(step), std::uint64_t(m)});
                      const double roll = std::uniform_real_distribution<double>(0, 360)(rng);
                      const cv::Vec3d rvec = lftag::rotation_from_angles(roll, angles[step], 0);
                      const Pose pose = place(camera, jittered_center(camera, rng), kDistance, rvec);
                      return run_trial(system, renderer, id, 1.0, pose);
                    });
  for (const SystemSweep& sw : swept) {
    const FiducialSystem& system = *sw.system;
    for (const Step& st : sw.steps)
      steps_csv.row(system.name(), system.family(), kDistance, st.value, st.markers, st.found, st.wrong);
    const Limits l = limits(sw.steps);
    summary_csv.row(system.name(), system.family(), kDistance, sw.steps.front().markers, l.first_missed, l.missed20,
                    l.last_found, l.wrong);
  }
  return true;
}

}  // namespace bench
