// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag render: a synthetic camera frame of markers (PNG) and its ground truth (JSON).
#include <cmath>
#include <fstream>
#include <iostream>
#include <optional>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "detection_json.hpp"
#include "lftag/image_file.hpp"
#include "lftag/render.hpp"

namespace lftag::tools {
namespace {

cv::Vec3d vec3(const nlohmann::json& j, const char* name) {
  if (!j.is_array() || j.size() != 3) throw std::invalid_argument(std::string("'") + name + "' must be [x, y, z]");
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

// Markers from a scene file: {"markers": [{"family": "3x3", "id": 5, "tag_size": 1,
// "tvec": [x, y, z], "rvec": [..] or "roll"/"tilt"/"pan" in degrees}, ...]}
std::vector<SceneMarker> read_scene(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open scene file '" + path + "'");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception& e) {
    throw std::runtime_error("scene file '" + path + "' is not JSON: " + e.what());
  }
  std::vector<SceneMarker> markers;
  for (const nlohmann::json& m : j.at("markers")) {
    SceneMarker s;
    s.family = Family::parse(m.at("family").get<std::string>());
    const nlohmann::json& id = m.at("id");
    s.id = id.is_string() ? TagId::parse(id.get<std::string>()) : TagId(id.get<std::uint64_t>());
    s.family.require(s.id);
    s.tag_size = m.value("tag_size", 1.0);
    s.tvec = vec3(m.at("tvec"), "tvec");
    s.rvec = m.contains("rvec") ? vec3(m["rvec"], "rvec")
                                : rotation_from_angles(m.value("roll", 0.0), m.value("tilt", 0.0), m.value("pan", 0.0));
    markers.push_back(s);
  }
  return markers;
}

nlohmann::json truth_json(const MarkerTruth& t) {
  return {{"family", t.family.name()},
          {"id", io::id_json(t.id)},
          {"tag_size", t.tag_size},
          {"rvec", io::vec_json(t.rvec)},
          {"tvec", io::vec_json(t.tvec)},
          {"keypoints", io::points_json(t.keypoints)},
          {"centers", io::points_json(t.centers)},
          {"corners", io::points_json(t.corners)},
          {"fully_visible", t.fully_visible},
          {"edge_px", t.edge_px}};
}

}  // namespace

void add_render_command(CLI::App& app, int& status) {
  struct Options {
    int width = 640, height = 480;
    double fx = 320, fy = 320;
    std::optional<double> cx, cy;  // empty: the frame centre
    std::vector<double> distortion;
    std::string calibration, family = "3x3", id = "0", scene, photo, output, truth;
    double tag_size = 1.0, distance = 5.0, x = 0, y = 0, roll = 0, tilt = 0, pan = 0;
    double blur = 0, blur_angle = 0, noise = 0, background = 0.5, light_gradient = 0;
    int supersample = 8, margin = 2;
    std::uint64_t seed = 1;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd =
      app.add_subcommand("render", "Render a synthetic camera frame of markers (PNG) with its ground truth (JSON).");
  cmd->add_option("--width", opt->width, "Frame width in pixels (default 640)")->check(CLI::PositiveNumber);
  cmd->add_option("--height", opt->height, "Frame height in pixels (default 480)")->check(CLI::PositiveNumber);
  cmd->add_option("--fx", opt->fx, "Focal length in pixels along x (default 320)")
      ->check(finite_in(Camera::kMinFocal, Camera::kMaxFocal));
  cmd->add_option("--fy", opt->fy, "Focal length in pixels along y (default 320)")
      ->check(finite_in(Camera::kMinFocal, Camera::kMaxFocal));
  cmd->add_option("--cx", opt->cx, "Principal point x (default: frame centre)")
      ->check(finite_in(-Camera::kMaxPrincipal, Camera::kMaxPrincipal));
  cmd->add_option("--cy", opt->cy, "Principal point y (default: frame centre)")
      ->check(finite_in(-Camera::kMaxPrincipal, Camera::kMaxPrincipal));
  cmd->add_option("--distortion", opt->distortion, "Distortion k1,k2,p1,p2[,k3]")->delimiter(',');
  cmd->add_option("--calibration", opt->calibration, "OpenCV calibration file (YAML/XML); replaces the camera options");
  cmd->add_option("--family", opt->family, "Family of the single marker (default 3x3)");
  cmd->add_option("--id", opt->id, "Id of the single marker, decimal or 0x-hexadecimal (default 0)");
  cmd->add_option("--tag-size", opt->tag_size, "Outer edge of the black border in metres (default 1)")
      ->check(finite_in(1e-6, 1e3));
  cmd->add_option("--distance", opt->distance, "Distance of the marker centre along the optical axis, m (default 5)")
      ->check(finite_in(1e-6, 1e6));
  cmd->add_option("--x", opt->x, "Sideways offset of the marker centre, m (default 0)")->check(finite_in(-1e6, 1e6));
  cmd->add_option("--y", opt->y, "Downward offset of the marker centre, m (default 0)")->check(finite_in(-1e6, 1e6));
  cmd->add_option("--roll", opt->roll, "In-plane rotation, degrees (default 0)")->check(finite_in(-1e4, 1e4));
  cmd->add_option("--tilt", opt->tilt, "Rotation about the camera's x axis, degrees (default 0)")
      ->check(finite_in(-1e4, 1e4));
  cmd->add_option("--pan", opt->pan, "Rotation about the camera's y axis, degrees (default 0)")
      ->check(finite_in(-1e4, 1e4));
  cmd->add_option("--margin", opt->margin, "White margin around the marker, whole units (default 2)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--scene", opt->scene,
                  "JSON file of several markers: {\"markers\": [{\"family\", \"id\", \"tag_size\", \"tvec\", "
                  "\"rvec\" or \"roll\"/\"tilt\"/\"pan\"}]}; replaces the single-marker options");
  cmd->add_option("--blur", opt->blur, "Linear motion blur length in pixels (default 0)")->check(finite_in(0, 1e4));
  cmd->add_option("--blur-angle", opt->blur_angle, "Motion blur direction, degrees: 0 vertical, 90 horizontal")
      ->check(finite_in(-1e4, 1e4));
  cmd->add_option("--noise", opt->noise, "Gaussian noise sigma in grey levels (default 0)")->check(finite_in(0, 1e4));
  cmd->add_option("--seed", opt->seed, "Noise seed (default 1)");
  cmd->add_option("--background", opt->background, "Flat background albedo 0..1 (default 0.5)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--photo", opt->photo, "Background photo (any format OpenCV reads), scaled to cover the frame");
  cmd->add_option("--light-gradient", opt->light_gradient,
                  "Illumination change across the frame, e.g. 0.5 for +-25 % (default 0)");
  cmd->add_option("--supersample", opt->supersample, "Samples per pixel edge at marker edges (default 8)")
      ->check(CLI::Range(1, 64));
  cmd->add_option("--output,-o", opt->output, "Output image (.png)")->required();
  cmd->add_option("--truth", opt->truth, "Ground-truth JSON file (default: the output name with .json)");
  cmd->callback([opt, &status] {
    try {
      SceneParams p;
      if (!opt->calibration.empty()) {
        p.camera = Camera::load(opt->calibration).for_frame(opt->width, opt->height);
      } else {
        p.camera = Camera::pinhole(opt->fx, opt->fy, opt->cx.value_or((opt->width - 1) / 2.0),
                                   opt->cy.value_or((opt->height - 1) / 2.0), opt->width, opt->height);
        p.camera.distortion = opt->distortion;
        if (!opt->distortion.empty() && opt->distortion.size() != 4 && opt->distortion.size() != 5)
          throw std::invalid_argument("--distortion takes 4 or 5 coefficients: k1,k2,p1,p2[,k3]");
      }
      p.camera.validate();
      p.supersample = opt->supersample;
      p.background = opt->background;
      p.light_gradient = opt->light_gradient;
      p.blur_length_px = opt->blur;
      p.blur_angle_deg = opt->blur_angle;
      p.noise_sigma = opt->noise;
      p.seed = opt->seed;
      if (!opt->photo.empty()) {
        p.photo = read_grey_image(opt->photo);
      }
      std::vector<SceneMarker> markers;
      if (!opt->scene.empty()) {
        markers = read_scene(opt->scene);
      } else {
        SceneMarker m;
        m.family = Family::parse(opt->family);
        m.id = TagId::parse(opt->id);
        m.family.require(m.id);
        m.tag_size = opt->tag_size;
        m.tvec = {opt->x, opt->y, opt->distance};
        m.rvec = rotation_from_angles(opt->roll, opt->tilt, opt->pan);
        markers.push_back(m);
      }
      for (SceneMarker& m : markers) m.margin_units = opt->margin;
      const RenderedScene scene = render_scene(p, markers);
      if (!cv::imwrite(opt->output, scene.image)) throw std::runtime_error("cannot write image '" + opt->output + "'");
      std::string truth_path = opt->truth;
      if (truth_path.empty()) {
        const std::size_t dot = opt->output.rfind('.');
        truth_path = (dot == std::string::npos ? opt->output : opt->output.substr(0, dot)) + ".json";
      }
      nlohmann::json truth = {{"image", opt->output},
                              {"width", opt->width},
                              {"height", opt->height},
                              {"camera",
                               {{"fx", p.camera.fx},
                                {"fy", p.camera.fy},
                                {"cx", p.camera.cx},
                                {"cy", p.camera.cy},
                                {"distortion", p.camera.distortion}}},
                              {"markers", nlohmann::json::array()}};
      for (const MarkerTruth& t : scene.truth) truth["markers"].push_back(truth_json(t));
      std::ofstream out(truth_path);
      if (!(out << truth.dump(2) << "\n")) throw std::runtime_error("cannot write truth '" + truth_path + "'");
      status = 0;
    } catch (const cv::Exception& e) {
      std::cerr << "lftag render: " << e.err << "\n";
      status = 1;
    } catch (const std::exception& e) {
      std::cerr << "lftag render: " << e.what() << "\n";
      status = 1;
    }
  });
}

}  // namespace lftag::tools
