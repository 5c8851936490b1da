// SPDX-License-Identifier: LGPL-2.1-or-later
// Pose accuracy against ground truth, in the paper's camera with a 1 m marker: one sweep
// over distance (facing the camera, random in-plane rotation) and one over tilt at a
// fixed distance. Each system's own pose is used; AprilTag's and ArUco's come from their
// four corners through OpenCV's IPPE for squares, with the same camera.
#include "csv.hpp"
#include "experiment.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

constexpr double kTiltDistance = 3.0;  // metres, for the tilt sweep

struct Plan {
  int markers;
  std::vector<double> distances;  // metres
  std::vector<double> tilts;      // degrees
};

Plan plan(bool quick) {
  if (quick) return {5, {2, 5, 10, 15}, {0, 20, 40, 60}};
  return {30, arange(2, 20, 1), arange(0, 75, 5)};
}

struct Case {
  std::string sweep;
  double distance, tilt;
};

}  // namespace

bool run_pose(const Options& options) {
  const Plan p = plan(options.quick);
  std::vector<Case> cases;
  for (double d : p.distances) cases.push_back({"distance", d, 0});
  for (double t : p.tilts) cases.push_back({"tilt", kTiltDistance, t});
  const lftag::Camera camera = paper_camera();
  lftag::SceneParams params;
  params.camera = camera;
  const lftag::SceneRenderer renderer(params);

  Csv trials_csv(options.out / "pose.csv", {"system", "family", "sweep", "distance_m", "tilt_deg", "id", "found",
                                            "rotation_error_deg", "translation_error_m"});
  Csv summary_csv(options.out / "pose_summary.csv",
                  {"system", "family", "sweep", "distance_m", "tilt_deg", "markers", "with_pose", "median_rotation_deg",
                   "p90_rotation_deg", "median_translation_m", "p90_translation_m", "median_translation_rel"});
  const int n = int(options.systems.size());
  std::vector<std::unique_ptr<FiducialSystem>> systems(n);
  std::vector<std::vector<std::string>> ids(n);
  std::vector<std::vector<std::vector<Outcome>>> results(n);  // system, case, marker
  parallel_for(n, options.threads, [&](int s, int) {
    systems[s] = make_system(options.systems[s]);
    FiducialSystem& system = *systems[s];
    system.set_camera(camera, 1.0);
    ids[s] = system.marker_ids(p.markers, options.seed);
    for (std::size_t c = 0; c < cases.size(); ++c) {
      std::vector<Outcome> outcomes;
      for (std::size_t m = 0; m < ids[s].size(); ++m) {
        std::mt19937_64 rng = seeded(options.seed, {0x905e, c, m});
        const double roll = std::uniform_real_distribution<double>(0, 360)(rng);
        const cv::Vec3d rvec = lftag::rotation_from_angles(roll, cases[c].tilt, 0);
        const Pose pose = place(camera, jittered_center(camera, rng), cases[c].distance, rvec);
        outcomes.push_back(run_trial(system, renderer, ids[s][m], 1.0, pose));
      }
      results[s].push_back(std::move(outcomes));
    }
    progress("pose: " + system.name() + " done");
  });
  for (int s = 0; s < n; ++s) {
    const FiducialSystem& system = *systems[s];
    for (std::size_t c = 0; c < cases.size(); ++c) {
      const Case& k = cases[c];
      std::vector<double> rot, trans;
      for (std::size_t m = 0; m < ids[s].size(); ++m) {
        const Outcome& o = results[s][c][m];
        trials_csv.row(system.name(), system.family(), k.sweep, k.distance, k.tilt, ids[s][m], int(o.found),
                       o.rotation_error_deg, o.translation_error_m);
        if (o.found && std::isfinite(o.rotation_error_deg)) {
          rot.push_back(o.rotation_error_deg);
          trans.push_back(o.translation_error_m);
        }
      }
      summary_csv.row(system.name(), system.family(), k.sweep, k.distance, k.tilt, int(ids[s].size()), int(rot.size()),
                      quantile(rot, 0.5), quantile(rot, 0.9), quantile(trans, 0.5), quantile(trans, 0.9),
                      quantile(trans, 0.5) / k.distance);
    }
  }
  return true;
}

}  // namespace bench
