// SPDX-License-Identifier: LGPL-2.1-or-later
#include "trial.hpp"

#include <algorithm>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "experiment.hpp"
#include "lftag/tracker.hpp"  // rotation_angle
#include "systems.hpp"

namespace bench {

lftag::Camera paper_camera() { return lftag::Camera::pinhole(320, 320, 319.5, 239.5, 640, 480); }

Pose place(const lftag::Camera& camera, cv::Point2d center, double distance, const cv::Vec3d& rvec) {
  const cv::Point2d ideal = camera.undistort({center})[0];
  const double x = (ideal.x - camera.cx) / camera.fx, y = (ideal.y - camera.cy) / camera.fy;
  return {rvec, cv::Vec3d(x * distance, y * distance, distance)};
}

Placement between(const Placement& a, const Placement& b, double s) {
  const double e = (1 - std::cos(CV_PI * s)) / 2;
  auto mix = [e](double x, double y) { return x + (y - x) * e; };
  return {{mix(a.center.x, b.center.x), mix(a.center.y, b.center.y)},
          std::exp(mix(std::log(a.edge), std::log(b.edge))),
          mix(a.tilt, b.tilt),
          mix(a.tilt_axis, b.tilt_axis),
          mix(a.roll, b.roll)};
}

Pose facing_pose(const lftag::Camera& camera, cv::Point2d center, double edge, double tilt, double tilt_axis,
                 double roll, double tag_size) {
  const auto rotation = [](const cv::Vec3d& axis_angle) {
    cv::Matx33d r;
    cv::Rodrigues(axis_angle, r);
    return r;
  };
  const cv::Point2d ideal = camera.undistort({center})[0];
  const cv::Vec3d ray =
      cv::normalize(cv::Vec3d((ideal.x - camera.cx) / camera.fx, (ideal.y - camera.cy) / camera.fy, 1));
  const cv::Vec3d axis = cv::Vec3d(0, 0, 1).cross(ray);
  const double turn = std::asin(std::min(1.0, cv::norm(axis)));
  const cv::Matx33d to_ray = rotation(turn > 1e-12 ? axis * (turn / cv::norm(axis)) : cv::Vec3d());
  const double d = CV_PI / 180;
  const cv::Matx33d tilted = rotation(cv::Vec3d(std::cos(tilt_axis * d), std::sin(tilt_axis * d), 0) * (tilt * d));
  Pose pose;
  cv::Rodrigues(to_ray * tilted * rotation({0, 0, roll * d}), pose.rvec);
  // The edge is nearly inverse to the distance (not quite, once tilted): a few corrections.
  double distance = camera.fx * tag_size / edge;
  for (int i = 0; i < 4; ++i) {
    pose.tvec = ray * distance;
    distance *= edge_px(camera, pose, tag_size) / edge;
  }
  pose.tvec = ray * distance;
  return pose;
}

double tilt_from_sight_deg(const Pose& pose) {
  cv::Matx33d r;
  cv::Rodrigues(pose.rvec, r);
  const cv::Vec3d normal = r * cv::Vec3d(0, 0, 1);
  return std::acos(std::clamp(normal.dot(cv::normalize(pose.tvec)), -1.0, 1.0)) * 180 / CV_PI;
}

cv::Point2d jittered_center(const lftag::Camera& camera, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> offset(-0.5, 0.5);
  const double dx = offset(rng), dy = offset(rng);
  return {(camera.width - 1) / 2.0 + dx, (camera.height - 1) / 2.0 + dy};
}

double edge_px(const lftag::Camera& camera, const Pose& pose, double tag_size) {
  const double h = tag_size / 2;
  const std::vector<cv::Point2d> c =
      camera.project({{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}}, pose.rvec, pose.tvec);
  double sum = 0;
  for (int i = 0; i < 4; ++i) sum += cv::norm(c[(i + 1) % 4] - c[i]);
  return sum / 4;
}

double uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

cv::Matx33d rotation_matrix(const cv::Vec3d& axis_angle) {
  cv::Matx33d r;
  cv::Rodrigues(axis_angle, r);
  return r;
}

double tilt_deg(const Pose& pose) {
  const cv::Vec3d normal = rotation_matrix(pose.rvec) * cv::Vec3d(0, 0, 1);
  return std::acos(std::clamp(normal.dot(cv::normalize(pose.tvec)), -1.0, 1.0)) * 180 / CV_PI;
}

Pose shaken(const Pose& pose, const cv::Matx33d& shake) {
  Pose p;
  cv::Rodrigues(shake * rotation_matrix(pose.rvec), p.rvec);
  p.tvec = shake * pose.tvec;
  return p;
}

double rotation_error_deg(const cv::Vec3d& a, const cv::Vec3d& b) { return lftag::rotation_angle(a, b) * 180 / CV_PI; }

Outcome score(const std::vector<Detected>& detections, const std::string& id, const Pose& truth, double tag_size,
              const lftag::Camera& camera) {
  const cv::Point2d center = camera.project({{0, 0, 0}}, truth.rvec, truth.tvec)[0];
  const double tolerance = std::max(2.0, edge_px(camera, truth, tag_size) / 4);
  Outcome out;
  for (const Detected& d : detections) {
    const double error = cv::norm(d.center - center);
    if (d.id != id || error > tolerance) {
      ++out.wrong;
      continue;
    }
    if (out.found) continue;  // a duplicate of the marker is neither new nor wrong
    out.found = true;
    out.center_offset = d.center - center;
    if (d.pose) {
      out.rotation_error_deg = rotation_error_deg(d.pose->rvec, truth.rvec);
      out.translation_error_m = cv::norm(d.pose->tvec - truth.tvec);
      out.depth_error_m = cv::norm(d.pose->tvec) - cv::norm(truth.tvec);
    }
    if (d.alternative) out.alternative_rotation_error_deg = rotation_error_deg(d.alternative->rvec, truth.rvec);
    out.ambiguity_ratio = d.ambiguity_ratio;
  }
  return out;
}

Outcome run_trial(FiducialSystem& system, const lftag::SceneRenderer& renderer, const std::string& id, double tag_size,
                  const Pose& pose, const std::filesystem::path& save_if_missed) {
  const cv::Mat1b image = renderer.render({system.target(id, tag_size, pose.rvec, pose.tvec)});
  const Outcome outcome = score(system.detect(image), id, pose, tag_size, renderer.params().camera);
  if (!outcome.found && !save_if_missed.empty()) cv::imwrite(save_if_missed.string(), image);
  return outcome;
}

std::vector<Step> sweep(const std::vector<double>& values, int markers, const std::function<Outcome(int, int)>& trial,
                        const std::function<bool(const std::vector<Step>&)>& done) {
  std::vector<Step> steps;
  for (std::size_t s = 0; s < values.size(); ++s) {
    Step step;
    step.value = values[s];
    for (int m = 0; m < markers; ++m) {
      const Outcome o = trial(int(s), m);
      ++step.markers;
      step.found += o.found;
      step.wrong += o.wrong;
    }
    steps.push_back(step);
    if (done(steps)) break;
  }
  return steps;
}

std::function<bool(const std::vector<Step>&)> after_empty_steps(int count) {
  return [count](const std::vector<Step>& steps) {
    if (int(steps.size()) < count) return false;
    return std::all_of(steps.end() - count, steps.end(), [](const Step& s) { return s.found == 0; });
  };
}

std::vector<SystemSweep> sweep_systems(
    const std::vector<std::string>& names, int threads, std::uint64_t seed, const std::string& experiment,
    const lftag::Camera& camera, const std::vector<double>& values, int markers, int empty_steps,
    const std::function<Outcome(FiducialSystem&, const std::string&, int, int)>& trial) {
  std::vector<SystemSweep> out(names.size());
  parallel_for(int(names.size()), threads, [&](int s, int) {
    SystemSweep& sw = out[std::size_t(s)];
    sw.system = make_system(names[std::size_t(s)]);
    FiducialSystem& system = *sw.system;
    system.set_camera(camera, 1.0);
    const std::vector<std::string> ids = system.marker_ids(markers, seed);
    sw.steps = sweep(
        values, int(ids.size()), [&](int step, int m) { return trial(system, ids[std::size_t(m)], step, m); },
        after_empty_steps(empty_steps));
    progress(experiment + ": " + system.name() + " done");
  });
  return out;
}

Limits limits(const std::vector<Step>& steps) {
  Limits l;
  for (const Step& s : steps) {
    const int missed = s.markers - s.found;
    if (missed > 0 && std::isnan(l.first_missed)) l.first_missed = s.value;
    if (missed * 5 >= s.markers && missed > 0 && std::isnan(l.missed20)) l.missed20 = s.value;
    if (s.found > 0) l.last_found = s.value;
    l.wrong += s.wrong;
  }
  return l;
}

std::vector<double> arange(double start, double stop, double step) {
  std::vector<double> v;
  for (int i = 0;; ++i) {
    const double x = start + i * step;
    if (x > stop + step * 1e-6) break;
    v.push_back(std::round(x * 1e9) / 1e9);
  }
  return v;
}

}  // namespace bench
