// SPDX-License-Identifier: LGPL-2.1-or-later
// The second look (src/detect/second_look.cpp): which clusters of the frame's binary image
// are looked at again, and how their patch is enlarged and binarised.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "binary.hpp"
#include "lftag/render.hpp"
#include "stages.hpp"

using namespace lftag;

namespace {

// Ink 30 and paper 220 where `black` is non-zero and zero, blurred by a Gaussian of
// `sigma` pixels (none: sharp).
cv::Mat1b grey_of(const cv::Mat1b& black, double sigma) {
  cv::Mat1b grey(black.size(), std::uint8_t(220));
  grey.setTo(30, black);
  if (sigma > 0) cv::GaussianBlur(grey, grey, cv::Size(), sigma, sigma, cv::BORDER_REPLICATE);
  return grey;
}

// The near-candidates of a binary image, with the grey levels `grey`; by default those of
// a blurred print of it, whose binary image does not explain them all (so that only the
// binary image's shapes decide).
std::vector<cv::Rect> clusters_of(const cv::Mat1b& black, const std::vector<cv::Rect>& taken = {},
                                  const detail::SecondLook& look = {}, cv::Mat1b grey = {}) {
  if (grey.empty()) grey = grey_of(black, 2);
  const detail::BinaryImage binary = test::binary_from_mask(black);
  detail::RegionTree tree;
  detail::RegionLabeller().label(binary, tree);
  return detail::near_candidates(tree, binary, ImageView(grey), look, taken);
}

// The binary image of a resolved `family` marker, `scale` pixels per unit, at (x, y) on
// white: 255 where black.
cv::Mat1b resolved_marker(const Family& family, int scale, cv::Size size, int x, int y) {
  cv::Mat1b units = family.unit_bitmap(TagId(0)), pixels;
  cv::resize(units, pixels, cv::Size(), scale, scale, cv::INTER_NEAREST);
  cv::Mat1b black(size, std::uint8_t(0));
  black(cv::Rect(x, y, pixels.cols, pixels.rows)).setTo(255, pixels < 128);
  return black;
}

// A far marker as its binary image shows it: half ink, in pieces that touch only at
// their corners (black is 4-connected), here a 20 x 20 checkerboard of 2 x 2 pieces at
// (x, y).
void draw_pieces(cv::Mat1b& black, int x, int y) {
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j)
      if ((i + j) % 2 == 0) black(cv::Rect(x + 2 * j, y + 2 * i, 2, 2)).setTo(255);
}

}  // namespace

TEST(NearCandidates, AClusterOfPiecesOnPaperIsLookedAt) {
  cv::Mat1b black(120, 160, std::uint8_t(0));
  draw_pieces(black, 30, 40);
  const std::vector<cv::Rect> boxes = clusters_of(black);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_EQ(boxes[0], cv::Rect(30, 40, 20, 20));
}

TEST(NearCandidates, BlobsLettersTexturesAndTakenPlacesAreNot) {
  cv::Mat1b black(120, 300, std::uint8_t(0));
  black(cv::Rect(10, 10, 20, 20)).setTo(255);                       // a solid blob: all ink
  cv::circle(black, cv::Point(60, 20), 8, 255, 2);                  // a letter o: one piece and its hole
  cv::line(black, cv::Point(100, 10), cv::Point(160, 25), 255, 2);  // a stroke: too thin a box
  EXPECT_TRUE(clusters_of(black).empty());
  // Pieces on a dark ground rather than on paper.
  cv::Mat1b ground(120, 160, std::uint8_t(255));
  ground(cv::Rect(28, 38, 24, 24)).setTo(0);
  draw_pieces(ground, 30, 40);
  EXPECT_TRUE(clusters_of(ground).empty());
  // A texture of pieces larger than any marker looked at.
  cv::Mat1b texture(300, 300, std::uint8_t(0));
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 10; ++x) draw_pieces(texture, 20 + 20 * x, 20 + 20 * y);
  EXPECT_TRUE(clusters_of(texture).empty());
  // A marker already found there.
  cv::Mat1b alone(120, 160, std::uint8_t(0));
  draw_pieces(alone, 30, 40);
  EXPECT_TRUE(clusters_of(alone, {cv::Rect(25, 35, 30, 30)}).empty());
  EXPECT_EQ(clusters_of(alone, {cv::Rect(100, 35, 30, 30)}).size(), 1u);
  // Too small, too large.
  cv::Mat1b tiny(60, 60, std::uint8_t(0));
  tiny(cv::Rect(20, 20, 2, 2)).setTo(255), tiny(cv::Rect(23, 20, 2, 2)).setTo(255);
  tiny(cv::Rect(20, 23, 2, 2)).setTo(255), tiny(cv::Rect(23, 23, 2, 2)).setTo(255);
  EXPECT_TRUE(clusters_of(tiny).empty());
  cv::Mat1b huge(400, 400, std::uint8_t(0));
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 10; ++x) huge(cv::Rect(50 + 25 * x, 50 + 25 * y, 16, 16)).setTo(255);
  EXPECT_TRUE(clusters_of(huge).empty());
}

