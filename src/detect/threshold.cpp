// SPDX-License-Identifier: LGPL-2.1-or-later
// Binarisation against the mean of an M x M window (paper IV-A), packed 16 pixels at a
// time into the bit rows that the region labeller scans.
//
// The mean is OpenCV's box filter with replicated borders, to the bit. For the default
// window of 16 (and 2, 4, 8) it is computed here instead, fused with the comparison: the
// sums of a power-of-two window fit 16 bits, so a running column sum and a few doubling
// passes along the row give them with 16-bit lanes and no division, in half the box
// filter's time, which was a third of a frame's. Other windows use the box filter itself.
#include <algorithm>
#include <array>
#include <cstdlib>
#include <vector>

#include <opencv2/core/hal/intrin.hpp>
#include <opencv2/imgproc.hpp>

#include "stages.hpp"

namespace lftag::detail {
namespace {

// Sets the bit of every pixel of a row with grey + offset < mean.
void compare_row(const std::uint8_t* g, const std::uint8_t* m, int w, std::uint8_t off, std::uint64_t* bits) {
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

// The mean a band of rows at a time, so that its scratch is not another frame: a band of
// a view filters as the whole image would (its window reads the rows around it, and the
// border is the image's), at a few percent more work.
void threshold_box_filter(const cv::Mat& grey, int window, std::uint8_t off, cv::Mat& mean, BinaryImage& out) {
  const int band = std::max(256, 4 * window);
  for (int top = 0; top < grey.rows; top += band) {
    const int rows = std::min(band, grey.rows - top);
    cv::blur(grey.rowRange(top, top + rows), mean, cv::Size(window, window), cv::Point(-1, -1), cv::BORDER_REPLICATE);
    for (int y = 0; y < rows; ++y)
      compare_row(grey.ptr<std::uint8_t>(top + y), mean.ptr<std::uint8_t>(y), grey.cols, off,
                  out.bits.data() + std::size_t(top + y) * out.words_per_row);
  }
}

// dst[i] = a[i] + b[i] over n 16-bit lanes (sums that never exceed 16 bits).
void add_u16(const std::uint16_t* a, const std::uint16_t* b, std::uint16_t* dst, int n) {
  int i = 0;
#if CV_SIMD128
  for (; i + 8 <= n; i += 8) cv::v_store(dst + i, cv::v_load(a + i) + cv::v_load(b + i));
#endif
  for (; i < n; ++i) dst[i] = std::uint16_t(a[i] + b[i]);
}

// col[i] += add[i] - sub[i] over n pixels.
void slide_columns(std::uint16_t* col, const std::uint8_t* add, const std::uint8_t* sub, int n) {
  int i = 0;
#if CV_SIMD128
  for (; i + 16 <= n; i += 16) {
    cv::v_uint16x8 a0, a1, s0, s1;
    cv::v_expand(cv::v_load(add + i), a0, a1);
    cv::v_expand(cv::v_load(sub + i), s0, s1);
    cv::v_store(col + i, cv::v_load(col + i) + a0 - s0);
    cv::v_store(col + i + 8, cv::v_load(col + i + 8) + a1 - s1);
  }
#endif
  for (; i < n; ++i) col[i] = std::uint16_t(col[i] + add[i] - sub[i]);
}

// The window of pixel x spans x - M/2 .. x + M/2 - 1, as OpenCV anchors an even kernel,
// and its mean rounds as OpenCV's fixed-point box filter does for a power-of-two area d:
// (sum + d/2 + 1) >> log2(d).
void threshold_power_of_two(const cv::Mat& grey, int window, std::uint8_t off, cv::Mat& scratch, BinaryImage& out) {
  const int w = grey.cols, h = grey.rows, half = window / 2;
  const int padded = w + window - 1;  // the column sums of columns -half .. w + half - 2
  // Two rows of 16-bit lanes (column sums, partial window sums) and one of 8-bit means,
  // each with room for a last partial vector.
  const int stride = padded + 16;
  scratch.create(3, stride, CV_16U);
  std::uint16_t* col = scratch.ptr<std::uint16_t>(0);
  std::uint16_t* sums = scratch.ptr<std::uint16_t>(1);
  std::uint8_t* mean = reinterpret_cast<std::uint8_t*>(scratch.ptr<std::uint16_t>(2));
  std::fill(col, col + stride, 0);
  std::fill(sums, sums + stride, 0);
  const auto row = [&](int y) { return grey.ptr<std::uint8_t>(std::clamp(y, 0, h - 1)); };
  for (int y = -half; y < half; ++y)  // the window of row 0: rows -half .. half - 1
    for (int x = 0; x < w; ++x) col[half + x] = std::uint16_t(col[half + x] + row(y)[x]);
  int shift = 0;
  while ((1 << shift) < window * window) ++shift;
  const std::uint16_t round = std::uint16_t(window * window / 2 + 1);

  for (int y = 0; y < h; ++y) {
    if (y > 0) slide_columns(col + half, row(y + half - 1), row(y - half - 1), w);
    std::fill(col, col + half, col[half]);  // replicated columns
    std::fill(col + half + w, col + padded, col[half + w - 1]);
    // Doubling: `part` holds the sums of `span` columns from each column on, until the
    // span is half the window; two halves make a window.
    const std::uint16_t* part = col;
    for (int span = 1; span < half; span *= 2) {
      add_u16(part, part + span, sums, padded - 2 * span + 1);
      part = sums;
    }
    int x = 0;
#if CV_SIMD128
    const cv::v_uint16x8 vround = cv::v_setall_u16(round);
    const auto means = [&](int i) { return (cv::v_load(part + i) + cv::v_load(part + i + half) + vround) >> shift; };
    for (; x + 16 <= w; x += 16) cv::v_store(mean + x, cv::v_pack(means(x), means(x + 8)));
#endif
    for (; x < w; ++x) mean[x] = std::uint8_t((part[x] + part[x + half] + round) >> shift);
    compare_row(grey.ptr<std::uint8_t>(y), mean, w, off, out.bits.data() + std::size_t(y) * out.words_per_row);
  }
}

}  // namespace

double estimate_noise(const ImageView& image, int row_step) {
  // The mask's taps are two pixels apart: a codec (JPEG, H.264) quantises away nearly all
  // of the noise that neighbouring pixels show and keeps most of what the threshold's
  // window sees.
  constexpr int kSpacing = 2;
  const int w = image.width, h = image.height;
  if (w <= 2 * kSpacing || h <= 2 * kSpacing) return 0;
  // |response| of each sampled pixel; for white Gaussian noise of deviation s the response
  // has deviation 6 s (the mask's norm), so its median is 0.6745 x 6 s.
  constexpr int kBins = 1024;
  std::array<std::int64_t, kBins> histogram{};
  std::vector<int> second(std::size_t(w), 0);  // a column's second difference
  std::int64_t samples = 0;
  for (int y = kSpacing; y + kSpacing < h; y += row_step) {
    const std::uint8_t* at = image.data + std::ptrdiff_t(y) * image.stride;
    const std::uint8_t* up = at - std::ptrdiff_t(kSpacing) * image.stride;
    const std::uint8_t* down = at + std::ptrdiff_t(kSpacing) * image.stride;
    for (int x = 0; x < w; ++x) second[std::size_t(x)] = int(up[x]) - 2 * int(at[x]) + int(down[x]);
    for (int x = kSpacing; x + kSpacing < w; ++x) {
      const int r =
          std::abs(second[std::size_t(x - kSpacing)] - 2 * second[std::size_t(x)] + second[std::size_t(x + kSpacing)]);
      ++histogram[std::size_t(std::min(r, kBins - 1))];
    }
    samples += w - 2 * kSpacing;
  }
  if (samples == 0) return 0;
  std::int64_t below = 0;
  int median = 0;
  while (median < kBins - 1 && 2 * (below + histogram[std::size_t(median)]) <= samples)
    below += histogram[std::size_t(median++)];
  // Interpolated within the median's bin, the integers m - 1/2 to m + 1/2 (0 to 1/2 for 0).
  const double count = double(std::max<std::int64_t>(histogram[std::size_t(median)], 1));
  const double within = (0.5 * double(samples) - double(below)) / count;
  const double r = median == 0 ? 0.5 * within : median - 0.5 + within;
  return r / (0.6745 * 6);
}

cv::Mat1b BinaryImage::to_mat() const {
  cv::Mat1b out(height, width);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) out(y, x) = black(x, y) ? 255 : 0;
  return out;
}

void threshold_mean(const ImageView& image, int window, int offset, cv::Mat& scratch, BinaryImage& out) {
  const int w = image.width, h = image.height;
  out.width = w, out.height = h, out.words_per_row = (w + 63) / 64;
  reserve_for_frame(out.bits, std::size_t(out.words_per_row) * h);
  out.bits.assign(std::size_t(out.words_per_row) * h, 0);
  if (w == 0 || h == 0) return;
  const auto off = std::uint8_t(std::clamp(offset, 0, 255));
  if (window == 2 || window == 4 || window == 8 || window == 16)
    threshold_power_of_two(image.mat(), window, off, scratch, out);
  else
    threshold_box_filter(image.mat(), window, off, scratch, out);
}

}  // namespace lftag::detail
