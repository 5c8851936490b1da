// SPDX-License-Identifier: LGPL-2.1-or-later
// Speed (the paper's performance table): time per frame of every system, one thread, on
// the same 1280x720 and 1920x1080 frames in the same run. Two frame sets: rendered scenes
// with one marker of each family on a photo, and frames of opencv-doc's videos. Each
// system's pose estimation is part of its time, as in the paper. Reference points on the
// same frames: a 16x16 mean adaptive threshold, and OpenCV's connectedComponentsWithStats
// labelling its binary image with each algorithm OpenCV offers.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "csv.hpp"
#include "experiment.hpp"
#include "sources.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

const std::vector<cv::Size> kSizes{{1280, 720}, {1920, 1080}};
constexpr double kTagSize = 0.1;  // metres

struct Plan {
  int frames;  // per frame set and size
  int passes;  // timed passes over the frames
};
constexpr Plan kFull{30, 3}, kQuick{3, 1};

struct Marker {
  std::string id;
  Pose pose;
};

struct Frame {
  cv::Mat1b image;
  std::map<std::string, Marker> markers;  // by family
};

// One marker of every family on a photo: a grid of cells, one marker per cell, each
// turned and tilted at random by up to 30 degrees and 35-55 % of its cell across.
std::vector<Frame> scene_frames(const std::vector<std::unique_ptr<FiducialSystem>>& systems,
                                const std::vector<Source>& sources, cv::Size size, int count, std::uint64_t seed) {
  std::map<std::string, const FiducialSystem*> by_family;
  for (const auto& s : systems) by_family.emplace(s->family(), s.get());
  std::vector<Source> photos;
  for (const Source& s : sources)
    if (!s.video) photos.push_back(s);
  const int m = int(by_family.size());
  const int cols = int(std::ceil(std::sqrt(m * double(size.width) / size.height))), rows = (m + cols - 1) / cols;
  const double cell_w = double(size.width) / cols, cell_h = double(size.height) / rows;
  lftag::SceneParams params;
  params.camera = lftag::Camera::default_for(size.width, size.height);
  std::vector<Frame> frames;
  for (int k = 0; k < count; ++k) {
    std::mt19937_64 rng = seeded(seed, {0x5eed, std::uint64_t(size.width), std::uint64_t(k)});
    std::uniform_real_distribution<double> unit(0, 1);
    params.photo = cv::imread(photos[rng() % photos.size()].path.string(), cv::IMREAD_GRAYSCALE);
    Frame frame;
    std::vector<lftag::SceneTarget> targets;
    int cell = 0;
    for (const auto& [family, system] : by_family) {
      const std::vector<std::string> ids = system->marker_ids(8, seed);
      const std::string id = ids[std::size_t(k) % ids.size()];
      const double edge = (0.35 + 0.2 * unit(rng)) * std::min(cell_w, cell_h);
      const cv::Point2d center((cell % cols + 0.4 + 0.2 * unit(rng)) * cell_w,
                               (cell / cols + 0.4 + 0.2 * unit(rng)) * cell_h);
      const cv::Vec3d rvec = lftag::rotation_from_angles(360 * unit(rng), 60 * unit(rng) - 30, 60 * unit(rng) - 30);
      const Pose pose = place(params.camera, center, params.camera.fx * kTagSize / edge, rvec);
      targets.push_back(system->target(id, kTagSize, pose.rvec, pose.tvec));
      frame.markers[family] = {id, pose};
      ++cell;
    }
    frame.image = lftag::SceneRenderer(params).render(targets);
    frames.push_back(std::move(frame));
  }
  return frames;
}