// In a dim frame the threshold's offset is within the sensor's noise, and flat paper
// breaks into specks that cluster as a far marker's pieces do: a cluster is looked at only
// when its ink stands well out of the frame's noise (kMinNoiseContrast of 6 deviations).
TEST(NearCandidates, ClustersOfSensorNoiseAreNot) {
  cv::Mat1b black(120, 160, std::uint8_t(0));
  draw_pieces(black, 30, 40);
  const auto looked_at = [&](int contrast, double noise) {
    cv::Mat1b grey(black.size(), std::uint8_t(120));
    grey.setTo(120 - contrast, black);
    detail::SecondLook look;
    look.noise = noise;
    return clusters_of(black, {}, look, grey).size();
  };
  EXPECT_EQ(looked_at(15, 0), 1u);  // a faint cluster in a clean frame
  EXPECT_EQ(looked_at(15, 5), 0u);  // the noise's own dark tail: 3 deviations
  EXPECT_EQ(looked_at(29, 5), 0u);
  EXPECT_EQ(looked_at(31, 5), 1u);
  EXPECT_EQ(looked_at(60, 5), 1u);  // a dim frame's far marker
}

TEST(NearCandidates, AClosedBorderAroundSomeSquaresIsLookedAt) {
  // A marker turned 45 degrees whose border stayed closed, two of its nine squares joined
  // to it: its box is only a quarter ink, so it fails as a cluster, but the border with
  // seven squares in its hole is looked at. Specks of the background that reach into the
  // box's corners do not matter.
  const cv::Point2d centre(80, 60);
  const auto at = [&](double u, double v) {  // marker units (0..24) -> pixels, 40 px edge
    const double s = 40.0 / 24 / std::sqrt(2.0);
    return cv::Point(cvRound(centre.x + s * ((u - 12) - (v - 12))), cvRound(centre.y + s * ((u - 12) + (v - 12))));
  };
  const auto fill = [&](cv::Mat1b& image, double u0, double v0, double u1, double v1) {
    const std::vector<cv::Point> q = {at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1)};
    cv::fillConvexPoly(image, q, 255);
  };
  cv::Mat1b black(120, 160, std::uint8_t(0));
  fill(black, 0, 0, 24, 24);
  cv::Mat1b hole(black.size(), std::uint8_t(0));
  fill(hole, 2, 2, 22, 22);
  black.setTo(0, hole);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) fill(black, 5 + 6 * c, 5 + 6 * r, 9 + 6 * c, 9 + 6 * r);
  fill(black, 1, 5, 6, 9), fill(black, 17, 18, 23, 22);  // two squares joined to the border
  black(cv::Rect(52, 32, 3, 3)).setTo(255), black(cv::Rect(105, 85, 3, 3)).setTo(255);  // specks
  const std::vector<cv::Rect> boxes = clusters_of(black);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_NEAR(boxes[0].x + boxes[0].width / 2.0, centre.x, 3);
  EXPECT_NEAR(boxes[0].y + boxes[0].height / 2.0, centre.y, 3);
  EXPECT_NEAR(boxes[0].width, 57, 4);
  // The same border on a dark ground, with hardly any paper around it, is not.
  cv::Mat1b ground(black.size(), std::uint8_t(255));
  cv::Mat1b paper(black.size(), std::uint8_t(0));
  fill(paper, -1, -1, 25, 25);
  ground.setTo(0, paper);
  EXPECT_TRUE(clusters_of(ground | black).empty());
}

