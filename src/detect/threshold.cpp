// SPDX-License-Identifier: LGPL-2.1-or-later
// Binarisation against the mean of an M x M window (paper IV-A). The window mean comes
// from OpenCV's box filter (any M, any frame size); the comparison packs 16 pixels at a
// time into the bit rows that the region labeller scans.
#include <algorithm>

#include <opencv2/core/hal/intrin.hpp>
#include <opencv2/imgproc.hpp>

#include "stages.hpp"

namespace lftag::detail {

cv::Mat1b BinaryImage::to_mat() const {
  cv::Mat1b out(height, width);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) out(y, x) = black(x, y) ? 255 : 0;
  return out;
}

void threshold_mean(const ImageView& image, int window, int offset, cv::Mat& mean, BinaryImage& out) {
  const int w = image.width, h = image.height;
  out.width = w, out.height = h, out.words_per_row = (w + 63) / 64;
  out.bits.assign(std::size_t(out.words_per_row) * h, 0);
  if (w == 0 || h == 0) return;
  const cv::Mat grey = image.mat();
  cv::blur(grey, mean, cv::Size(window, window), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  const auto off = std::uint8_t(std::clamp(offset, 0, 255));

  for (int y = 0; y < h; ++y) {
    const std::uint8_t* g = grey.ptr<std::uint8_t>(y);
    const std::uint8_t* m = mean.ptr<std::uint8_t>(y);
    std::uint64_t* bits = out.bits.data() + std::size_t(y) * out.words_per_row;
    int x = 0;
#if CV_SIMD128
    const cv::v_uint8x16 voff = cv::v_setall_u8(off);
    for (; x + 16 <= w; x += 16) {
      // Saturating add: g + off < mean exactly when g is darker than mean - off.
      const cv::v_uint8x16 dark = (cv::v_load(g + x) + voff) < cv::v_load(m + x);
      bits[x >> 6] |= std::uint64_t(std::uint32_t(cv::v_signmask(dark))) << (x & 63);
    }
#endif
    for (; x < w; ++x)
      if (int(g[x]) + off < int(m[x])) bits[x >> 6] |= std::uint64_t{1} << (x & 63);
  }
}

}  // namespace lftag::detail
