// SPDX-License-Identifier: LGPL-2.1-or-later
#include <random>

#include <gtest/gtest.h>

#include "lftag/family.hpp"

using lftag::Family;
using lftag::TagId;

namespace {

TagId random_id(const Family& f, std::mt19937_64& rng) {
  TagId id;
  for (int k = 0; k < f.data_cell_count(); ++k) id = id.with_digit(k, int(rng() & 3));
  return id;
}

// Decoding from geometry: the digit of each data cell is read back from its centre.
TagId decode_centres(const Family& f, const std::vector<cv::Point2d>& centres) {
  TagId id;
  for (int g = 0; g < f.cell_count(); ++g) {
    if (f.is_baseline(g)) continue;
    const cv::Point2d d = centres[g] - f.nominal_center(g);
    const int digit = (d.x > 0 ? 2 : 0) | (d.y > 0 ? 1 : 0);
    id = id.with_digit(f.data_index(g), digit);
  }
  return id;
}

}  // namespace

TEST(Family, ParsesNamesAndRejectsUnknown) {
  EXPECT_EQ(Family::parse("3x3").n(), 3);
  EXPECT_EQ(Family::parse("8x8").name(), "8x8");
  EXPECT_EQ(Family::parse("4X4").n(), 4);
  EXPECT_EQ(Family::parse(" 4x4\t").n(), 4);
  for (const char* bad : {"1x1", "9x9", "3x4", "3", "", " ", "33", "3 x3", "3xx3", "10x10"}) {
    try {
      Family::parse(bad);
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("2x2"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(Family(1), std::invalid_argument);
  EXPECT_THROW(Family(9), std::invalid_argument);
  const auto list = Family::parse_list("3x3,4x4,3x3");
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list[1].n(), 4);
  EXPECT_THROW(Family::parse_list("3x3,"), std::invalid_argument);
  const auto spaced = Family::parse_list("3x3, 4X4");
  ASSERT_EQ(spaced.size(), 2u);
  EXPECT_EQ(spaced[1].n(), 4);
  try {
    Family::parse_list("3x3, 9x9");
    ADD_FAILURE() << "9x9 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("' 9x9'"), std::string::npos) << e.what();
  }
}

TEST(Family, SizesAndDictionaries) {
  const char* sizes[] = {"16",
                         "16384",
                         "268435456",
                         "70368744177664",
                         "295147905179352825856",
                         "19807040628566084398385987584",
                         "21267647932558653966460912964485513216"};
  for (const Family& f : Family::all()) {
    EXPECT_EQ(f.side(), 6 * (f.n() + 1));
    EXPECT_EQ(f.dictionary_size(), sizes[f.n() - 2]) << f.name();
  }
  EXPECT_EQ(Family(3).max_id(), TagId(16383));
  EXPECT_EQ(Family(8).max_id(), TagId(~0ull >> 4, ~0ull));
}

TEST(Family, RejectsOutOfRangeIds) {
  EXPECT_NO_THROW(Family(3).require(16383));
  try {
    Family(3).require(16384);
    ADD_FAILURE();
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("16383"), std::string::npos);
  }
  EXPECT_THROW(Family(2).centers(16), std::out_of_range);
  EXPECT_THROW(Family(8).require(TagId(1ull << 60, 0)), std::out_of_range);
}

TEST(Family, SpecGeometryOf3x3) {
  const Family f(3);
  EXPECT_EQ(f.side(), 24);
  // Id 0: every data square at its top-left position.
  const auto c0 = f.centers(0);
  EXPECT_EQ(c0[0], cv::Point2d(6, 6));
  EXPECT_EQ(c0[2], cv::Point2d(18, 6));
  EXPECT_EQ(c0[1], cv::Point2d(11.5, 5.5));
  EXPECT_EQ(c0[3], cv::Point2d(5.5, 11.5));
  EXPECT_EQ(c0[8], cv::Point2d(17.5, 17.5));
  // Id 6789: cells 0 and 1 lower, 3, 4 and 5 further right, 6 lower.
  const auto c = f.centers(6789);
  EXPECT_EQ(c[1], cv::Point2d(11.5, 6.5));   // data cell 0
  EXPECT_EQ(c[3], cv::Point2d(5.5, 12.5));   // data cell 1
  EXPECT_EQ(c[4], cv::Point2d(11.5, 11.5));  // data cell 2
  EXPECT_EQ(c[5], cv::Point2d(18.5, 11.5));  // data cell 3
  EXPECT_EQ(c[6], cv::Point2d(6.5, 17.5));   // data cell 4
  EXPECT_EQ(c[7], cv::Point2d(12.5, 17.5));  // data cell 5
  EXPECT_EQ(c[8], cv::Point2d(17.5, 18.5));  // data cell 6
  const auto kp = f.keypoints(6789);
  EXPECT_EQ(kp[0], cv::Point2d(6, 6));
  EXPECT_EQ(kp[1], cv::Point2d(18, 6));
  EXPECT_EQ(kp[2], cv::Point2d(6.5, 17.5));
  EXPECT_EQ(kp[3], cv::Point2d(17.5, 18.5));
}

TEST(Family, UnitBitmapMatchesTheSpecDrawing) {
  // SPEC 1, 3x3 id 0, row by row ('#' and digits black).
  const char* rows[] = {
      "########################", "########################", "##....................##", "##....................##",
      "##..BBBB..000...BBBB..##", "##..BBBB..000...BBBB..##", "##..BBBB..000...BBBB..##", "##..BBBB........BBBB..##",
      "##....................##", "##....................##", "##..111...222...333...##", "##..111...222...333...##",
      "##..111...222...333...##", "##....................##", "##....................##", "##....................##",
      "##..444...555...666...##", "##..444...555...666...##", "##..444...555...666...##", "##....................##",
      "##....................##", "##....................##", "########################", "########################"};
  const cv::Mat1b bits = Family(3).unit_bitmap(0);
  ASSERT_EQ(bits.rows, 24);
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 24; ++x) EXPECT_EQ(bits(y, x) == 0, rows[y][x] != '.') << x << "," << y;
}