TEST(NearCandidates, ABorderWithItsSquaresSmearedIntoItIsLookedAt) {
  // A marker under a long vertical motion blur: each column of squares smeared into one
  // strip joined to the top of the border, so the border holds no piece, and its one hole
  // is the gaps between the strips (joined along the bottom), with the white ring's sides
  // still lining the border's. The hole spans the border's box but fills little of its
  // own box: looked at. The same border around a plain hole (a picture frame) is not, nor
  // is one whose gaps do not line both sides (data cells joined to one side, as in
  // another family's marker).
  cv::Mat1b black(110, 100, std::uint8_t(0));
  const cv::Rect border(20, 20, 61, 67);
  cv::rectangle(black, border, 255, cv::FILLED);
  black(cv::Rect(24, 24, 53, 59)).setTo(0);
  const cv::Mat1b frame = black.clone();
  for (const int x : {28, 42, 56}) black(cv::Rect(x, 24, 10, 52)).setTo(255);
  const std::vector<cv::Rect> boxes = clusters_of(black);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_EQ(boxes[0], border);
  EXPECT_TRUE(clusters_of(frame).empty());
  cv::Mat1b one_side = black.clone();
  one_side(cv::Rect(66, 24, 11, 40)).setTo(255);  // the right gap filled on most rows
  EXPECT_TRUE(clusters_of(one_side).empty());
}

TEST(NearCandidates, ASmallMarkerWhoseBorderBrokeOpenIsLookedAtAlone) {
  // A 3x3 marker of 40 px turned 25 degrees whose border the threshold broke open on one
  // side, two of its squares joined to the border, on a clean margin; but specks of the
  // background reach into its box's corners and a chain of them joins its cluster, which
  // outgrows a marker. The border with the pieces inside its box is looked at alone. At
  // 60 px (a box of 80 px) a marker keeps its border closed: not looked at so; nor is one
  // with ink on its margin.
  const auto marker = [](double edge, bool ink_on_margin) {
    const cv::Point2d centre(110, 110);
    const auto at = [&](double u, double v) {  // marker units (0..24) -> pixels, turned 25 degrees
      const double s = edge / 24, c = std::cos(25 * CV_PI / 180), n = std::sin(25 * CV_PI / 180);
      return cv::Point(cvRound(centre.x + s * (c * (u - 12) - n * (v - 12))),
                       cvRound(centre.y + s * (n * (u - 12) + c * (v - 12))));
    };
    const auto fill = [&](cv::Mat1b& image, double u0, double v0, double u1, double v1, std::uint8_t value) {
      const std::vector<cv::Point> q = {at(u0, v0), at(u1, v0), at(u1, v1), at(u0, v1)};
      cv::fillConvexPoly(image, q, value);
    };
    cv::Mat1b black(220, 220, std::uint8_t(0));
    fill(black, 0, 0, 24, 24, 255);
    fill(black, 2, 2, 22, 22, 0);
    fill(black, 22, 8, 24, 16, 0);  // the border broken open
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) fill(black, 5 + 6 * c, 5 + 6 * r, 9 + 6 * c, 9 + 6 * r, 255);
    fill(black, 1, 5, 6, 9, 255), fill(black, 17, 1, 21, 6, 255);  // two squares joined to the border
    // Specks in the box's top-left corner, and a chain of them running off to the corner
    // of the frame (touching diagonally: apart, but their boxes meet).
    const cv::Rect box = cv::boundingRect(black);
    for (int k = 0; k < 20; ++k) black(cv::Rect(box.x - 2 * k, box.y - 2 * k, 2, 2)).setTo(255);
    if (ink_on_margin) cv::circle(black, at(12, 12), int(edge * 0.85), 255, 1);
    return black;
  };
  const cv::Mat1b small = marker(40, false);
  const std::vector<cv::Rect> boxes = clusters_of(small);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_NEAR(boxes[0].x + boxes[0].width / 2.0, 110, 3);
  EXPECT_NEAR(boxes[0].y + boxes[0].height / 2.0, 110, 3);
  EXPECT_NEAR(boxes[0].width, 53, 3);  // 40 (cos 25 + sin 25)
  EXPECT_TRUE(clusters_of(marker(60, false)).empty());
  EXPECT_TRUE(clusters_of(marker(40, true)).empty());
}

