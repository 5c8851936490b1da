// SPDX-License-Identifier: LGPL-2.1-or-later
// Binarisation (src/detect/threshold.cpp): the bit rows the region labeller scans.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "stages.hpp"

using namespace lftag;
using lftag::detail::BinaryImage;
using lftag::detail::threshold_mean;

namespace {

// The rule, written out: black iff grey + offset < the mean of the M x M window, the mean
// being OpenCV's box filter with replicated borders on a contiguous copy of the pixels.
cv::Mat1b reference(const cv::Mat1b& grey, int window, int offset, int border = cv::BORDER_REPLICATE) {
  cv::Mat1b mean;
  cv::blur(grey.clone(), mean, cv::Size(window, window), cv::Point(-1, -1), border);
  cv::Mat1b out(grey.size(), uchar(0));
  for (int y = 0; y < grey.rows; ++y)
    for (int x = 0; x < grey.cols; ++x) out(y, x) = int(grey(y, x)) + offset < int(mean(y, x)) ? 255 : 0;
  return out;
}

cv::Mat1b random_grey(int w, int h, std::mt19937& rng) {
  // Smooth structure plus noise, so that both colours occur at every scale.
  cv::Mat1b g(h, w);
  std::uniform_int_distribution<int> noise(-40, 40);
  const double fx = 0.37 + (rng() % 100) / 300.0, fy = 0.23 + (rng() % 100) / 300.0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      g(y, x) = cv::saturate_cast<uchar>(128 + 80 * std::sin(fx * x) * std::cos(fy * y) + noise(rng));
  return g;
}

// Every bit of `b` against the expected 255/0 mask, plus the layout: words per row and
// white (zero) padding bits beyond the width.
void expect_bits(const BinaryImage& b, const cv::Mat1b& expected, const std::string& what) {
  const int w = expected.cols, h = expected.rows;
  ASSERT_EQ(b.width, w) << what;
  ASSERT_EQ(b.height, h) << what;
  ASSERT_EQ(b.words_per_row, (w + 63) / 64) << what;
  ASSERT_EQ(b.bits.size(), std::size_t(b.words_per_row) * h) << what;
  int wrong = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x)
      if (b.black(x, y) != (expected(y, x) != 0) && ++wrong <= 5)
        ADD_FAILURE() << what << ": pixel (" << x << ", " << y << ") is " << (b.black(x, y) ? "black" : "white");
    for (int x = w; x < b.words_per_row * 64; ++x)
      if (((b.row(y)[x >> 6] >> (x & 63)) & 1) && ++wrong <= 5)
        ADD_FAILURE() << what << ": padding bit " << x << " of row " << y << " is set";
  }
  EXPECT_EQ(wrong, 0) << what;
}

}  // namespace

TEST(Threshold, BitPackingForWidthsOnAndOffWordBoundaries) {
  std::mt19937 rng(7);
  const cv::Size sizes[] = {{1, 1}, {3, 2}, {17, 13}, {65, 3}, {640, 480}, {16, 5}, {64, 2}, {127, 4}, {129, 3}};
  for (const cv::Size& s : sizes)
    for (const auto& [window, offset] :
         {std::pair{16, 0}, std::pair{3, 0}, std::pair{5, 7}, std::pair{32, 2}, std::pair{9, 60}, std::pair{4, 255},
          std::pair{8, 1}, std::pair{2, 0}, std::pair{17, 0}}) {
      const cv::Mat1b grey = random_grey(s.width, s.height, rng);
      cv::Mat mean;
      BinaryImage b;
      threshold_mean(ImageView(grey), window, offset, mean, b);
      expect_bits(b, reference(grey, window, offset),
                  std::to_string(s.width) + "x" + std::to_string(s.height) + " M=" + std::to_string(window) +
                      " offset=" + std::to_string(offset));
    }
}

TEST(Threshold, PowerOfTwoWindowsRoundTheirMeansAsTheBoxFilter) {
  // Windows of 2, 4, 8 and 16 have a path of their own (16-bit sums): near-white images
  // bring the sums to their largest (65,280 for 16 x 16), and each level's pixels sit
  // just below, at and just above the rounded means of windows holding a few darker ones.
  std::mt19937 rng(13);
  for (int window : {2, 4, 8, 16})
    for (int base : {255, 254, 129, 128, 1}) {
      cv::Mat1b grey(41, 150, uchar(base));
      std::uniform_int_distribution<int> pick(0, 149), row(0, 40), step(0, 3);
      for (int k = 0; k < 400; ++k) grey(row(rng), pick(rng)) = uchar(std::max(0, base - step(rng)));
      for (int offset : {0, 1, 2}) {
        cv::Mat mean;
        BinaryImage b;
        threshold_mean(ImageView(grey), window, offset, mean, b);
        expect_bits(
            b, reference(grey, window, offset),
            "M=" + std::to_string(window) + " base " + std::to_string(base) + " offset " + std::to_string(offset));
      }
    }
}

