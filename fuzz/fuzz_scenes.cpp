// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: frames in the format of frame_input.hpp, started from rendered scenes
// with markers of every family (fuzz/corpus/scenes, written by make_corpus), so that the
// mutations stay near real markers and reach decoding and pose, which random bytes
// seldom do.
#include "frame_input.hpp"

// Decoding a marker under the sanitizers takes a few milliseconds and a candidate under
// way is never cut, so the deadline here is longer than fuzz_frames': with 5 ms the seeds'
// markers are still found in most runs (2 ms: a few of them), and a frame of look-alikes
// costs tens of milliseconds at most.
constexpr double kDeadlineMs = 5;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lftag::fuzz::detect_frame(data, size, kDeadlineMs);
  return 0;
}
