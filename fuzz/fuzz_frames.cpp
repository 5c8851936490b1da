// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: arbitrary bytes as a frame (size, stride, pixels; see frame_input.hpp)
// through the whole detector with every family from 2x2 to 8x8.
#include "frame_input.hpp"

// A tenth of a millisecond of processor time a detection: a frame's fixed work (threshold,
// labelling, decoding its own candidates) is never cut, the second looks and outline reads
// mostly are (fuzz_scenes reaches those), so that the target runs about two thousand inputs
// a second under the sanitizers (0.25 ms: 1,100; 0.5 ms: 900), the half
// with flag 64 checking the buffers' reuse.
constexpr double kDeadlineMs = 0.1;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lftag::fuzz::detect_frame(data, size, kDeadlineMs);
  return 0;
}
