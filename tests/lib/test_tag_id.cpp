// SPDX-License-Identifier: LGPL-2.1-or-later
#include <random>

#include <gtest/gtest.h>

#include "lftag/tag_id.hpp"

using lftag::TagId;

TEST(TagId, DecimalRoundTripAcross128Bits) {
  EXPECT_EQ(TagId(0).to_decimal(), "0");
  EXPECT_EQ(TagId(6789).to_decimal(), "6789");
  EXPECT_EQ(TagId(~0ull).to_decimal(), "18446744073709551615");
  EXPECT_EQ(TagId(1, 0).to_decimal(), "18446744073709551616");
  EXPECT_EQ(TagId(~0ull, ~0ull).to_decimal(), "340282366920938463463374607431768211455");
  EXPECT_EQ(TagId::parse("340282366920938463463374607431768211455"), TagId(~0ull, ~0ull));
  EXPECT_EQ(TagId::parse("18446744073709551616"), TagId(1, 0));
}

TEST(TagId, HexRoundTrip) {
  EXPECT_EQ(TagId(255).to_hex(), "0xff");
  EXPECT_EQ(TagId(0x123, 0x0000000000000abcull).to_hex(), "0x1230000000000000abc");
  EXPECT_EQ(TagId::parse("0x1230000000000000ABC"), TagId(0x123, 0xabc));
  EXPECT_EQ(TagId::parse("0XfF"), TagId(255));
}

TEST(TagId, RandomValuesRoundTrip) {
  std::mt19937_64 rng(42);
  for (int i = 0; i < 1000; ++i) {
    const TagId id(rng() >> (i % 64), rng());
    EXPECT_EQ(TagId::parse(id.to_decimal()), id);
    EXPECT_EQ(TagId::parse(id.to_hex()), id);
  }
}

TEST(TagId, RejectsBadText) {
  for (const char* bad : {"", "abc", "12a", "-1", "0x", "0xg", "1.5", " 1", "340282366920938463463374607431768211456",
                          "0x100000000000000000000000000000000"})
    EXPECT_THROW(TagId::parse(bad), std::invalid_argument) << bad;
}

TEST(TagId, Digits) {
  // 6789 in base 4, least significant first: 1 1 0 2 2 2 1 (SPEC 1).
  const int expected[] = {1, 1, 0, 2, 2, 2, 1};
  for (int k = 0; k < 7; ++k) EXPECT_EQ(TagId(6789).digit(k), expected[k]);
  TagId id;
  for (int k = 0; k < 7; ++k) id = id.with_digit(k, expected[k]);
  EXPECT_EQ(id, TagId(6789));
  // Digits above bit 64.
  const TagId big = TagId().with_digit(61, 3).with_digit(32, 2);
  EXPECT_EQ(big.digit(61), 3);
  EXPECT_EQ(big.digit(32), 2);
  EXPECT_EQ(big, TagId(std::uint64_t{3} << 58, 0).with_digit(32, 2));
}

TEST(TagId, FitsIn53Bits) {
  EXPECT_TRUE(TagId((1ull << 53) - 1).fits_53_bits());
  EXPECT_FALSE(TagId(1ull << 53).fits_53_bits());
  EXPECT_FALSE(TagId(1, 0).fits_53_bits());
}

TEST(TagId, ParsesLists) {
  const auto ids = lftag::parse_id_list("7,0x10,3-5");
  ASSERT_EQ(ids.size(), 5u);
  EXPECT_EQ(ids[1], TagId(16));
  EXPECT_EQ(ids[4], TagId(5));
  EXPECT_THROW(lftag::parse_id_list("5-3"), std::invalid_argument);
  // Ranges at the top of 64 bits end (they used to wrap round to 0 and never stop).
  const auto top = lftag::parse_id_list("18446744073709551614-18446744073709551615");
  ASSERT_EQ(top.size(), 2u);
  EXPECT_EQ(top[1].to_decimal(), "18446744073709551615");
  EXPECT_EQ(lftag::parse_id_list("18446744073709551615-18446744073709551615").size(), 1u);
  EXPECT_THROW(lftag::parse_id_list("1,,2"), std::invalid_argument);
  // Spaces as family lists allow them; a negative id says so (it once read as an empty
  // range start, "id '' is not a number").
  EXPECT_EQ(lftag::parse_id_list("1, 2").size(), 2u);
  EXPECT_EQ(lftag::parse_id_list(" 3 - 5 ,7 ").size(), 4u);
  try {
    lftag::parse_id_list("-1");
    ADD_FAILURE() << "-1 was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("negative"), std::string::npos) << e.what();
  }
  EXPECT_THROW(lftag::parse_id_list("0-99", 10), std::invalid_argument);
  EXPECT_THROW(lftag::parse_id_list("1,2,3", 2), std::invalid_argument);
  EXPECT_EQ(lftag::parse_id_list("340282366920938463463374607431768211455").front(), TagId(~0ull, ~0ull));
}
