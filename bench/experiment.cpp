// SPDX-License-Identifier: LGPL-2.1-or-later
#include "experiment.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <iostream>
#include <limits>
#include <mutex>
#include <thread>

namespace bench {

const std::vector<Experiment>& experiments() {
  static const std::vector<Experiment> all{
      {"check", "every system finds its own markers at 2 m with correct ids, centres and poses", run_check},
      {"range", "first-missed and 20 %-missed distance, the paper's camera and set-up", run_range},
      {"angle", "first-missed grazing angle at a fixed distance", run_angle},
      {"blur", "largest linear motion blur with every marker found, per blur angle", run_blur},
      {"pose", "rotation and translation error against distance and tilt", run_pose},
      {"ambiguity", "how often the planar pose's flip is chosen, by marker size and tilt, tuning and validation sets",
       run_ambiguity},
      {"fp", "false positives on marker-free real images (opencv-doc)", run_false_positives},
      {"video", "recall and pose error of moving markers composited into real video (1280x720, JPEG)", run_video},
      {"speed", "median time per 1280x720 and 1920x1080 frame, one thread", run_speed},
      {"adversarial",
       "time and recall on grids of dotted tiles that make thousands of candidates, against an ordinary frame",
       run_adversarial},
      {"field",
       "recall, wrong ids, pose error and time per condition (shadows, motion and rolling shutter, pillbox, "
       "barrel, low light, Bayer, bent, small at 1080p, crowded, occlusion, H.264), tuning and validation sets",
       run_field},
      {"tracking",
       "the video and field clips with LFTag's tracking off and on: recall (measured, predicted), wrong ids, "
       "wrong pose choices, jitter raw and smoothed, frame time against AprilTag 36h11 d2, both sets",
       run_tracking},
  };
  return all;
}

std::mt19937_64 seeded(std::uint64_t seed, std::initializer_list<std::uint64_t> path) {
  // splitmix64 steps fold the path into one well-mixed state.
  auto mix = [](std::uint64_t z) {
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  };
  std::uint64_t state = mix(seed);
  for (std::uint64_t p : path) state = mix(state ^ p);
  return std::mt19937_64(state);
}

void parallel_for(int count, int threads, const std::function<void(int, int)>& fn) {
  std::atomic<int> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&](int worker) {
    for (int i = next++; i < count; i = next++) {
      try {
        fn(i, worker);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = count;  // stop handing out work
      }
    }
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < threads; ++w) pool.emplace_back(work, w);
  work(0);
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const double pos = q * double(v.size() - 1);
  const std::size_t i = std::size_t(pos);
  return i + 1 < v.size() ? v[i] + (pos - double(i)) * (v[i + 1] - v[i]) : v[i];
}

void progress(const std::string& message) {
  static std::mutex mutex;
  std::lock_guard<std::mutex> lock(mutex);
  std::cerr << message << std::endl;
}

}  // namespace bench