TEST(NearCandidates, ResolvedMarkersOfLargerFamiliesAreNot) {
  // A 4x4 and a 5x5 marker that the binary image resolved, every square apart: sought
  // with families up to 3x3, no second look can make either a 3x3 (blur only joins
  // squares), so neither is looked at; with 4x4 sought the 4x4 is, and with every family
  // both are.
  const Family four(4), five(5);
  const cv::Mat1b black =
      resolved_marker(four, 3, cv::Size(400, 200), 20, 40) | resolved_marker(five, 3, cv::Size(400, 200), 220, 40);
  detail::SecondLook upto3, upto4;
  upto3.sought = 0b1100, upto4.sought = 0b11100;  // bit n: n x n
  EXPECT_TRUE(clusters_of(black, {}, upto3).empty());
  const std::vector<cv::Rect> four_only = clusters_of(black, {}, upto4);
  ASSERT_EQ(four_only.size(), 1u);
  EXPECT_EQ(four_only[0], cv::Rect(20, 40, 3 * four.side(), 3 * four.side()));
  EXPECT_EQ(clusters_of(black).size(), 2u);
  // Sixteen pieces of very unequal sizes in the hole (a 3x3 marker's large squares
  // broken up, say) are no 4x4 marker: looked at with families up to 3x3.
  cv::Mat1b broken = resolved_marker(four, 3, cv::Size(400, 200), 20, 40);
  const cv::Rect first_square(20 + 3 * 4, 40 + 3 * 4, 12, 12);
  cv::Mat1b square = broken(first_square);
  ASSERT_EQ(cv::countNonZero(square), 144);  // the top-left baseline square, whole
  square.setTo(0);
  square(cv::Rect(5, 5, 2, 2)).setTo(255);  // a speck where it was
  EXPECT_EQ(clusters_of(broken, {}, upto3).size(), 1u);
  // A small 3x3 marker whose squares the mean threshold broke (as one of 31 px did in the
  // range sweep): 4 x 4 pieces of 3 x 3 pixels in its hole. Too small to be a 4x4
  // marker's squares: looked at.
  cv::Mat1b small(100, 100, std::uint8_t(0));
  small(cv::Rect(30, 30, 32, 32)).setTo(255);
  small(cv::Rect(32, 32, 28, 28)).setTo(0);
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) small(cv::Rect(34 + 7 * j, 34 + 7 * i, 3, 3)).setTo(255);
  EXPECT_EQ(clusters_of(small, {}, upto3).size(), 1u);
  // The same with pieces of 4 x 4 pixels: a 4x4 marker's squares.
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) small(cv::Rect(34 + 7 * j, 34 + 7 * i, 4, 4)).setTo(255);
  EXPECT_TRUE(clusters_of(small, {}, upto3).empty());
}

