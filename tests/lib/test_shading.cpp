// SPDX-License-Identifier: LGPL-2.1-or-later
// The paper's light under a marker (src/detect/shading.cpp).
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "lftag/render.hpp"
#include "stages.hpp"

using namespace lftag;

namespace {

// A 3x3 marker of 9 px a unit (216 px) at (40, 40) on paper of 200, its outline, and the
// light on the frame: 1 left of column `edge`, `shadow` from it on (a hard shadow's edge
// across the marker), or 1 everywhere.
struct Lit {
  cv::Mat1b image;
  std::array<cv::Point2d, 4> outline;
};
Lit lit_marker(int edge = 10000, double shadow = 1) {
  const cv::Mat1b marker = rasterize_marker(Family(3), 1234, 9, 0);  // 216 x 216, 0 and 255
  Lit out;
  out.image = cv::Mat1b(300, 300, std::uint8_t(200));
  cv::Mat1b inside = out.image(cv::Rect(40, 40, marker.cols, marker.rows));
  marker.convertTo(inside, CV_8U, 180.0 / 255, 20);  // ink 20, paper 200
  for (int y = 0; y < out.image.rows; ++y)
    for (int x = edge; x < out.image.cols; ++x)
      out.image(y, x) = cv::saturate_cast<std::uint8_t>(out.image(y, x) * shadow);
  out.outline = {cv::Point2d(39.5, 39.5), cv::Point2d(255.5, 39.5), cv::Point2d(255.5, 255.5),
                 cv::Point2d(39.5, 255.5)};
  return out;
}

}  // namespace

TEST(PaperLevel, FillsTheDarkFeaturesAndKeepsAShadowsEdge) {
  // Squares of 8 px closed by 11 px: paper everywhere, 200 left of the edge, 90 right of it.
  cv::Mat1b grey(60, 120, std::uint8_t(200));
  for (int x = 5; x < 110; x += 16) grey(cv::Rect(x, 20, 8, 8)).setTo(10);
  grey(cv::Rect(60, 0, 60, 60)) *= 0.45;
  const cv::Mat1b paper = detail::paper_level(grey, 11);
  for (int x = 0; x < 120; ++x) EXPECT_EQ(paper(24, x), x < 60 ? 200 : 90) << x;
}

TEST(FilledBasins, FillsAFeatureWiderThanTheClosingThatPaperEncloses) {
  // A 20 px square is wider than the closing's 11 px: closed, it stays dark, but paper
  // encloses it, so no light reaches it that does not reach the paper around it.
  cv::Mat1b grey(60, 120, std::uint8_t(200));
  grey(cv::Rect(30, 20, 20, 20)).setTo(10);
  grey(cv::Rect(90, 0, 30, 60)) *= 0.45;  // a shadow from the edge on stays
  const cv::Mat1b closed = detail::paper_level(grey, 11);
  EXPECT_EQ(closed(30, 40), 10);
  const cv::Mat1b paper = detail::filled_basins(closed);
  for (int x = 0; x < 120; ++x) EXPECT_EQ(paper(30, x), x < 90 ? 200 : 90) << x;
}

TEST(EvenLight, NoneWhereTheLightIsEven) {
  EXPECT_FALSE(detail::even_light(ImageView(lit_marker().image), lit_marker().outline, Family(3)));
  // A gentle gradient across the marker: 6 %, under kMinPaperSpread's 20 %.
  Lit graded = lit_marker();
  for (int y = 0; y < graded.image.rows; ++y)
    for (int x = 0; x < graded.image.cols; ++x)
      graded.image(y, x) = std::uint8_t(graded.image(y, x) * (1 - 0.06 * x / 300));
  EXPECT_FALSE(detail::even_light(ImageView(graded.image), graded.outline, Family(3)));
}

TEST(EvenLight, TakesAShadowOut) {
  const Lit shadowed = lit_marker(150, 0.45);
  const std::optional<detail::EvenLight> even =
      detail::even_light(ImageView(shadowed.image), shadowed.outline, Family(3));
  ASSERT_TRUE(even);
  const cv::Mat1b& p = even->pixels;
  // The white ring (units 2 to 4 from the border's outer edge: 18 to 36 px) on either side
  // of the shadow's edge, and the border: the same levels as in the light.
  const auto at = [&](int x, int y) { return int(p(y - even->origin.y, x - even->origin.x)); };
  EXPECT_NEAR(at(100, 40 + 27), 200, 4);  // lit ring
  EXPECT_NEAR(at(200, 40 + 27), 200, 6);  // shadowed ring
  EXPECT_NEAR(at(100, 40 + 9), 20, 4);    // lit border
  EXPECT_NEAR(at(200, 40 + 9), 20, 6);    // shadowed border
}

TEST(EvenLight, NoneForAMarkerSmearedByMotion) {
  // Smeared along a diagonal by 6 units, a baseline joins the border's corner in a dark
  // patch wider than the closing (the dimmest tenth of the ring was at 0.71 of its
  // brightest, closed alone): the marker's own ink, not light.
  Lit smeared = lit_marker();
  cv::filter2D(smeared.image, smeared.image, -1, motion_blur_kernel(54, 45), cv::Point(-1, -1), 0,
               cv::BORDER_REPLICATE);
  EXPECT_FALSE(detail::even_light(ImageView(smeared.image), smeared.outline, Family(3)));
}

TEST(EvenLight, NoneForAMarkerWithNoPaperBetweenItsSquares) {
  // 1.5 px a unit: gaps of 3 px, no pure paper after the squares' edges.
  std::array<cv::Point2d, 4> small;
  const double side = 24 * 1.5;
  small = {cv::Point2d(40, 40), cv::Point2d(40 + side, 40), cv::Point2d(40 + side, 40 + side),
           cv::Point2d(40, 40 + side)};
  EXPECT_FALSE(detail::even_light(ImageView(lit_marker(150, 0.45).image), small, Family(3)));
}