TEST(Threshold, ExtremeImagesSetEveryBitOrNone) {
  // Uniform grey is never darker than its own mean; a single dark pixel in white is black.
  cv::Mat mean;
  BinaryImage b;
  for (const cv::Size& s : {cv::Size(1, 1), cv::Size(65, 3), cv::Size(200, 7)}) {
    for (int v : {0, 77, 255}) {
      const cv::Mat1b flat(s, uchar(v));
      threshold_mean(ImageView(flat), 16, 0, mean, b);
      expect_bits(b, cv::Mat1b(s, uchar(0)), "flat " + std::to_string(v));
    }
  }
  // Alternating columns of 0 and 255 with a 2-pixel window: means are 0, 128 or 255 and only
  // the dark columns beside a bright one are black.
  cv::Mat1b stripes(3, 130, uchar(255));
  for (int x = 0; x < stripes.cols; x += 2) stripes.col(x).setTo(0);
  threshold_mean(ImageView(stripes), 2, 0, mean, b);
  expect_bits(b, reference(stripes, 2, 0), "stripes");
  int black = 0;
  for (int x = 0; x < stripes.cols; ++x) black += b.black(x, 1);
  EXPECT_GT(black, 60);
}

TEST(Threshold, PaddedStridesIgnoreThePadding) {
  std::mt19937 rng(11);
  for (const cv::Size& s : {cv::Size(1, 1), cv::Size(3, 2), cv::Size(17, 13), cv::Size(65, 3), cv::Size(640, 480)}) {
    const cv::Mat1b grey = random_grey(s.width, s.height, rng);
    const cv::Mat1b expected = reference(grey, 16, 3);
    for (int pad : {1, 13, 64}) {
      const int stride = s.width + pad;
      // Two buffers with the same pixels and different garbage in the padding.
      std::vector<std::uint8_t> a(std::size_t(stride) * s.height), c(a.size());
      for (std::size_t i = 0; i < a.size(); ++i) a[i] = 0, c[i] = 255;
      std::uniform_int_distribution<int> any(0, 255);
      for (int y = 0; y < s.height; ++y)
        for (int x = s.width; x < stride; ++x) a[std::size_t(y) * stride + x] = std::uint8_t(any(rng));
      for (int y = 0; y < s.height; ++y)
        for (int x = 0; x < s.width; ++x) a[std::size_t(y) * stride + x] = c[std::size_t(y) * stride + x] = grey(y, x);
      cv::Mat mean;
      BinaryImage ba, bc;
      threshold_mean(ImageView(a.data(), s.width, s.height, stride), 16, 3, mean, ba);
      threshold_mean(ImageView(c.data(), s.width, s.height, stride), 16, 3, mean, bc);
      const std::string what =
          std::to_string(s.width) + "x" + std::to_string(s.height) + " stride " + std::to_string(stride);
      expect_bits(ba, expected, what + " (random padding)");
      expect_bits(bc, expected, what + " (white padding)");
      EXPECT_EQ(ba.bits, bc.bits) << what;
    }
  }
  // A view into the middle of a larger matrix (a ROI): the pixels around it do not matter.
  cv::Mat1b big = random_grey(300, 200, rng);
  const cv::Mat1b roi = big(cv::Rect(37, 21, 101, 77));
  ASSERT_FALSE(roi.isContinuous());
  cv::Mat mean;
  BinaryImage b;
  threshold_mean(ImageView(roi), 16, 0, mean, b);
  expect_bits(b, reference(roi, 16, 0), "ROI");
}

TEST(Threshold, OffsetSemanticsAreStrict) {
  // 3x3 window over 100s with one pixel at 91: its window mean is exactly (8 * 100 + 91) / 9
  // = 99, so it is black iff 91 + offset < 99, i.e. for offsets 0..7. Its neighbours' means
  // are at least 99 but they are 100: never black.
  cv::Mat1b grey(9, 9, uchar(100));
  grey(4, 4) = 91;
  cv::Mat mean;
  BinaryImage b;
  for (int offset = 0; offset <= 12; ++offset) {
    threshold_mean(ImageView(grey), 3, offset, mean, b);
    cv::Mat1b expected(grey.size(), uchar(0));
    if (offset <= 7) expected(4, 4) = 255;
    expect_bits(b, expected, "offset " + std::to_string(offset));
  }
  // Offsets saturate: 255 makes nothing black, not even a black pixel in white.
  cv::Mat1b dot(5, 5, uchar(255));
  dot(2, 2) = 0;
  threshold_mean(ImageView(dot), 3, 255, mean, b);
  expect_bits(b, cv::Mat1b(dot.size(), uchar(0)), "offset 255");
  threshold_mean(ImageView(dot), 3, 226, mean, b);  // mean 227: 0 + 226 < 227
  EXPECT_TRUE(b.black(2, 2));
  threshold_mean(ImageView(dot), 3, 227, mean, b);
  EXPECT_FALSE(b.black(2, 2));
}

