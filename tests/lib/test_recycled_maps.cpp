// SPDX-License-Identifier: LGPL-2.1-or-later
// Recycled working maps (src/core/recycled_maps.cpp): a thread's freed buffers serve its
// next maps, with the contents every map is asked for.
#include <gtest/gtest.h>

#include <thread>

#include <opencv2/imgproc.hpp>

#include "../core/recycled_maps.hpp"

using lftag::detail::recycled_copy;
using lftag::detail::recycled_map;
using lftag::detail::recycling_allocator;

TEST(RecycledMaps, AReleasedBufferServesTheNextMapOfItsSize) {
  const void* first = nullptr;
  {
    const cv::Mat1f m = recycled_map({300, 200}, 1.f);
    first = m.data;
  }
  const cv::Mat1f again = recycled_map({300, 200}, 2.f);
  EXPECT_EQ(again.data, first);
  EXPECT_EQ(cv::countNonZero(again != 2.f), 0);  // filled as asked, nothing of the last map
}

TEST(RecycledMaps, SmallerMapsTakeABufferUpToHalfItsSizeAndNoLess) {
  const void* large = nullptr;
  { large = recycled_map({400, 400}).data; }
  const cv::Mat1f half = recycled_map({400, 210});  // a little more than half: reused
  EXPECT_EQ(half.data, large);
  const cv::Mat1f small = recycled_map({100, 100});  // a sixteenth: a buffer of its own
  EXPECT_NE(small.data, large);
}

TEST(RecycledMaps, CopiesAndOpenCVOutputsAreOrdinaryMaps) {
  cv::Mat1f source(64, 48);
  cv::randu(source, 0, 255);
  const cv::Mat1f copy = recycled_copy(source);
  EXPECT_NE(copy.data, source.data);
  EXPECT_EQ(cv::norm(copy, source, cv::NORM_INF), 0);

  // An output prepared with the allocator keeps it, and the result is OpenCV's own.
  cv::Mat1f blurred = recycled_map(source.size()), expected;
  const void* prepared = blurred.data;
  cv::GaussianBlur(source, blurred, cv::Size(), 1.5, 1.5, cv::BORDER_CONSTANT);
  cv::GaussianBlur(source, expected, cv::Size(), 1.5, 1.5, cv::BORDER_CONSTANT);
  EXPECT_EQ(blurred.data, prepared);
  EXPECT_EQ(cv::norm(blurred, expected, cv::NORM_INF), 0);

  // An empty output with the allocator set is created by it.
  cv::Mat3f merged;
  merged.allocator = recycling_allocator();
  cv::merge(std::vector<cv::Mat>{source, copy, blurred}, merged);
  ASSERT_EQ(merged.size(), source.size());
  EXPECT_EQ(merged(5, 7)[1], source(5, 7));

  // A region of a recycled map is a view of it, and outlives the map's own header.
  cv::Mat1f roi;
  {
    const cv::Mat1f whole = recycled_copy(source);
    roi = whole(cv::Rect(4, 4, 10, 10));
  }
  EXPECT_EQ(roi(0, 0), source(4, 4));
}

TEST(RecycledMaps, EachThreadKeepsItsOwn) {
  const void* mine = nullptr;
  { mine = recycled_map({256, 256}).data; }
  const void* theirs = nullptr;
  std::thread([&] { theirs = recycled_map({256, 256}).data; }).join();
  EXPECT_NE(theirs, mine);
  const cv::Mat1f again = recycled_map({256, 256});  // still this thread's
  EXPECT_EQ(again.data, mine);
}
