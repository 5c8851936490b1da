// SPDX-License-Identifier: LGPL-2.1-or-later
// The detector's tunable parameters, one row each: the lftagdetect element installs its
// properties from these rows and `lftag detect` and `lftag annotate` their options, so
// that a parameter has one name, one range, one default and one description everywhere,
// and reaches DetectorParams by one path.
#pragma once

#include <array>
#include <climits>
#include <cstddef>
#include <type_traits>

#include "lftag/detector.hpp"

namespace lftag::io {

struct Tunable {
  enum class Kind { integer, real, boolean };
  const char* name;   // the property; the option is "--" + name
  const char* nick;   // the property's short title
  const char* blurb;  // what it does, for gst-inspect-1.0 and --help
  Kind kind;
  double min, max;  // inclusive (booleans: 0 and 1)
  double (*get)(const DetectorParams&);
  void (*set)(DetectorParams&, double);
};

// What the element and the command line start from: the library's defaults, but with the
// live deadline (a frame of look-alikes must not stall a stream).
inline DetectorParams front_end_defaults() {
  DetectorParams p;
  p.deadline_ms = kLiveDeadlineMs;
  return p;
}

namespace detail {
template <auto Field>
constexpr Tunable field(const char* name, const char* nick, const char* blurb, double min, double max) {
  using T = std::remove_reference_t<decltype(std::declval<DetectorParams&>().*Field)>;
  const Tunable::Kind kind = std::is_same_v<T, bool> ? Tunable::Kind::boolean
                             : std::is_integral_v<T> ? Tunable::Kind::integer
                                                     : Tunable::Kind::real;
  return {name,
          nick,
          blurb,
          kind,
          min,
          max,
          [](const DetectorParams& p) { return double(p.*Field); },
          [](DetectorParams& p, double v) { p.*Field = static_cast<T>(v); }};
}
}  // namespace detail

constexpr std::size_t kTunables = 10;

inline const std::array<Tunable, kTunables>& tunables() {
  using detail::field;
  static const std::array<Tunable, kTunables> rows = {
      field<&DetectorParams::threshold_window>(
          "threshold-window", "Threshold window",
          "Side in pixels of the window whose mean grey level a pixel must be below to count as black (the "
          "paper's M). Larger suits large markers",
          2, 1024),
      field<&DetectorParams::threshold_offset>(
          "threshold-offset", "Threshold offset",
          "Grey levels below the window's mean for a pixel to count as black; raising it ignores faint texture "
          "and noise",
          0, 255),
      field<&DetectorParams::second_look>(
          "second-look", "Second look",
          "Look again where no marker was found: at black regions shaped and shaded like a marker's border, and "
          "at small isolated clusters (enlarged, with a local threshold): shadowed, blurred, far and small markers",
          0, 1),
      field<&DetectorParams::ids_complete>(
          "ids-complete", "Ids complete",
          "The ids listed (ids) are every marker that may be in view: a reading from the grey levels that is "
          "too close to an id one square off is then judged against the nearest other listed id instead, and "
          "small or compressed markers are read more often. A marker in view whose id is not listed may then be "
          "read as a listed neighbour: list every id printed. Needs ids",
          0, 1),
      field<&DetectorParams::max_ink_ratio>(
          "max-ink-ratio", "Maximum ink ratio",
          "tau1: a candidate is rejected when its largest black square holds more than this many times the ink "
          "of its smallest, once perspective is taken out (the design ratio is 1.78)",
          1, 100),
      field<&DetectorParams::min_spread_ratio>(
          "min-spread-ratio", "Minimum spread ratio",
          "tau2: a candidate is rejected when its squares' centres are this close to collinear (minor to major "
          "axis of their scatter)",
          0, 1),
      // One value for every family: the per-family array reads back as any of its entries.
      {"max-decode-error", "Maximum decoding error",
       "tau3: a reading is rejected when its decoding error exceeds this, for every family (0: each family's "
       "calibrated default; the paper's 5e-4 for 3x3 and 1e-3 for 4x4)",
       Tunable::Kind::real, 0, 1, [](const DetectorParams& p) { return p.max_decode_error[Family::kMinN]; },
       [](DetectorParams& p, double v) { p.max_decode_error.fill(v); }},
      field<&DetectorParams::max_cell_residual>(
          "max-cell-residual", "Maximum cell residual",
          "A reading is rejected when a square lies further than this from its decoded position, in marker "
          "units (positions are 1 unit apart)",
          0.01, 1),
      field<&DetectorParams::max_candidates>(
          "max-candidates", "Candidates per frame",
          "Work budget per frame: at most this many candidate markers (white regions holding n x n black "
          "squares) are examined, the most plausible first; the rest are skipped and counted, so that a frame "
          "full of look-alikes (a tiled wall, a perforated sheet) cannot stall the stream. 0: no limit",
          0, INT_MAX),
      field<&DetectorParams::deadline_ms>(
          "deadline", "Deadline per frame (ms)",
          "Milliseconds of processor time a frame's detection may take: once they are spent, its optional work "
          "(the second looks at far or blurred markers, and their outline reads) is skipped and counted, so "
          "that no frame of look-alikes or sensor noise stalls a live stream; the frame's own candidates are "
          "always examined. 0: no deadline (every frame gets all its work, as in lftag::Detector)",
          0, 1e7),
  };
  return rows;
}

}  // namespace lftag::io
