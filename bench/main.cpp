// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag-bench: runs the named experiments (all by default) and writes their results as
// CSV files, plus meta.json describing the run, into the results directory.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "experiment.hpp"
#include "systems.hpp"

namespace {

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  return text;
}

int run(int argc, char** argv) {
  CLI::App app("Benchmarks of fiducial systems on the same rendered and real frames.");
  bench::Options options;
  std::vector<std::string> names;
  std::string systems, conditions, save_misses, out = "bench-results", data = "/usr/share/doc/opencv-doc/examples/data";
  bool list = false;
  options.threads = int(std::max(1u, std::thread::hardware_concurrency()));
  app.add_option("experiments", names, "Experiments to run (default: all; see --list)");
  app.add_flag("--quick", options.quick, "Reduced form of every experiment (CI; numbers are indicative only)");
  app.add_flag("--acceptance", options.acceptance,
               "field: the acceptance test's plan (2 clips of 5 frames per condition and set), not timed");
  app.add_option("--out", out, "Results directory (default: bench-results)");
  app.add_option("--systems", systems, "Comma-separated system names or prefixes (default: all)");
  app.add_option("--data", data, "opencv-doc's examples/data directory (false positives, speed)");
  app.add_option("--threads", options.threads, "Worker threads for the accuracy experiments; timing uses one")
      ->check(CLI::Range(1, 64));
  app.add_option("--seed", options.seed, "Seed of every random choice (default 1)");
  app.add_option(
      "--save-misses", save_misses,
      "Write each video, range, blur or field frame where a system missed a marker (field: or read a wrong id) "
      "to this directory (PNG)");
  app.add_option("--conditions", conditions,
                 "Comma-separated conditions of the field and tracking experiments (default: all)");
  app.add_flag("--list", list, "List experiments and systems, then exit");
  CLI11_PARSE(app, argc, argv);

  if (list) {
    for (const bench::Experiment& e : bench::experiments()) std::cout << e.name << "\t" << e.what << "\n";
    for (const std::string& s : bench::system_names()) std::cout << "system\t" << s << "\n";
    return 0;
  }
  std::vector<bench::Experiment> chosen;
  for (const bench::Experiment& e : bench::experiments())
    if (names.empty() || std::find(names.begin(), names.end(), e.name) != names.end()) chosen.push_back(e);
  for (const std::string& n : names)
    if (std::none_of(chosen.begin(), chosen.end(), [&](const bench::Experiment& e) { return n == e.name; }))
      throw std::invalid_argument("unknown experiment '" + n + "' (see --list)");

  options.systems = bench::select_systems(systems);
  options.out = out;
  options.data = data;
  options.save_misses = save_misses;
  for (std::size_t start = 0; !conditions.empty() && start <= conditions.size();) {
    const std::size_t comma = std::min(conditions.find(',', start), conditions.size());
    options.conditions.push_back(conditions.substr(start, comma - start));
    start = comma + 1;
  }
  std::filesystem::create_directories(options.out);
  if (!save_misses.empty()) std::filesystem::create_directories(save_misses);
  // OpenCV's own threads would blur timings and compete with ours.
  cv::setNumThreads(1);

  // meta.json describes the machine and, per experiment, the run that last wrote its
  // files: running one experiment again keeps the others' entries.
  nlohmann::json meta = nlohmann::json::object();
  if (std::ifstream in(options.out / "meta.json"); in) meta = nlohmann::json::parse(in, nullptr, false);
  if (!meta.is_object() || !meta.contains("experiments")) meta = {{"experiments", nlohmann::json::object()}};
  meta.update({{"mode", options.quick ? "quick" : "full"},
               {"date", utc_now()},
               {"cpu", cpu_model()},
               {"hardware_threads", std::thread::hardware_concurrency()},
               {"worker_threads", options.threads},
               {"opencv", CV_VERSION},
               {"apriltag", BENCH_APRILTAG_VERSION},
               {"seed", options.seed},
               {"systems", options.systems}});
  bool ok = true;
  for (const bench::Experiment& e : chosen) {
    bench::progress(std::string("== ") + e.name + ": " + e.what);
    const auto start = std::chrono::steady_clock::now();
    const bool passed = e.run(options);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    bench::progress(std::string("== ") + e.name + (passed ? " done" : " FAILED") + " in " +
                    std::to_string(int(seconds + 0.5)) + " s");
    meta["experiments"][e.name] = {{"seconds", seconds},
                                   {"passed", passed},
                                   {"date", meta["date"]},
                                   {"mode", meta["mode"]},
                                   {"systems", options.systems}};
    ok = ok && passed;
    std::ofstream(options.out / "meta.json") << meta.dump(2) << "\n";
  }
  return ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "lftag-bench: " << e.what() << "\n";
    return 2;
  }
}
