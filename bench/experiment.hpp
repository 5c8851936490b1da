// SPDX-License-Identifier: LGPL-2.1-or-later
// What every experiment shares: the run options, the list of experiments, seeded
// randomness and a small thread pool.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace bench {

struct Options {
  bool quick = false;                // reduced form of every experiment (CI, smoke runs)
  bool acceptance = false;           // field: the acceptance test's plan (bench/test_field.py)
  std::filesystem::path out;         // results directory
  std::vector<std::string> systems;  // selected system names
  std::filesystem::path data;        // opencv-doc's examples/data
  int threads = 1;                   // worker threads (never used for timing)
  std::uint64_t seed = 1;
  std::filesystem::path save_misses;    // when set: the video and range frames where a system missed a marker
  std::vector<std::string> conditions;  // the field (and tracking) experiment's conditions to run (empty: all)
};

// An experiment writes its CSV files into options.out and returns false when a check it
// makes failed (only the "check" experiment makes any).
struct Experiment {
  const char* name;
  const char* what;
  bool (*run)(const Options&);
};
const std::vector<Experiment>& experiments();

bool run_check(const Options& options);
bool run_range(const Options& options);
bool run_angle(const Options& options);
bool run_blur(const Options& options);
bool run_pose(const Options& options);
bool run_ambiguity(const Options& options);
bool run_false_positives(const Options& options);
bool run_video(const Options& options);
bool run_speed(const Options& options);
bool run_adversarial(const Options& options);
bool run_field(const Options& options);
bool run_tracking(const Options& options);

// A generator seeded from the run seed and a path of indices, so that every system sees
// the same random poses and frames whatever the thread and order.
std::mt19937_64 seeded(std::uint64_t seed, std::initializer_list<std::uint64_t> path);

// Calls fn(index, worker) for index in [0, count) on `threads` threads (worker in
// [0, threads)). Rethrows the first exception after all threads have stopped.
void parallel_for(int count, int threads, const std::function<void(int index, int worker)>& fn);

// The q-quantile (0..1) of `values` by linear interpolation; NaN when empty.
double quantile(std::vector<double> values, double q);

// Progress on stderr, so that long runs show they are alive.
void progress(const std::string& message);

}  // namespace bench
