// SPDX-License-Identifier: LGPL-2.1-or-later
// TimestampWatch (src/tools/gst/timestamps.hpp): the gaps, repeats and early ends that
// `lftag annotate` reports, and the frame numbers it derives from stream time.
#include "timestamps.hpp"

#include <gtest/gtest.h>

using lftag::tools::TimestampWatch;

namespace {

constexpr std::int64_t kFrame = 33333333;  // 1/30 s, as GStreamer rounds it

std::int64_t at(int frame) { return std::int64_t(frame) * 1000000000 / 30; }

}  // namespace

TEST(TimestampWatch, SteadyStreamFindsNothing) {
  TimestampWatch w;
  w.set_rate(30, 1);
  for (int i = 0; i < 90; ++i) {
    EXPECT_FALSE(w.frame(at(i), kFrame)) << i;
    EXPECT_EQ(w.index(at(i)), i);
  }
  EXPECT_FALSE(w.end(3000000000));
}

TEST(TimestampWatch, GapCountsTheFramesMissing) {
  TimestampWatch w;
  w.set_rate(30, 1);
  for (int i = 0; i <= 35; ++i) ASSERT_FALSE(w.frame(at(i), kFrame));
  const auto found = w.frame(at(46), kFrame);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->kind, TimestampWatch::Kind::kGap);
  EXPECT_EQ(found->missing, 10);
  EXPECT_EQ(found->previous, at(35));
  EXPECT_EQ(w.index(found->at), 46);
  EXPECT_FALSE(w.frame(at(47), kFrame));
}

TEST(TimestampWatch, JitterIsNotAGap) {
  TimestampWatch w;
  w.set_rate(30, 1);
  ASSERT_FALSE(w.frame(0, kFrame));
  // Rounded to the millisecond, as WebM keeps them: up to half a frame off.
  EXPECT_FALSE(w.frame(at(1) + 1000000, kFrame));
  EXPECT_FALSE(w.frame(at(2) - 1000000, kFrame));
  EXPECT_FALSE(w.frame(at(3) + kFrame * 4 / 10, kFrame));
}

TEST(TimestampWatch, RepeatedOrEarlierTimestamp) {
  TimestampWatch w;
  w.set_rate(30, 1);
  ASSERT_FALSE(w.frame(at(10), kFrame));
  auto found = w.frame(at(10), kFrame);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->kind, TimestampWatch::Kind::kBackwards);
  found = w.frame(at(4), kFrame);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->kind, TimestampWatch::Kind::kBackwards);
  // Followed from there: the next frame is in order.
  EXPECT_FALSE(w.frame(at(5), kFrame));
}

TEST(TimestampWatch, EndBeforeTheContainersDuration) {
  TimestampWatch w;
  w.set_rate(30, 1);
  for (int i = 0; i < 56; ++i) ASSERT_FALSE(w.frame(at(i), kFrame));
  const auto found = w.end(3000000000);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->kind, TimestampWatch::Kind::kEndsEarly);
  EXPECT_EQ(found->missing, 34);
  // One frame short is reported, none is not; an unknown duration says nothing.
  TimestampWatch one;
  one.set_rate(30, 1);
  for (int i = 0; i < 89; ++i) ASSERT_FALSE(one.frame(at(i), kFrame));
  ASSERT_TRUE(one.end(3000000000));
  EXPECT_EQ(one.end(3000000000)->missing, 1);
  EXPECT_FALSE(one.end(-1));
}

TEST(TimestampWatch, WithoutARateTheDurationsAreTheStep) {
  TimestampWatch w;
  w.set_rate(0, 1);
  EXPECT_FALSE(w.has_rate());
  ASSERT_FALSE(w.frame(0, 40000000));
  ASSERT_FALSE(w.frame(40000000, 40000000));
  const auto found = w.frame(200000000, 40000000);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->missing, 3);
  // Neither a rate nor durations: no step, so no gap can be told.
  TimestampWatch blind;
  ASSERT_FALSE(blind.frame(0, -1));
  EXPECT_FALSE(blind.frame(1000000000, -1));
}