TEST(NearCandidates, SharpResolvedMarkersOfSmallerFamiliesNotSoughtAreNot) {
  // A sharp 5x5 marker at 2 px per unit, turned by 30 degrees: 72 px, its features a few
  // pixels wide, so a sharp cluster of fine features like any other. With 5x5 and 8x8
  // sought it is looked at; with 8x8 alone its binary image shows a 5x5 marker's squares
  // and explains its grey levels, so it is not.
  const Family five(5);
  const auto turned = [&](const cv::Mat1b& black) {
    cv::Mat1b out;
    const cv::Point2f centre(black.cols / 2.0f, black.rows / 2.0f);
    cv::warpAffine(black, out, cv::getRotationMatrix2D(centre, 30, 1), black.size(), cv::INTER_NEAREST);
    return out;
  };
  const cv::Mat1b marker = turned(resolved_marker(five, 2, cv::Size(200, 200), 64, 64));
  cv::Mat1b noise(marker.size());
  cv::randn(noise, 0, 3);
  cv::Mat1b sharp = grey_of(marker, 0);
  sharp += noise;
  detail::SecondLook five_and_eight, eight;
  five_and_eight.sought = 0b100100000, eight.sought = 0b100000000;  // bit n: n x n
  EXPECT_EQ(clusters_of(marker, {}, five_and_eight, sharp).size(), 1u);
  EXPECT_TRUE(clusters_of(marker, {}, eight, sharp).empty());
  // Blurred by 2 px it is looked at: a blur that joins a larger marker's squares leaves
  // mid grey between them.
  EXPECT_EQ(clusters_of(marker, {}, eight, grey_of(marker, 2)).size(), 1u);
  // So is one with a square 2.5 times the others, as two joined squares of a larger
  // marker would be.
  cv::Mat1b uneven = resolved_marker(five, 2, cv::Size(200, 200), 64, 64);
  const cv::Rect square(64 + 2 * 10, 64 + 2 * 16, 6, 6);  // the data square of row 2, column 1
  ASSERT_EQ(cv::countNonZero(uneven(square)), 36);
  uneven(cv::Rect(square.x - 2, square.y - 1, 10, 9)).setTo(255);
  uneven = turned(uneven);
  sharp = grey_of(uneven, 0);
  sharp += noise;
  EXPECT_EQ(clusters_of(uneven, {}, eight, sharp).size(), 1u);
}

TEST(NearCandidates, SharpClustersOfAMarkersSizeAreNotLookedAtAgain) {
  // Another kind of marker, sharp and 96 px: a border around a hole with data blobs of
  // several shapes. Its binary image explains its grey levels (the mid grey is on its
  // edges), so a second look at the same resolution would see the same: not looked at.
  // Blurred by 2 px, it is; and so is a sharp one of 48 px, which a second look enlarges.
  const auto pattern = [](int cell_w, int cell_h) {  // 8 x 8 cells of cell_w x cell_h px, at (40, 40)
    cv::Mat1b black(80 + 8 * cell_h, 80 + 8 * cell_w, std::uint8_t(0));
    const auto ink = [&](int c, int r, int w, int h) {
      black(cv::Rect(40 + c * cell_w, 40 + r * cell_h, w * cell_w, h * cell_h)).setTo(255);
    };
    ink(0, 0, 8, 1), ink(0, 7, 8, 1), ink(0, 1, 1, 6), ink(7, 1, 1, 6);  // the border
    ink(2, 2, 1, 1), ink(4, 2, 2, 1), ink(2, 4, 2, 2), ink(5, 4, 1, 2);  // data blobs
    return black;
  };
  const cv::Mat1b large = pattern(12, 12), small = pattern(6, 6);
  cv::Mat1b noise(large.size());
  cv::randn(noise, 0, 3);
  cv::Mat1b sharp = grey_of(large, 0);
  sharp += noise;
  EXPECT_TRUE(clusters_of(large, {}, {}, sharp).empty());
  const cv::Mat1b blurred = grey_of(large, 2);
  const std::vector<cv::Rect> boxes = clusters_of(large, {}, {}, blurred);
  ASSERT_EQ(boxes.size(), 1u);
  EXPECT_EQ(boxes[0], cv::Rect(40, 40, 96, 96));
  EXPECT_EQ(clusters_of(small, {}, {}, grey_of(small, 0)).size(), 1u);
  // A sharp cluster whose features are a few pixels wide is looked at too: the frame's
  // 16 px mean threshold can fail on it where the second look's own threshold does not
  // (sharp 5x5 to 8x8 markers tilted 60 to 70 degrees were found so). Here pieces of
  // 3 x 3 px touching at their corners, 72 x 24 px in all; the same with pieces of 12 px
  // is not looked at.
  const auto checkerboard = [](int piece, int columns, int rows) {
    cv::Mat1b black(80 + rows * piece, 80 + columns * piece, std::uint8_t(0));
    for (int r = 0; r < rows; ++r)
      for (int c = 0; c < columns; ++c)
        if ((r + c) % 2 == 0) black(cv::Rect(40 + c * piece, 40 + r * piece, piece, piece)).setTo(255);
    return black;
  };
  const cv::Mat1b fine = checkerboard(3, 24, 8), coarse = checkerboard(12, 8, 8);
  EXPECT_EQ(clusters_of(fine, {}, {}, grey_of(fine, 0)).size(), 1u);
  EXPECT_EQ(clusters_of(coarse, {}, {}, grey_of(coarse, 2)).size(), 1u);
  EXPECT_TRUE(clusters_of(coarse, {}, {}, grey_of(coarse, 0)).empty());
}

