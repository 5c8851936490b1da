// SPDX-License-Identifier: LGPL-2.1-or-later
// The suite's sanity check: every system must find its own markers where any fiducial
// system should (2 m, 160 px, tilted 20 degrees), with the right ids, centres and poses.
// It catches a wrongly drawn marker, a swapped corner order, a half-pixel convention
// error or a wrong tag size before any other experiment trusts the system.
#include <iostream>

#include "csv.hpp"
#include "experiment.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

constexpr int kMarkers = 20;  // enough for the mean centre offset to show a bias
constexpr double kDistance = 2.0, kTilt = 20.0;
// Far beyond what a detector that works misses by (ArUco's unrefined corners: about 1.5
// degrees, 2 cm and a 0.1 px mean offset), and far below what a convention error costs:
// a corner order off by one turns the pose by 90 degrees, a wrong tag size scales the
// distance by 10 % or more, a half-pixel shift moves every centre by 0.7 px.
constexpr double kMaxRotationDeg = 5.0, kMaxTranslation = 0.05 * kDistance, kMaxCenterBiasPx = 0.25;

}  // namespace

bool run_check(const Options& options) {
  Csv csv(options.out / "check.csv", {"system", "family", "id", "found", "wrong", "center_dx_px", "center_dy_px",
                                      "rotation_error_deg", "translation_error_m"});
  const lftag::Camera camera = paper_camera();
  const int n = int(options.systems.size());
  std::vector<std::unique_ptr<FiducialSystem>> systems(n);
  std::vector<std::vector<std::string>> ids(n), problems(n);
  std::vector<std::vector<Outcome>> outcomes(n);
  parallel_for(n, options.threads, [&](int s, int) {
    systems[s] = make_system(options.systems[s]);
    FiducialSystem& system = *systems[s];
    system.set_camera(camera, 1.0);
    lftag::SceneParams params;
    params.camera = camera;
    const lftag::SceneRenderer renderer(params);
    ids[s] = system.marker_ids(kMarkers, options.seed);
    if (ids[s].size() < kMarkers) problems[s].push_back("fewer test markers than asked for");
    cv::Point2d bias(0, 0);
    int found = 0;
    for (std::size_t m = 0; m < ids[s].size(); ++m) {
      std::mt19937_64 rng = seeded(options.seed, {0xc4ec, m});
      const double roll = std::uniform_real_distribution<double>(0, 360)(rng);
      const cv::Vec3d rvec = lftag::rotation_from_angles(roll, kTilt, 0);
      const Pose pose = place(camera, jittered_center(camera, rng), kDistance, rvec);
      const Outcome o = run_trial(system, renderer, ids[s][m], 1.0, pose);
      outcomes[s].push_back(o);
      const std::string what = "marker " + ids[s][m] + ": ";
      if (!o.found) problems[s].push_back(what + "not found");
      if (o.wrong) problems[s].push_back(what + std::to_string(o.wrong) + " wrong detections");
      if (!o.found) continue;
      if (!(o.rotation_error_deg <= kMaxRotationDeg))
        problems[s].push_back(what + "rotation error " + std::to_string(o.rotation_error_deg) + " deg");
      if (!(o.translation_error_m <= kMaxTranslation))
        problems[s].push_back(what + "translation error " + std::to_string(o.translation_error_m) + " m");
      bias += o.center_offset;
      ++found;
    }
    if (found && cv::norm(bias / found) > kMaxCenterBiasPx)
      problems[s].push_back("centres offset by (" + std::to_string(bias.x / found) + ", " +
                            std::to_string(bias.y / found) + ") px on average");
  });
  bool ok = true;
  for (int s = 0; s < n; ++s) {
    for (std::size_t m = 0; m < outcomes[s].size(); ++m) {
      const Outcome& o = outcomes[s][m];
      csv.row(systems[s]->name(), systems[s]->family(), ids[s][m], int(o.found), o.wrong, o.center_offset.x,
              o.center_offset.y, o.rotation_error_deg, o.translation_error_m);
    }
    for (const std::string& p : problems[s]) std::cerr << "check: " << systems[s]->name() << ": " << p << "\n";
    ok = ok && problems[s].empty();
  }
  return ok;
}

}  // namespace bench
