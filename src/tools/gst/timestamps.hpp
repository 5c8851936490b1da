// SPDX-License-Identifier: LGPL-2.1-or-later
// What a decoded video's timestamps say about its file: frames missing (a jump in the
// stream time), a frame that repeats or goes back in time, a stream that ends before the
// duration its container gives. `lftag annotate` warns on each and counts them; the frame
// numbers it writes come from the same rounding (frame = round(stream time x rate)), so
// that after a gap they are still the file's frame indices.
#pragma once

#include <cstdint>
#include <optional>

namespace lftag::tools {

// Times in nanoseconds.
class TimestampWatch {
 public:
  enum class Kind { kGap, kBackwards, kEndsEarly };
  struct Finding {
    Kind kind;
    std::int64_t previous;  // the frame before (kGap, kBackwards), or the end of the last one (kEndsEarly)
    std::int64_t at;        // the frame (kGap, kBackwards), or the container's duration (kEndsEarly)
    std::int64_t missing;   // frames not there (kGap, kEndsEarly); 0 for kBackwards
  };

  // The frame rate of the caps; 0 when unknown or variable (then each frame's duration
  // is the step, and frame numbers are not derived from time).
  void set_rate(int numerator, int denominator);
  bool has_rate() const { return fps_n_ > 0 && fps_d_ > 0; }
  // round(t x rate): the frame's index in the file. Needs has_rate().
  std::int64_t index(std::int64_t t) const;

  // The next decoded frame, at stream time `t`, lasting `duration` (< 0: unknown).
  // Returns what it reveals, if anything.
  std::optional<Finding> frame(std::int64_t t, std::int64_t duration);
  // At the end of the stream: the frames missing before `duration`, the container's
  // (< 0: unknown), if at least one is.
  std::optional<Finding> end(std::int64_t duration) const;

 private:
  // The length of one frame: from the rate, else the last frame's duration; 0: unknown.
  std::int64_t step() const;

  int fps_n_ = 0, fps_d_ = 1;
  std::int64_t last_ = -1, last_duration_ = -1;
};

}  // namespace lftag::tools