TEST(NearCandidates, EachBoundRefusesAClusterJustOutsideIt) {
  // The bounds at the top of second_look.cpp, each with a cluster just inside it (looked
  // at) and one just outside (not), all else alike.
  // Ink over the box, 0.35 to 0.8: a black 21 x 21 square with four holes (5 pieces).
  const auto holed = [](const std::vector<cv::Rect>& holes) {
    cv::Mat1b black(100, 100, std::uint8_t(0));
    black(cv::Rect(40, 40, 21, 21)).setTo(255);
    for (const cv::Rect& h : holes) black(h + cv::Point(40, 40)).setTo(0);
    return black;
  };
  const auto four_holes = [](cv::Size a, cv::Size b, cv::Size c, cv::Size d) {
    return std::vector<cv::Rect>{{{1, 1}, a}, {{11, 1}, b}, {{1, 11}, c}, {{11, 11}, d}};
  };
  const cv::Size big(8, 9), smaller(7, 9), small(5, 5), tiny(4, 5);
  EXPECT_EQ(clusters_of(holed(four_holes(big, big, big, smaller))).size(), 1u);      // 162 / 441 = 0.367
  EXPECT_TRUE(clusters_of(holed(four_holes(big, big, big, big))).empty());           // 153 / 441 = 0.347
  EXPECT_EQ(clusters_of(holed(four_holes(small, small, small, small))).size(), 1u);  // 341 / 441 = 0.773
  EXPECT_TRUE(clusters_of(holed(four_holes(tiny, tiny, tiny, tiny))).empty());       // 361 / 441 = 0.819
  // Four pieces at least: the square with three holes (4 pieces, ink 0.51) and with two
  // (3 pieces, ink 0.50).
  EXPECT_EQ(clusters_of(holed({{{1, 1}, big}, {{11, 1}, big}, {{1, 11}, big}})).size(), 1u);
  EXPECT_TRUE(clusters_of(holed({{{1, 1}, cv::Size(19, 5)}, {{1, 12}, cv::Size(19, 6)}})).empty());

  // Longer side over shorter, 3 at most: checkerboards of 2 px pieces 30 x 10 and 32 x 10.
  const auto board = [](int w, int h) {
    cv::Mat1b black(100, 100, std::uint8_t(0));
    for (int y = 0; y < h; y += 2)
      for (int x = 0; x < w; x += 2)
        if ((x + y) % 4 == 0) black(cv::Rect(30 + x, 40 + y, 2, 2)).setTo(255);
    return black;
  };
  EXPECT_EQ(clusters_of(board(30, 10)).size(), 1u);
  EXPECT_TRUE(clusters_of(board(32, 10)).empty());

  // Ink on the ring just outside the box, a quarter at most: the 20 x 20 cluster of
  // draw_pieces (ring of 84 px) under and over combs of a larger region, whose teeth
  // reach the ring only beside its white pixels (so as not to join the cluster): 21
  // teeth are 0.25, 22 are 0.26.
  const auto combed = [](int teeth) {
    cv::Mat1b black(120, 400, std::uint8_t(0));
    const int x0 = 260, y0 = 40, x1 = 279, y1 = 59;
    draw_pieces(black, x0, y0);
    black.row(y0 - 2).colRange(0, x1 + 2).setTo(255);  // longer than any cluster looked at
    black.row(y1 + 2).colRange(0, x1 + 2).setTo(255);
    std::vector<cv::Point> free;  // ring pixels whose inner neighbour is white
    for (int x = x0 - 1; x <= x1 + 1; ++x) {
      if (x < x0 || x > x1 || !black(y0, x)) free.emplace_back(x, y0 - 1);
      if (x < x0 || x > x1 || !black(y1, x)) free.emplace_back(x, y1 + 1);
    }
    EXPECT_EQ(free.size(), 24u);
    for (int k = 0; k < teeth; ++k) black(free[std::size_t(k)]) = 255;
    return black;
  };
  EXPECT_EQ(clusters_of(combed(21)).size(), 1u);
  EXPECT_TRUE(clusters_of(combed(22)).empty());

  // A closed border around a hole: the hole with what it holds 0.2 to 0.8 of the box,
  // and two squares in it at least. A 40 px frame holding two 4 px squares, its ink
  // outside the cluster bounds at every thickness here: 3 px (0.72) and 11 px (0.20) are
  // looked at, 2 px (0.81) and 12 px (0.16) are not; nor is one holding a single square.
  const auto frame = [](int thickness, int squares) {
    cv::Mat1b black(100, 100, std::uint8_t(0));
    black(cv::Rect(30, 30, 40, 40)).setTo(255);
    black(cv::Rect(30 + thickness, 30 + thickness, 40 - 2 * thickness, 40 - 2 * thickness)).setTo(0);
    for (int k = 0; k < squares; ++k) black(cv::Rect(44 + 8 * k, 48, 4, 4)).setTo(255);
    return black;
  };
  EXPECT_EQ(clusters_of(frame(3, 2)).size(), 1u);
  EXPECT_TRUE(clusters_of(frame(2, 2)).empty());
  EXPECT_EQ(clusters_of(frame(11, 2)).size(), 1u);
  EXPECT_TRUE(clusters_of(frame(12, 2)).empty());
  EXPECT_TRUE(clusters_of(frame(3, 1)).empty());
}