TEST(Family, IdRoundTripThroughGeometryForEveryFamily) {
  std::mt19937_64 rng(7);
  for (const Family& f : Family::all()) {
    std::vector<TagId> ids = {0, f.max_id()};
    for (int i = 0; i < 50; ++i) ids.push_back(random_id(f, rng));
    for (TagId id : ids) {
      ASSERT_TRUE(f.contains(id));
      EXPECT_EQ(decode_centres(f, f.centers(id)), id) << f.name() << " " << id.to_decimal();
      // Squares never overlap and stay inside the white interior.
      const auto squares = f.black_squares(id);
      ASSERT_EQ(int(squares.size()), f.cell_count());
      for (const auto& s : squares) {
        EXPECT_GE(s.x, 4);
        EXPECT_LE(s.x + s.width, f.side() - 4);
        EXPECT_LE(s.y + s.height, f.side() - 4);
      }
    }
  }
  // Ids above 64 bits keep every digit.
  const Family f8(8);
  const TagId big = TagId::parse("21267647932558653966460912964485513215");
  EXPECT_EQ(big, f8.max_id());
  EXPECT_EQ(decode_centres(f8, f8.centers(big)), big);
}

TEST(Family, CellIndexing) {
  for (const Family& f : Family::all()) {
    int k = 0;
    for (int g = 0; g < f.cell_count(); ++g) {
      if (f.is_baseline(g)) {
        EXPECT_EQ(f.data_index(g), -1);
        continue;
      }
      EXPECT_EQ(f.data_index(g), k);
      EXPECT_EQ(f.grid_index(k), g);
      ++k;
    }
    EXPECT_EQ(k, f.data_cell_count());
    const auto kc = f.keypoint_cells();
    EXPECT_EQ(f.nominal_center(kc[2]), cv::Point2d(6, f.side() - 6));
    EXPECT_EQ(f.nominal_center(kc[3]), cv::Point2d(f.side() - 6, f.side() - 6));
  }
}

TEST(Family, MetricFrame) {
  const Family f(4);  // S = 30
  EXPECT_EQ(f.to_marker_frame({15, 15}, 0.3), cv::Point3d(0, 0, 0));
  const cv::Point3d c = f.to_marker_frame({0, 30}, 0.3);
  EXPECT_NEAR(c.x, -0.15, 1e-12);
  EXPECT_NEAR(c.y, 0.15, 1e-12);
}
