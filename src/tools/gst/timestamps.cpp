// SPDX-License-Identifier: LGPL-2.1-or-later
#include "timestamps.hpp"

#include <cmath>

namespace lftag::tools {
namespace {

constexpr std::int64_t kSecond = 1000000000;

}  // namespace

void TimestampWatch::set_rate(int numerator, int denominator) {
  fps_n_ = numerator > 0 && denominator > 0 ? numerator : 0;
  fps_d_ = numerator > 0 && denominator > 0 ? denominator : 1;
}

std::int64_t TimestampWatch::index(std::int64_t t) const {
  return std::llround(double(t) * fps_n_ / (double(fps_d_) * kSecond));
}

std::int64_t TimestampWatch::step() const {
  if (has_rate()) return std::llround(double(kSecond) * fps_d_ / fps_n_);
  return last_duration_ > 0 ? last_duration_ : 0;
}

std::optional<TimestampWatch::Finding> TimestampWatch::frame(std::int64_t t, std::int64_t duration) {
  const std::int64_t previous = last_;
  if (duration > 0) last_duration_ = duration;
  const std::int64_t s = step();
  if (previous < 0) {
    last_ = t;
    return std::nullopt;
  }
  // Followed either way: after a timestamp reset, only the reset is reported.
  last_ = t;
  if (t <= previous) return Finding{Kind::kBackwards, previous, t, 0};
  if (s <= 0) return std::nullopt;
  // Up to half a frame of jitter is a rounded timestamp, not a missing frame.
  const std::int64_t missing = std::llround(double(t - previous) / s) - 1;
  if (missing >= 1) return Finding{Kind::kGap, previous, t, missing};
  return std::nullopt;
}

std::optional<TimestampWatch::Finding> TimestampWatch::end(std::int64_t duration) const {
  const std::int64_t s = step();
  if (last_ < 0 || duration < 0 || s <= 0) return std::nullopt;
  const std::int64_t missing = std::llround(double(duration - last_) / s) - 1;
  if (missing >= 1) return Finding{Kind::kEndsEarly, last_ + s, duration, missing};
  return std::nullopt;
}

}  // namespace lftag::tools
