// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag detect: markers in image files, as JSON Lines (SPEC 5), one object per image.
#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "detection_json.hpp"
#include "lftag/detector.hpp"
#include "lftag/draw.hpp"
#include "lftag/image_file.hpp"
#include "lftag/trace.hpp"

namespace lftag::tools {
namespace {

nlohmann::json stats_json(const DetectionStats& s) {
  return {{"funnel",
           {{"regions", s.regions},
            {"topology", s.topology},
            {"area", s.area},
            {"geometry", s.geometry},
            {"angle", s.angle},
            {"collinearity", s.collinearity},
            {"residual", s.residual},
            {"unambiguous", s.unambiguous},
            {"decoded", s.decoded},
            {"unlisted", s.unlisted},
            {"bowed", s.bowed},
            {"second_looks", s.second_looks},
            {"second_look_found", s.second_look_found},
            {"outline_reads", s.outline_reads},
            {"outline_found", s.outline_found},
            {"outline_reads_skipped", s.outline_reads_skipped},
            {"borders", s.borders},
            {"border_found", s.border_found},
            {"skipped_by_budget", s.skipped_by_budget},
            {"second_looks_skipped", s.second_looks_skipped},
            {"past_deadline", s.past_deadline},
            {"skipped_by_deadline", s.skipped_by_deadline}}},
          {"time_ms",
           {{"threshold", s.threshold_ms},
            {"regions", s.regions_ms},
            {"candidates", s.candidates_ms},
            {"keypoints", s.keypoints_ms},
            {"hypotheses", s.hypotheses_ms},
            {"decode", s.decode_ms},
            {"pose", s.pose_ms},
            {"borders", s.borders_ms},
            {"second_look", s.second_look_ms},
            {"total", s.total_ms()}}}};
}

// One topological candidate and the stage that stopped it (--why).
nlohmann::json verdict_json(const CandidateVerdict& v) {
  cv::Point2d mean;
  for (const cv::Point2d& q : v.centroids) mean += q;
  mean *= 1.0 / std::max<std::size_t>(1, v.centroids.size());
  nlohmann::json out = {{"family", v.family.name()},
                        {"stage", stage_name(v.stage)},
                        {"second_look", v.second_look},
                        {"center", {mean.x, mean.y}},
                        {"centroids", io::points_json(v.centroids)}};
  if (v.reading) {
    out["reading"] = io::id_json(*v.reading);
    out["decode_error"] = v.decode_error;
    out["worst_cell"] = v.worst_cell;
    out["noise_margin"] = v.noise_margin;
  }
  return out;
}

// One outline read of a second look and the check that stopped it (--why).
nlohmann::json outline_json(const OutlineVerdict& v) {
  nlohmann::json out = {{"family", v.family.name()},
                        {"stage", stage_name(v.stage)},
                        {"outline", io::points_json({v.outline.begin(), v.outline.end()})},
                        {"correlation", v.correlation},
                        {"marker_correlation", v.marker_correlation},
                        {"contrast", v.contrast},
                        {"margin", v.margin},
                        {"noise_margin", v.noise_margin},
                        {"evidence", v.evidence},
                        {"listed_noise_margin", v.listed_noise_margin},
                        {"listed_evidence", v.listed_evidence},
                        {"model_ink", v.model_ink},
                        {"pixels_per_unit", v.pixels_per_unit},
                        {"smear", v.smear},
                        {"defocus", v.defocus}};
  if (v.reading) out["reading"] = io::id_json(*v.reading);
  if (v.border) out["border"] = true;
  return out;
}

// One quadrilateral black region and its fate as a border proposal (--why).
nlohmann::json border_json(const BorderVerdict& v) {
  return {{"family", v.family.name()},
          {"stage", stage_name(v.stage)},
          {"outline", io::points_json({v.outline.begin(), v.outline.end()})},
          {"contrast", v.contrast},
          {"noise", v.noise},
          {"ring", v.ring},
          {"darker_sides", v.darker_sides},
          {"structure", v.structure}};
}

}  // namespace

void add_detector_options(CLI::App* cmd, DetectorOptions& o) {
  cmd->add_option("--family", o.families, "Families to detect, comma-separated (default 3x3,4x4)");
  cmd->add_option("--ids", o.ids,
                  "The ids in use, comma-separated, with ranges (for example 0-49,100): a marker read as another id "
                  "is not reported. Each must be an id of one of the families (default: every id)");
  PinholeSettings& pin = o.pinhole;
  cmd->add_option("--fx", pin.fx, "Focal length in pixels (x)")->check(finite_in(Camera::kMinFocal, Camera::kMaxFocal));
  cmd->add_option("--fy", pin.fy, "Focal length in pixels (y; default fx)")
      ->check(finite_in(Camera::kMinFocal, Camera::kMaxFocal));
  cmd->add_option("--cx", pin.cx, "Principal point x (default: image centre)")
      ->check(finite_in(-Camera::kMaxPrincipal, Camera::kMaxPrincipal));
  cmd->add_option("--cy", pin.cy, "Principal point y (default: image centre)")
      ->check(finite_in(-Camera::kMaxPrincipal, Camera::kMaxPrincipal));
  cmd->add_option("--calibration", o.calibration,
                  "OpenCV calibration file (YAML/XML/JSON: camera_matrix + distortion_coefficients, or "
                  "cameraMatrix + distCoeffs). Without a camera, poses assume fx = image width and are "
                  "marked \"calibrated\": false");
  cmd->add_option("--tag-size", o.tag_size, "Outer edge of the black border in metres (default 0.1)")
      ->check(finite_in(1e-6, 1e3));
  for (const io::Tunable& t : io::tunables()) {
    const std::string name = std::string("--") + t.name;
    const double initial = t.get(o.params);
    DetectorParams* params = &o.params;
    const io::Tunable* row = &t;
    CLI::Option* option = nullptr;
    switch (t.kind) {
      case io::Tunable::Kind::integer:
        option = cmd->add_option_function<int>(
                        name, [params, row](int v) { row->set(*params, v); }, t.blurb)
                     ->check(CLI::Range(int(t.min), int(t.max)));
        option->default_str(std::to_string(int(initial)));
        break;
      case io::Tunable::Kind::real:
        option = cmd->add_option_function<double>(
                        name, [params, row](double v) { row->set(*params, v); }, t.blurb)
                     ->check(finite_in(t.min, t.max));
        option->default_str(CLI::detail::to_string(initial));
        break;
      case io::Tunable::Kind::boolean:
        option = cmd->add_option_function<bool>(
            name, [params, row](bool v) { row->set(*params, v); }, t.blurb);
        option->default_str(initial != 0 ? "true" : "false");
        break;
    }
  }
}

void set_families_and_ids(const DetectorOptions& o, DetectorParams& params) {
  params.families = Family::parse_list(o.families);
  try {
    params.ids = o.ids.empty() ? std::vector<TagId>() : parse_id_list(o.ids);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("--ids: ") + e.what());
  }
  params.validate();  // each id is one of a family's
}