TEST(SecondLookPatch, ReopensOnePixelGapsBesideABrightMargin) {
  // A 3x3 marker at 0.55 pixels per unit (13 px across) with a quarter-tag white margin on
  // mid-grey, turned 30 degrees: the frame's 16 px mean threshold joins squares to the
  // border, so its white region has fewer than 9 children; the enlarged patch, binarised
  // at its local midpoint, separates all nine again.
  const Family f(3);
  SceneParams sp;
  sp.camera = Camera::pinhole(320, 320, 49.5, 49.5, 100, 100);
  SceneMarker m;
  m.id = 6789;
  m.margin_units = 6;
  m.tvec = {0.003, -0.002, 24.0};
  m.rvec = rotation_from_angles(30, 0, 0);
  const RenderedScene scene = render_scene(sp, {m});
  const ImageView view(scene.image);

  auto most_children = [](const detail::RegionTree& tree) {
    int most = 0;
    for (const detail::Region& r : tree.regions)
      if (!r.black && &r != &tree.regions[0]) most = std::max(most, r.child_count);
    return most;
  };
  detail::BinaryImage binary;
  cv::Mat mean;
  detail::threshold_mean(view, 16, 4, mean, binary);
  detail::RegionTree tree;
  detail::RegionLabeller labeller;
  labeller.label(binary, tree);
  EXPECT_LT(most_children(tree), 9) << "the frame's threshold keeps the marker: no test of the second look";

  const std::vector<cv::Rect> boxes = detail::near_candidates(tree, binary, view, detail::SecondLook{}, {});
  ASSERT_EQ(boxes.size(), 1u);
  const cv::Rect truth =
      cv::boundingRect(std::vector<cv::Point2f>(scene.truth[0].corners.begin(), scene.truth[0].corners.end()));
  EXPECT_GE((boxes[0] & truth).area(), truth.area() / 2);

  detail::Patch patch;
  ASSERT_TRUE(detail::enlarge_patch(view, boxes[0], detail::SecondLook{}, patch));
  EXPECT_EQ(patch.frame.scale, 2);
  EXPECT_EQ(patch.grey.size(), cv::Size(patch.grey.cols, patch.grey.rows));
  // The patch maps back onto the frame: its pixel centres at (p + 0.5) / 2 - 0.5 + origin.
  const cv::Point2d back = patch.frame.to_frame({1.5, 1.5});
  EXPECT_DOUBLE_EQ(back.x, patch.frame.origin.x + 0.5);
  EXPECT_DOUBLE_EQ(back.y, patch.frame.origin.y + 0.5);
  detail::BinaryImage patch_binary;
  detail::binarise_patch(patch, patch_binary);
  detail::RegionTree patch_tree;
  labeller.label(patch_binary, patch_tree);
  EXPECT_EQ(most_children(patch_tree), 9);

  // Its candidate's centroids, taken back to the frame, lie on the truth.
  DetectorParams params;
  params.families = {f};
  std::vector<detail::Candidate> out;
  DetectionStats stats;
  detail::find_candidates(patch_tree, patch_binary, ImageView(patch.grey), params, sp.camera, out, stats, patch.frame);
  ASSERT_EQ(out.size(), 1u);
  for (const detail::Blob& b : out[0].blobs) {
    double nearest = 1e9;
    for (const cv::Point2d& t : scene.truth[0].centroids) nearest = std::min(nearest, cv::norm(b.centroid - t));
    EXPECT_LT(nearest, 0.2);  // pixels, at 0.55 pixels per unit
  }
}

