// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: arbitrary bytes as a frame (size, stride, pixels; see frame_input.hpp)
// through the whole detector with every family from 2x2 to 8x8.
#include "frame_input.hpp"

// Half a millisecond of processor time a detection: a frame's fixed work (threshold,
// labelling) is not cut, and the small frames of this target mostly finish in it, so
// that about half the inputs are compared and the target runs hundreds of inputs a
// second under the sanitizers (2 ms halves that; no deadline: 16 a second).
constexpr double kDeadlineMs = 0.5;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lftag::fuzz::detect_frame(data, size, kDeadlineMs);
  return 0;
}
