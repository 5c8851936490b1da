// SPDX-License-Identifier: LGPL-2.1-or-later
// Binary images for the stage tests, built bit by bit, independently of the threshold stage.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

#include "stages.hpp"

namespace lftag::test {

// Black wherever `black` is non-zero.
inline detail::BinaryImage binary_from_mask(const cv::Mat1b& black) {
  detail::BinaryImage b;
  b.width = black.cols, b.height = black.rows, b.words_per_row = (black.cols + 63) / 64;
  b.bits.assign(std::size_t(b.words_per_row) * b.height, 0);
  for (int y = 0; y < black.rows; ++y)
    for (int x = 0; x < black.cols; ++x)
      if (black(y, x)) b.bits[std::size_t(y) * b.words_per_row + (x >> 6)] |= std::uint64_t{1} << (x & 63);
  return b;
}

}  // namespace lftag::test