TEST(SecondLookPatch, AFlatPatchHasNoBlack) {
  // Where the local range is below a printed contrast, nothing is black (shading on paper).
  cv::Mat1b flat(60, 60);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 60; ++x) flat(y, x) = cv::saturate_cast<std::uint8_t>(190 + x / 6 + y / 10);
  detail::Patch patch;
  ASSERT_TRUE(detail::enlarge_patch(ImageView(flat), cv::Rect(20, 20, 20, 20), detail::SecondLook{}, patch));
  detail::BinaryImage binary;
  detail::binarise_patch(patch, binary);
  for (std::uint64_t word : binary.bits) EXPECT_EQ(word, 0u);
}

TEST(SecondLookPatch, APixelIsBlackBelowTheMidpointOfItsLocalLevelsWhereTheyDifferByAPrintedContrast) {
  // Every pixel of patches whose rows end inside, at and past a 64-pixel word: black
  // exactly where 2 grey < dark + bright and bright - dark >= 24, with nothing past a
  // row's end.
  cv::RNG rng(7);
  for (int width : {1, 63, 64, 65, 131}) {
    detail::Patch patch;
    patch.grey.create(5, width, CV_8UC1);
    patch.dark.create(5, width, CV_8UC1);
    patch.bright.create(5, width, CV_8UC1);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < width; ++x) {
        const int dark = rng.uniform(0, 256), bright = std::min(255, dark + rng.uniform(0, 60));
        patch.dark.at<std::uint8_t>(y, x) = std::uint8_t(dark);
        patch.bright.at<std::uint8_t>(y, x) = std::uint8_t(bright);
        patch.grey.at<std::uint8_t>(y, x) = std::uint8_t(rng.uniform(dark, bright + 1));
      }
    detail::BinaryImage binary;
    detail::binarise_patch(patch, binary);
    ASSERT_EQ(binary.width, width);
    ASSERT_EQ(binary.height, 5);
    int black = 0;
    for (int y = 0; y < 5; ++y) {
      for (int x = 0; x < width; ++x) {
        const int g = patch.grey.at<std::uint8_t>(y, x), dark = patch.dark.at<std::uint8_t>(y, x),
                  bright = patch.bright.at<std::uint8_t>(y, x);
        const bool expected = bright - dark >= 24 && 2 * g < dark + bright;
        EXPECT_EQ(binary.black(x, y), expected) << width << " wide, at " << x << ", " << y;
        black += expected;
      }
      if (width % 64) {
        EXPECT_EQ(binary.row(y)[width / 64] >> (width % 64), 0u) << "past the end of row " << y;
      }
    }
    if (width > 60) {
      EXPECT_GT(black, width / 8);
    }
  }
}
