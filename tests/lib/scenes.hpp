// SPDX-License-Identifier: LGPL-2.1-or-later
// Helpers shared by the tests that render scenes.
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/render.hpp"

namespace lftag::test {

inline cv::Vec3d rotation(double roll, double tilt, double pan) { return rotation_from_angles(roll, tilt, pan); }

inline TagId random_id(const Family& f, std::mt19937_64& rng) {
  TagId id;
  for (int k = 0; k < f.data_cell_count(); ++k) id = id.with_digit(k, int(rng() & 3));
  return id;
}

// The paper's simulation camera: 640x480, fx = fy = 320.
inline Camera paper_camera() { return Camera::pinhole(320, 320, 319.5, 239.5, 640, 480); }

// Angle between two rotation vectors, degrees.
inline double rotation_error_deg(const cv::Vec3d& a, const cv::Vec3d& b) {
  cv::Matx33d ra, rb;
  cv::Rodrigues(a, ra);
  cv::Rodrigues(b, rb);
  cv::Vec3d d;
  cv::Rodrigues(ra.t() * rb, d);
  return cv::norm(d) * 180 / CV_PI;
}

// One marker rendered with its truth and its homography (units -> pixels, from the true
// outer corners; exact where the camera has no distortion).
struct RenderedMarker {
  SceneMarker marker;
  MarkerTruth truth;
  cv::Mat1b image;
  cv::Matx33d homography;
};

// How it is seen: defocused by `defocus` px (Gaussian), lit by a gradient of `gradient`
// across the frame, its light raised to the power `gamma` before quantising, on a flat
// `background` with a white margin of `margin_units`, near `at` (px from the centre).
struct Look {
  double defocus = 0, gradient = 0, gamma = 1, background = 0.45, margin_units = 2;
  cv::Point2d at;
};

// A random marker of family n, `pixels` across at a random turn, tilt (up to 30 degrees)
// and sub-pixel place, with noise of 1 grey level.
inline RenderedMarker render_marker(const Camera& camera, int n, double pixels, const Look& look,
                                    std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  RenderedMarker r;
  r.marker.family = Family(n);
  r.marker.id = random_id(r.marker.family, rng);
  r.marker.tag_size = 0.1;
  r.marker.margin_units = look.margin_units;
  const double z = camera.fx * 0.1 / pixels;
  r.marker.tvec = {(look.at.x + 0.4 * u(rng)) * z / camera.fx, (look.at.y + 0.4 * u(rng)) * z / camera.fx, z};
  r.marker.rvec = rotation(180 * u(rng), 30 * u(rng), 30 * u(rng));
  SceneParams p;
  p.camera = camera;
  p.background = look.background;
  p.light_gradient = look.gradient;
  p.light_angle_deg = 360 * u(rng);
  p.noise_sigma = 1;
  const SceneRenderer renderer(p);
  cv::Mat1f linear = renderer.render_linear({to_target(r.marker)});
  if (look.defocus > 0) cv::GaussianBlur(linear, linear, cv::Size(), look.defocus);
  if (look.gamma != 1) {  // grey levels 0..255
    cv::pow(linear / 255, look.gamma, linear);
    linear *= 255;
  }
  r.image = renderer.quantize(linear, rng());
  r.truth = make_truth(camera, r.marker);
  const double s = r.marker.family.side();
  const std::vector<cv::Point2f> units{{0, 0}, {float(s), 0}, {float(s), float(s)}, {0, float(s)}};
  const std::vector<cv::Point2f> corners(r.truth.corners.begin(), r.truth.corners.end());
  r.homography = cv::Matx33d(cv::getPerspectiveTransform(units, corners));
  return r;
}

}  // namespace lftag::test
