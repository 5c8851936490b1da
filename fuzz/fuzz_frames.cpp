// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: arbitrary bytes as a frame (size, stride, pixels; see frame_input.hpp)
// through the whole detector with every family from 2x2 to 8x8.
#include "frame_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  lftag::fuzz::detect_frame(data, size);
  return 0;
}