void check_camera_options(const DetectorOptions& o) {
  const PinholeSettings& pin = o.pinhole;
  if (!pin.fx && (pin.fy || pin.cx || pin.cy)) throw std::invalid_argument("--fy, --cx and --cy need --fx");
}

void add_detect_command(CLI::App& app, int& status) {
  struct Options : DetectorOptions {
    std::vector<std::string> images;
    std::string debug_dir;
    bool stats = false, why = false;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd =
      app.add_subcommand("detect", "Detect markers in images; prints one JSON object per image (JSON Lines).");
  cmd->add_option("images", opt->images, "Image files (PNG, JPEG and every format OpenCV reads)")->required();
  add_detector_options(cmd, *opt);
  cmd->add_flag("--stats", opt->stats,
                "Add the candidate funnel (with the candidates and second looks the budget skipped) and "
                "per-stage times to each object");
  cmd->add_flag("--why", opt->why,
                "Add \"candidates\": every topological candidate with the stage that stopped it (area, "
                "budget, deadline, geometry, angle, collinearity, resolution, decoding, margin, ink, pose, duplicate, "
                "unlisted) or "
                "\"detected\"");
  cmd->add_option("--debug-dir", opt->debug_dir,
                  "Write each image's stages there: threshold, candidates, keypoints, hypotheses, final");
  cmd->callback([opt, &status] {
    DetectorParams base = opt->params;
    try {
      set_families_and_ids(*opt, base);
      base.tag_size = opt->tag_size;
      check_camera_options(*opt);
      if (!opt->calibration.empty()) base.camera = Camera::load(opt->calibration);
      if (!opt->debug_dir.empty()) std::filesystem::create_directories(opt->debug_dir);
      base.validate();  // the hand-set camera's numbers passed the options' checks
    } catch (const std::exception& e) {
      std::cerr << "lftag detect: " << e.what() << "\n";
      status = 2;
      return;
    }

    // One detector per frame size: its buffers and camera follow the size.
    std::map<std::pair<int, int>, Detector> detectors;
    DetectionStats total;
    int failed = 0;
    for (const std::string& path : opt->images) {
      nlohmann::json out = {{"image", path}};
      try {
        const cv::Mat grey = read_grey_image(path);
        out["width"] = grey.cols;
        out["height"] = grey.rows;
        auto it = detectors.find({grey.cols, grey.rows});
        if (it == detectors.end()) {
          DetectorParams p = base;
          if (!p.camera) p.camera = opt->pinhole.camera_for(grey.cols, grey.rows);
          it = detectors.emplace(std::make_pair(grey.cols, grey.rows), Detector(p)).first;
        }
        DetectionStats stats;
        DetectionTrace trace;
        const auto start = std::chrono::steady_clock::now();
        const std::vector<Detection> found =
            it->second.detect(ImageView(grey), &stats, opt->debug_dir.empty() && !opt->why ? nullptr : &trace);
        out["time_ms"] = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        out["detections"] = nlohmann::json::array();
        for (const Detection& d : found) out["detections"].push_back(io::detection_json(d));
        if (opt->stats) out["stats"] = stats_json(stats);
        if (opt->why) {
          out["noise"] = trace.noise;
          out["candidates"] = nlohmann::json::array();
          for (const CandidateVerdict& v : trace.verdicts) out["candidates"].push_back(verdict_json(v));
          out["outline_reads"] = nlohmann::json::array();
          for (const OutlineVerdict& v : trace.outline_reads) out["outline_reads"].push_back(outline_json(v));
          out["borders"] = nlohmann::json::array();
          for (const BorderVerdict& v : trace.borders) out["borders"].push_back(border_json(v));
        }
        total += stats;
        if (!opt->debug_dir.empty()) {
          const std::optional<Camera>& given = it->second.params().camera;
          const Camera camera =
              given ? given->for_frame(grey.cols, grey.rows) : Camera::default_for(grey.cols, grey.rows);
          const std::string stem = std::filesystem::path(path).stem().string();
          for (const auto& [stage, image] : draw_trace(grey, trace, camera)) {
            const std::string file = (std::filesystem::path(opt->debug_dir) / (stem + "-" + stage + ".png")).string();
            if (!cv::imwrite(file, image)) throw std::runtime_error("cannot write debug image '" + file + "'");
          }
        }
      } catch (const cv::Exception& e) {
        out["error"] = e.err;
      } catch (const std::exception& e) {
        out["error"] = e.what();
      }
      if (out.contains("error")) ++failed;
      std::cout << out.dump() << "\n" << std::flush;
    }
    if (opt->stats)
      std::cerr << "lftag detect: " << total.frames << " images, funnel " << total.topology << " -> " << total.area
                << " -> " << total.geometry << " -> " << total.angle << " -> " << total.collinearity << " -> "
                << total.residual << " -> " << total.unambiguous << " -> " << total.decoded << ", mean "
                << total.total_ms() / std::max<std::int64_t>(1, total.frames)
                << " ms per image; over budget: " << total.skipped_by_budget << " candidates and "
                << total.second_looks_skipped << " second looks skipped; past the deadline: " << total.past_deadline
                << " images, " << total.skipped_by_deadline << " steps skipped\n";
    if (failed) std::cerr << "lftag detect: " << failed << " of " << opt->images.size() << " images failed\n";
    status = failed ? 1 : 0;
  });
}

}  // namespace lftag::tools
