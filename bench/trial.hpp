// SPDX-License-Identifier: LGPL-2.1-or-later
// One trial: a marker rendered at a known pose, detected and scored against the truth;
// and sweeps of trials over a growing difficulty (distance, angle, blur).
#pragma once

#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lftag/camera.hpp"
#include "lftag/render.hpp"
#include "system.hpp"

namespace bench {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The LFTag paper's simulation camera: 640x480, fx = fy = 320, no distortion.
lftag::Camera paper_camera();

// The pose with rotation `rvec` whose marker centre lies at depth `distance` on the
// ray through image point `center`.
Pose place(const lftag::Camera& camera, cv::Point2d center, double distance, const cv::Vec3d& rvec);

// The pose whose marker centre is seen at image point `center` (through the lens
// distortion, if any), tilted by
// `tilt` degrees from facing the camera along that line of sight, about an axis across it
// at `tilt_axis` degrees in the image, rolled by `roll` degrees, at the distance along the
// line that gives a mean projected tag edge of `edge` pixels.
Pose facing_pose(const lftag::Camera& camera, cv::Point2d center, double edge, double tilt, double tilt_axis,
                 double roll, double tag_size);

// A sheet at the start or end of a motion across a clip (`video`, `field`): the image
// point its centre is seen at, the mean projected edge of its tag, its tilt out of the
// plane facing the camera (about an axis across the line of sight at `tilt_axis` degrees
// in the image) and its roll.
struct Placement {
  cv::Point2d center;
  double edge, tilt, tilt_axis, roll;  // pixels, degrees
};

// Eased from a (s = 0) to b (s = 1): the sheet starts and stops gently.
Placement between(const Placement& a, const Placement& b, double s);

// Degrees between the marker's normal and the line of sight to its centre.
double tilt_from_sight_deg(const Pose& pose);

// The image centre moved by a random sub-pixel offset (up to half a pixel each way).
cv::Point2d jittered_center(const lftag::Camera& camera, std::mt19937_64& rng);

struct Outcome {
  bool found = false;                     // a detection with the right id at the marker's place
  int wrong = 0;                          // detections with another id, or with the right id elsewhere
  cv::Point2d center_offset{kNaN, kNaN};  // found centre - true centre, pixels
  double rotation_error_deg = kNaN;       // of the found detection, when it has a pose
  double translation_error_m = kNaN;
  double depth_error_m = kNaN;                   // signed: the found distance to the camera minus the true one
  double alternative_rotation_error_deg = kNaN;  // of the planar pose's other solution, when given
  double ambiguity_ratio = kNaN;                 // the system's, when given
};

// The planar pose's choice between its two solutions was wrong: the other one is nearer
// the truth by more than kWrongChoiceMargin degrees (face on, the two are mirror tilts
// about the line of sight and about as near). A wrong choice more than kFlipDeg off is a
// flip: what makes the z axis jump.
constexpr double kWrongChoiceMargin = 1, kFlipDeg = 10;
inline bool wrong_choice(const Outcome& o) {
  return o.found && o.rotation_error_deg > o.alternative_rotation_error_deg + kWrongChoiceMargin;
}
inline bool flipped(const Outcome& o) { return wrong_choice(o) && o.rotation_error_deg > kFlipDeg; }

// Mean projected edge of the tag (outer border) in pixels.
double edge_px(const lftag::Camera& camera, const Pose& pose, double tag_size);

// Scores detections against one marker: a detection is the marker when its id is right
// and its centre lies within a quarter of the marker's edge (at least 2 px) of the truth.
Outcome score(const std::vector<Detected>& detections, const std::string& id, const Pose& truth, double tag_size,
              const lftag::Camera& camera);

// Renders marker `id` of `system` alone with `pose`, detects it and scores the result.
// The system must have been given the renderer's camera and `tag_size`. When the marker
// is not found and `save_if_missed` is set, the frame is written there.
Outcome run_trial(FiducialSystem& system, const lftag::SceneRenderer& renderer, const std::string& id, double tag_size,
                  const Pose& pose, const std::filesystem::path& save_if_missed = {});

// Angle between two rotations, degrees.
double rotation_error_deg(const cv::Vec3d& rvec_a, const cv::Vec3d& rvec_b);

// A uniform draw from [lo, hi).
double uniform(std::mt19937_64& rng, double lo, double hi);
// The rotation matrix of a rotation vector.
cv::Matx33d rotation_matrix(const cv::Vec3d& axis_angle);
// Degrees between a sheet's normal and the line of sight to its centre.
double tilt_deg(const Pose& pose);
// A pose seen through a camera turned by `shake` about its centre.
Pose shaken(const Pose& pose, const cv::Matx33d& shake);

// One value of a swept parameter and how the markers fared there.
struct Step {
  double value = 0;
  int markers = 0, found = 0, wrong = 0;
};

// Runs trial(step, marker) for every marker at values[0], values[1], ... and stops after
// a step for which `done` (given all steps so far) is true.
std::vector<Step> sweep(const std::vector<double>& values, int markers,
                        const std::function<Outcome(int step, int marker)>& trial,
                        const std::function<bool(const std::vector<Step>&)>& done);

// Stop rule: `count` consecutive steps found nothing.
std::function<bool(const std::vector<Step>&)> after_empty_steps(int count);

// A system and its sweep.
struct SystemSweep {
  std::unique_ptr<FiducialSystem> system;
  std::vector<Step> steps;
};

// Every system of `names`, one to a worker (`threads`), made for `camera` with 1 m
// markers and swept over `values` with `markers` of its ids (of `seed`) until
// `empty_steps` steps found nothing: trial(system, id, step, marker). `experiment`
// names the progress lines.
std::vector<SystemSweep> sweep_systems(
    const std::vector<std::string>& names, int threads, std::uint64_t seed, const std::string& experiment,
    const lftag::Camera& camera, const std::vector<double>& values, int markers, int empty_steps,
    const std::function<Outcome(FiducialSystem& system, const std::string& id, int step, int marker)>& trial);

// What a sweep reached: the first value at which a marker was missed, the first at which
// 20 % or more were missed, the last at which any was found, and all wrong detections.
struct Limits {
  double first_missed = kNaN, missed20 = kNaN, last_found = kNaN;
  int wrong = 0;
};
Limits limits(const std::vector<Step>& steps);

// start, start + step, ... up to `stop` inclusive (within rounding).
std::vector<double> arange(double start, double stop, double step);

}  // namespace bench