TEST(Threshold, BordersAreReplicated) {
  // Rows 100 150 100 100 ... with a 5x5 window: at x = 0 the replicated window holds
  // 100 100 100 150 100 (mean 110) while a reflected one would hold 100 150 100 150 100
  // (mean 120). With offset 15, pixel 0 (100 + 15 = 115) is white under replication only.
  cv::Mat1b grey(5, 40, uchar(100));
  grey.col(1).setTo(150);
  const cv::Mat1b reflected = reference(grey, 5, 15, cv::BORDER_REFLECT_101);
  ASSERT_EQ(reflected(2, 0), 255);  // the case tells the two borders apart
  cv::Mat mean;
  BinaryImage b;
  threshold_mean(ImageView(grey), 5, 15, mean, b);
  for (int y = 0; y < grey.rows; ++y) EXPECT_FALSE(b.black(0, y)) << "row " << y;
  threshold_mean(ImageView(grey), 5, 9, mean, b);  // 109 < 110
  for (int y = 0; y < grey.rows; ++y) EXPECT_TRUE(b.black(0, y)) << "row " << y;
  expect_bits(b, reference(grey, 5, 9), "replicated");
}

TEST(Threshold, ReusedOutputIsResetForEachFrame) {
  std::mt19937 rng(5);
  cv::Mat mean;
  BinaryImage b;
  const cv::Mat1b large = random_grey(333, 111, rng), small = random_grey(70, 9, rng);
  threshold_mean(ImageView(large), 16, 0, mean, b);
  expect_bits(b, reference(large, 16, 0), "large");
  threshold_mean(ImageView(small), 16, 0, mean, b);
  expect_bits(b, reference(small, 16, 0), "small after large");
  threshold_mean(ImageView(large), 7, 1, mean, b);
  expect_bits(b, reference(large, 7, 1), "large after small");
}

TEST(Threshold, EmptyImage) {
  cv::Mat mean;
  BinaryImage b;
  threshold_mean(ImageView(nullptr, 0, 0, 0), 16, 0, mean, b);
  EXPECT_EQ(b.width, 0);
  EXPECT_EQ(b.height, 0);
  EXPECT_TRUE(b.bits.empty());
  EXPECT_TRUE(b.to_mat().empty());
}

TEST(Threshold, ToMatIs255ForBlack) {
  std::mt19937 rng(3);
  for (const cv::Size& s : {cv::Size(1, 1), cv::Size(65, 3), cv::Size(130, 40)}) {
    const cv::Mat1b grey = random_grey(s.width, s.height, rng);
    cv::Mat mean;
    BinaryImage b;
    threshold_mean(ImageView(grey), 16, 0, mean, b);
    const cv::Mat1b m = b.to_mat();
    ASSERT_EQ(m.size(), s);
    ASSERT_EQ(m.type(), CV_8UC1);
    EXPECT_EQ(cv::norm(m, reference(grey, 16, 0), cv::NORM_INF), 0.0);
  }
  // Hand-set bits, including the last pixel of a word and the first of the next.
  BinaryImage b;
  b.width = 66, b.height = 2, b.words_per_row = 2;
  b.bits = {std::uint64_t{1} << 63, 1, 1, 2};
  const cv::Mat1b m = b.to_mat();
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 66; ++x) {
      const bool black = (y == 0 && (x == 63 || x == 64)) || (y == 1 && (x == 0 || x == 65));
      EXPECT_EQ(m(y, x), black ? 255 : 0) << x << ", " << y;
    }
}

// The noise estimate reads the pixels' noise, not the picture: edges and gradients
// without noise read as the rounding to grey levels alone.
TEST(NoiseEstimate, IsThePixelsDeviationAndNotTheirEdgesOrGradients) {
  cv::Mat1f picture(480, 640);
  for (int y = 0; y < picture.rows; ++y)
    for (int x = 0; x < picture.cols; ++x) picture(y, x) = float(60 + 0.15 * x + 0.1 * y);
  for (int i = 0; i < 12; ++i)  // dark rectangles: edges in both directions
    picture(cv::Rect(20 + 50 * i, 40 + 25 * (i % 5), 30, 60)).setTo(20);
  cv::Mat1b clean;
  picture.convertTo(clean, CV_8U);
  EXPECT_LT(detail::estimate_noise(ImageView(clean)), 0.35);  // the rounding to grey levels: 0.29
  for (const double sigma : {2.0, 4.0, 6.0}) {
    cv::Mat1f noise(picture.size());
    cv::RNG(7).fill(noise, cv::RNG::NORMAL, 0.0, sigma);
    cv::Mat1b noisy;
    cv::Mat1f(picture + noise).convertTo(noisy, CV_8U);
    EXPECT_NEAR(detail::estimate_noise(ImageView(noisy)), sigma, 0.12 * sigma) << sigma;
  }
  EXPECT_EQ(detail::estimate_noise(ImageView(cv::Mat1b(4, 4, uchar(9)))), 0.0);
  EXPECT_EQ(detail::estimate_noise(ImageView(cv::Mat1b())), 0.0);
}