// Frames spread evenly over all frames of all videos.
std::vector<Frame> video_frames(const std::vector<Source>& sources, cv::Size size, int count) {
  std::vector<std::pair<int, int>> all;
  for (int s = 0; s < int(sources.size()); ++s)
    if (sources[s].video)
      for (int f = 0; f < sources[s].frames; ++f) all.emplace_back(s, f);
  FrameReader reader(sources);
  std::vector<Frame> frames;
  for (int k = 0; k < count && !all.empty(); ++k) {
    const auto [s, f] = all[std::size_t((k + 0.5) * double(all.size()) / count)];
    frames.push_back({cover(reader.read(s, f), size), {}});
  }
  return frames;
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The binary image an LFTag detector starts from: black where darker than the mean of
// the 16 x 16 window around the pixel.
void mean_threshold(const cv::Mat1b& grey, cv::Mat1b& mean, cv::Mat1b& binary) {
  cv::blur(grey, mean, cv::Size(16, 16), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  cv::compare(grey, mean, binary, cv::CMP_LT);
}

const std::vector<std::pair<std::string, int>> kLabelling{{"ccl-default", cv::CCL_DEFAULT},
                                                          {"ccl-sauf", cv::CCL_SAUF},
                                                          {"ccl-bbdt", cv::CCL_BBDT},
                                                          {"ccl-spaghetti", cv::CCL_SPAGHETTI}};

}  // namespace

bool run_speed(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  const std::vector<Source> sources = list_sources(options.data);
  std::vector<std::unique_ptr<FiducialSystem>> systems;
  for (const std::string& name : options.systems) systems.push_back(make_system(name));

  Csv speed_csv(options.out / "speed.csv", {"set", "width", "height", "system", "kind", "frames", "samples",
                                            "median_ms", "q1_ms", "q3_ms", "found_fraction", "note"});
  Csv ratios_csv(options.out / "speed_ratios.csv", {"set", "width", "height", "system", "reference", "ratio"});
  Csv counters_csv(options.out / "speed_counters.csv", {"set", "width", "height", "system", "counter", "per_frame"});

  for (const cv::Size size : kSizes) {
    const lftag::Camera camera = lftag::Camera::default_for(size.width, size.height);
    for (auto& s : systems) s->set_camera(camera, kTagSize);
    const std::vector<std::pair<std::string, std::vector<Frame>>> sets{
        {"scenes", scene_frames(systems, sources, size, plan.frames, options.seed)},
        {"video", video_frames(sources, size, plan.frames)}};
    for (const auto& [set, frames] : sets) {
      if (frames.empty()) continue;
      progress("speed: " + set + " " + std::to_string(size.width) + "x" + std::to_string(size.height));
      std::map<std::string, std::vector<double>> samples;  // by system or reference name
      std::vector<int> found(systems.size(), 0);
      cv::Mat1b mean, binary;
      cv::Mat labels, stats, centroids;
      // Warm-up: first calls allocate and fill caches.
      for (auto& s : systems) {
        s->detect(frames[0].image);
        s->reset_counters();
      }
      mean_threshold(frames[0].image, mean, binary);
      for (const auto& [name, algorithm] : kLabelling)
        cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S, algorithm);

      for (int pass = 0; pass < plan.passes; ++pass)
        for (std::size_t f = 0; f < frames.size(); ++f) {
          const Frame& frame = frames[f];
          // Rotate who goes first, so that no system always meets warm or cold caches.
          for (std::size_t i = 0; i < systems.size(); ++i) {
            const std::size_t k = (i + f + pass) % systems.size();
            FiducialSystem& system = *systems[k];
            const auto start = std::chrono::steady_clock::now();
            const std::vector<Detected> detections = system.detect(frame.image);
            samples[system.name()].push_back(elapsed_ms(start));
            const auto marker = frame.markers.find(system.family());
            if (pass == 0 && marker != frame.markers.end())
              found[k] += score(detections, marker->second.id, marker->second.pose, kTagSize, camera).found;
          }
          auto start = std::chrono::steady_clock::now();
          mean_threshold(frame.image, mean, binary);
          samples["mean-threshold-16"].push_back(elapsed_ms(start));
          for (const auto& [name, algorithm] : kLabelling) {
            start = std::chrono::steady_clock::now();
            cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S, algorithm);
            samples[name].push_back(elapsed_ms(start));
          }
        }

      // The fastest labelling algorithm, as its own reference row.
      std::string fastest;
      for (const auto& entry : kLabelling)
        if (fastest.empty() || quantile(samples[entry.first], 0.5) < quantile(samples[fastest], 0.5))
          fastest = entry.first;
      samples["ccl-fastest"] = samples[fastest];

      std::vector<std::string> rows;
      for (std::size_t k = 0; k < systems.size(); ++k) {
        const std::string name = systems[k]->name();
        rows.push_back(name);
        const bool scene = frames[0].markers.count(systems[k]->family()) > 0;
        const std::vector<double>& v = samples[name];
        speed_csv.row(set, size.width, size.height, name, "detector", int(frames.size()), int(v.size()),
                      quantile(v, 0.5), quantile(v, 0.25), quantile(v, 0.75),
                      scene ? double(found[k]) / double(frames.size()) : kNaN, "");
        for (const auto& [counter, value] : systems[k]->counters())
          counters_csv.row(set, size.width, size.height, name, counter, value / double(v.size()));
      }
      for (const std::string name :
           {"mean-threshold-16", "ccl-default", "ccl-sauf", "ccl-bbdt", "ccl-spaghetti", "ccl-fastest"}) {
        rows.push_back(name);
        const std::vector<double>& v = samples[name];
        speed_csv.row(set, size.width, size.height, name, "reference", int(frames.size()), int(v.size()),
                      quantile(v, 0.5), quantile(v, 0.25), quantile(v, 0.75), kNaN,
                      name == "ccl-fastest" ? "= " + fastest : std::string());
      }
      for (const std::string& a : rows)
        for (const std::string& b : rows)
          if (a != b)
            ratios_csv.row(set, size.width, size.height, a, b, quantile(samples[a], 0.5) / quantile(samples[b], 0.5));

      // The medians and the ratios users ask for first, on the terminal.
      const std::vector<std::string> peers = {"apriltag-36h11-d2", "apriltag-36h11-d1", "ccl-fastest"};
      std::printf("%s %dx%d: median ms per frame, and its ratio to", set.c_str(), size.width, size.height);
      for (const std::string& peer : peers)
        if (samples.count(peer)) std::printf(" %s", peer.c_str());
      std::printf("\n");
      for (const std::string& name : rows) {
        const double median = quantile(samples[name], 0.5);
        std::printf("  %-20s %9.3f", name.c_str(), median);
        for (const std::string& peer : peers)
          if (samples.count(peer)) std::printf(" %9.3f", median / quantile(samples[peer], 0.5));
        std::printf("\n");
      }
      std::fflush(stdout);
    }
  }
  return true;
}

}  // namespace bench
