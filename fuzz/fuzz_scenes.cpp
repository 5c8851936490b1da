// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: frames in the format of frame_input.hpp, started from rendered scenes
// with markers of every family (fuzz/corpus/scenes, written by make_scene_corpus), so that
// the mutations stay near real markers and reach decoding and pose, which random bytes
// seldom do.
#include "frame_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lftag::fuzz::detect_frame(data, size);
  return 0;
}
