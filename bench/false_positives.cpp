// SPDX-License-Identifier: LGPL-2.1-or-later
// False positives on marker-free real images (the paper's LabelMe tables, on a smaller
// set): every photo and every video frame that opencv-doc installs, plus seeded crops,
// scales and flips of them, at 640x480 and 1280x720. Every detection is a false positive.
// Systems with counters (LFTag's funnel of candidates per constraint) report them too.
#include <algorithm>
#include <map>
#include <mutex>
#include <tuple>

#include <opencv2/imgproc.hpp>

#include "csv.hpp"
#include "experiment.hpp"
#include "sources.hpp"
#include "systems.hpp"

namespace bench {
namespace {

const std::vector<cv::Size> kSizes{{640, 480}, {1280, 720}};
constexpr int kFullFrames = 5000, kQuickFrames = 40;  // per frame size: 10,000 frames in a full run

// Frame `index` of one size: base frame (a photo or one video frame) and how to vary it.
struct Spec {
  int index, source, frame, pass;
};

// Every base frame once per pass, in a seeded order per pass, so that a short run still
// samples every source. Sorted for reading: videos are read forward.
std::vector<Spec> plan_frames(const std::vector<Source>& sources, int size_index, int count, std::uint64_t seed) {
  std::vector<std::pair<int, int>> base;
  for (int s = 0; s < int(sources.size()); ++s)
    for (int f = 0; f < sources[s].frames; ++f) base.emplace_back(s, f);
  std::vector<Spec> specs;
  for (int pass = 0; int(specs.size()) < count; ++pass) {
    std::vector<std::pair<int, int>> order = base;
    std::mt19937_64 rng = seeded(seed, {0xf9, std::uint64_t(size_index), std::uint64_t(pass)});
    std::shuffle(order.begin(), order.end(), rng);
    for (std::size_t i = 0; i < order.size() && int(specs.size()) < count; ++i)
      specs.push_back({int(specs.size()), order[i].first, order[i].second, pass});
  }
  std::sort(specs.begin(), specs.end(), [](const Spec& a, const Spec& b) {
    return std::tie(a.source, a.frame, a.pass) < std::tie(b.source, b.frame, b.pass);
  });
  return specs;
}

// The first pass shows each base frame whole (scaled to cover the frame size); later
// passes a random crop of 25-100 % of the largest one with the frame's aspect ratio,
// so scaled up to 4 times, and flipped at random.
cv::Mat1b make_frame(const cv::Mat1b& base, const Spec& spec, cv::Size size, int size_index, std::uint64_t seed,
                     std::string& description) {
  if (spec.pass == 0) {
    description += " whole";
    return cover(base, size);
  }
  std::mt19937_64 rng = seeded(seed, {0xf9c, std::uint64_t(size_index), std::uint64_t(spec.index)});
  const double aspect = double(size.width) / size.height;
  const double max_w = std::min(double(base.cols), base.rows * aspect);
  const double f = std::uniform_real_distribution<double>(0.25, 1.0)(rng);
  const int w = std::max(8, int(max_w * f)), h = std::max(8, int(w / aspect));
  const int x = std::uniform_int_distribution<int>(0, base.cols - w)(rng);
  const int y = std::uniform_int_distribution<int>(0, base.rows - h)(rng);
  const int flip = std::uniform_int_distribution<int>(0, 3)(rng);  // none, horizontal, vertical, both
  cv::Mat1b frame;
  cv::resize(base(cv::Rect(x, y, w, h)), frame, size, 0, 0, w > size.width ? cv::INTER_AREA : cv::INTER_LINEAR);
  if (flip) cv::flip(frame, frame, flip == 1 ? 1 : flip == 2 ? 0 : -1);
  description += " crop " + std::to_string(x) + "," + std::to_string(y) + "," + std::to_string(w) + "x" +
                 std::to_string(h) +
                 (flip == 1   ? " flip h"
                  : flip == 2 ? " flip v"
                  : flip == 3 ? " flip hv"
                              : "");
  return frame;
}

}  // namespace

bool run_false_positives(const Options& options) {
  const std::vector<Source> sources = list_sources(options.data);
  const int count = options.quick ? kQuickFrames : kFullFrames;
  Csv summary_csv(options.out / "fp_summary.csv", {"system", "family", "dictionary_size", "width", "height", "frames",
                                                   "false_positives", "frames_with_false_positives"});
  Csv detections_csv(options.out / "fp_detections.csv",
                     {"system", "width", "height", "frame", "id", "center_x", "center_y"});
  Csv counters_csv(options.out / "fp_counters.csv", {"system", "width", "height", "frames", "counter", "value"});
  const int n = int(options.systems.size());

  for (int z = 0; z < int(kSizes.size()); ++z) {
    const cv::Size size = kSizes[z];
    const std::vector<Spec> specs = plan_frames(sources, z, count, options.seed);
    FrameReader reader(sources);
    std::mutex mutex;  // guards the reader, the next spec and the tallies
    std::size_t next = 0;
    std::vector<long> detections(n, 0), frames_hit(n, 0);
    std::vector<std::map<std::string, double>> counters(n);
    std::vector<std::string> families(n), dictionary(n);
    parallel_for(options.threads, options.threads, [&](int, int) {
      std::vector<std::unique_ptr<FiducialSystem>> systems;
      for (const std::string& name : options.systems) {
        systems.push_back(make_system(name));
        systems.back()->set_camera(lftag::Camera::default_for(size.width, size.height), 0.1);
        systems.back()->reset_counters();
      }
      for (;;) {
        Spec spec;
        cv::Mat1b base;
        {
          std::lock_guard<std::mutex> lock(mutex);
          if (next == specs.size()) break;
          spec = specs[next++];
          base = reader.read(spec.source, spec.frame);
          if (next % 500 == 0)
            progress("fp " + std::to_string(size.width) + "x" + std::to_string(size.height) + ": " +
                     std::to_string(next) + " / " + std::to_string(specs.size()) + " frames");
        }
        const Source& src = sources[spec.source];
        std::string description = src.path.filename().string() + (src.video ? "#" + std::to_string(spec.frame) : "");
        const cv::Mat1b frame = make_frame(base, spec, size, z, options.seed, description);
        for (int s = 0; s < n; ++s) {
          const std::vector<Detected> found = systems[s]->detect(frame);
          if (found.empty()) continue;
          std::lock_guard<std::mutex> lock(mutex);
          detections[s] += long(found.size());
          ++frames_hit[s];
          for (const Detected& d : found)
            detections_csv.row(systems[s]->name(), size.width, size.height, description, d.id, d.center.x, d.center.y);
        }
      }
      std::lock_guard<std::mutex> lock(mutex);
      for (int s = 0; s < n; ++s) {
        for (const auto& [name, value] : systems[s]->counters()) counters[s][name] += value;
        families[s] = systems[s]->family();
        dictionary[s] = systems[s]->dictionary_size();
      }
    });
    for (int s = 0; s < n; ++s) {
      summary_csv.row(options.systems[s], families[s], dictionary[s], size.width, size.height, int(specs.size()),
                      detections[s], frames_hit[s]);
      for (const auto& [name, value] : counters[s])
        counters_csv.row(options.systems[s], size.width, size.height, int(specs.size()), name, value);
    }
  }
  return true;
}

}  // namespace bench
