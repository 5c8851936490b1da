// SPDX-License-Identifier: LGPL-2.1-or-later
// The subcommands of the `lftag` tool. Each registers itself on the app and, when it
// runs, stores its exit status in `status`.
#pragma once

#include <cmath>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

#include "lftag/detector.hpp"
#include "tunables.hpp"

namespace lftag::tools {

// An option check: a finite number from lo to hi ("nan", "inf" and overflowing values fail,
// which CLI11's own PositiveNumber lets through for NaN).
inline CLI::Validator finite_in(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v) || v < lo || v > hi)
          return "must be a finite number from " + CLI::detail::to_string(lo) + " to " + CLI::detail::to_string(hi);
        return {};
      },
      "NUMBER in [" + CLI::detail::to_string(lo) + ", " + CLI::detail::to_string(hi) + "]");
}

// The detector's options, the same in `lftag detect` and `lftag annotate`. A camera
// option not given is empty (never a number standing for "not given": --cx 0 is 0).
struct DetectorOptions {
  std::string families = "3x3,4x4", calibration;
  std::string ids;          // --ids: the ids in use (empty: every id)
  PinholeSettings pinhole;  // --fx, --fy, --cx, --cy (no distortion: it comes with --calibration)
  double tag_size = 0.1;
  // The tunables (io/tunables.hpp), one option each, as lftagdetect's properties.
  DetectorParams params = io::front_end_defaults();
};
// Adds --family, --ids, --fx, --fy, --cx, --cy, --calibration, --tag-size and one option per
// tunable (--threshold-window, --max-candidates, --deadline, ...) to `cmd`, stored in
// `options` (which must outlive the parse).
void add_detector_options(CLI::App* cmd, DetectorOptions& options);
// Throws std::invalid_argument when --fy, --cx or --cy is given without --fx.
void check_camera_options(const DetectorOptions& options);
// The families and ids of `options` (--family, --ids) in `params`, then params.validate();
// throws std::invalid_argument saying what is wrong.
void set_families_and_ids(const DetectorOptions& options, DetectorParams& params);

void add_generate_command(CLI::App& app, int& status);
void add_render_command(CLI::App& app, int& status);
void add_detect_command(CLI::App& app, int& status);
#ifdef LFTAG_WITH_GST
void add_annotate_command(CLI::App& app, int& status);
#endif

}  // namespace lftag::tools
