// SPDX-License-Identifier: LGPL-2.1-or-later
// The outline reading (src/detect/outline.cpp): markers whose squares touch in every
// binary image, read from the grey levels under their aligned outline.
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "../../src/core/geometry.hpp"
#include "binary.hpp"
#include "lftag/detector.hpp"
#include "lftag/image_file.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using namespace lftag::detail;
using lftag::test::paper_camera;
using lftag::test::random_id;
using lftag::test::rotation;

namespace {

struct Far {
  RenderedScene scene;
  std::array<cv::Point2d, 4> corners;  // true outer corners, clockwise from the top-left
};

// A marker of family n at `distance` in the paper's camera, turned by `roll` degrees, on
// a white margin of a quarter of the tag and a mid-grey background.
Far far_marker(int n, TagId id, double distance, double roll, double blur_px = 0, cv::Point2d offset = {}) {
  SceneParams p;
  p.camera = paper_camera();
  p.blur_length_px = blur_px;
  SceneMarker m;
  m.family = Family(n);
  m.id = id;
  m.margin_units = std::round(m.family.side() / 4.0);
  m.tvec = {offset.x, offset.y, distance};
  m.rvec = rotation(roll, 0, 0);
  Far far{render_scene(p, {m}), {}};
  for (int i = 0; i < 4; ++i) far.corners[i] = far.scene.truth[0].corners[i];
  return far;
}

// The corners, started from corner `first` and moved by up to `jitter` pixels.
std::array<cv::Point2d, 4> coarse(const std::array<cv::Point2d, 4>& corners, int first, double jitter,
                                  std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-jitter, jitter);
  std::array<cv::Point2d, 4> out;
  for (int i = 0; i < 4; ++i) out[i] = corners[(first + i) % 4] + cv::Point2d(u(rng), u(rng));
  return out;
}

}  // namespace

TEST(OutlineReading, ReadsFarMarkersFromACoarseOutlineInAnyTurn) {
  // 3x3 at 28 m: 11 px across, 0.47 px per unit; the squares touch in the frame's binary
  // image. The outline is given from any corner and up to half a pixel off.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  DetectorParams params;
  int read = 0;
  for (int trial = 0; trial < 16; ++trial) {
    const TagId id = random_id(Family(3), rng);
    const Far far = far_marker(3, id, 28, 180 * u(rng), 0, {0.05 * u(rng), 0.05 * u(rng)});
    const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, trial % 4, 0.5, rng), Family(3));
    ASSERT_TRUE(reading);
    if (!acceptable(*reading, params)) continue;
    ++read;
    EXPECT_EQ(reading->id, id) << "trial " << trial;
    EXPECT_NEAR(reading->pixels_per_unit, 0.47, 0.03);
    // In the marker's true turn: the squares' centres within half a unit (0.23 px; about
    // 0.1 px typically).
    const std::vector<cv::Point2d> centres = Family(3).centers(id);
    for (int g = 0; g < 9; ++g) {
      const double e = cv::norm(apply(reading->homography, centres[g]) - far.scene.truth[0].centers[g]);
      EXPECT_LT(e, 0.5 * reading->pixels_per_unit);
    }
  }
  EXPECT_GE(read, 14);
}

TEST(OutlineReading, ReadsSquaresThatTouchUnderBlur) {
  // A 64 px 4x4 marker (5 m) blurred vertically over 13 % of its edge (4 units): the blur
  // closes the 2 u gaps, so no binary image has its n^2 squares, but the grey levels still
  // place them.
  std::mt19937_64 rng(12);
  DetectorParams params;
  for (int trial = 0; trial < 6; ++trial) {
    const TagId id = random_id(Family(4), rng);
    const Far far = far_marker(4, id, 5, 0, 0.13 * 64);
    const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, trial % 4, 1.0, rng), Family(4));
    ASSERT_TRUE(reading);
    EXPECT_TRUE(acceptable(*reading, params)) << "correlation " << reading->correlation << " margin " << reading->margin
                                              << " baseline gap " << reading->baseline_gap;
    EXPECT_EQ(reading->id, id);
  }
}

TEST(OutlineReading, ReadsFromTheDataSquaresOrACornerPulledOut) {
  // Far markers whose coarse outline is poor: the hull of the data squares only (the
  // border merged with the background), or one corner pulled 4 px out by a spur of the
  // broken border. 4x4 at 22 m: 14.5 px across, 0.48 px per unit.
  std::mt19937_64 rng(14);
  std::uniform_real_distribution<double> u(-1, 1);
  DetectorParams params;
  const Family family(4);
  const int side = family.side();
  int read = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const TagId id = random_id(family, rng);
    const Far far = far_marker(4, id, 22, 180 * u(rng), 0, {0.05 * u(rng), 0.05 * u(rng)});
    std::vector<cv::Point2f> units, pixels;
    for (int i = 0; i < 4; ++i)
      units.emplace_back(family.outer_corners()[i]), pixels.emplace_back(cv::Point2f(far.corners[i]));
    const cv::Matx33d h = cv::getPerspectiveTransform(units, pixels);
    std::array<cv::Point2d, 4> outline;
    if (trial % 2 == 0) {
      const double a = 4.5, b = side - 4.5;
      const std::array<cv::Point2d, 4> data = {cv::Point2d(a, a), {b, a}, {b, b}, {a, b}};
      for (int i = 0; i < 4; ++i) outline[i] = apply(h, data[i]) + cv::Point2d(0.3 * u(rng), 0.3 * u(rng));
    } else {
      outline = coarse(far.corners, 0, 0.3, rng);
      const cv::Point2d centre = (far.corners[0] + far.corners[2]) / 2;
      const cv::Point2d out = outline[trial % 4] - centre;
      outline[trial % 4] += out * (4 / cv::norm(out));
    }
    const auto reading = read_outline(ImageView(far.scene.image), outline, family);
    if (!reading || !acceptable(*reading, params)) continue;
    ++read;
    EXPECT_EQ(reading->id, id) << "trial " << trial;
  }
  EXPECT_GE(read, 7);
}

TEST(OutlineReading, ThePixelModelReadsAtTheResolutionBound) {
  // 3x3 at 29.5 m and 4x4 at 23.5 m (0.45 px per unit): a square's one-unit shift moves
  // under half a pixel. Interpolated samples blur that away (margins about 0.02); each
  // pixel's predicted ink share keeps it (margins about 0.15).
  std::mt19937_64 rng(15);
  std::uniform_real_distribution<double> u(-1, 1);
  DetectorParams params;
  for (const auto& [n, distance] : {std::pair{3, 29.5}, std::pair{4, 23.5}}) {
    int read = 0;
    for (int trial = 0; trial < 10; ++trial) {
      const TagId id = random_id(Family(n), rng);
      const Far far = far_marker(n, id, distance, 180 * u(rng), 0, {0.05 * u(rng), 0.05 * u(rng)});
      const auto reading =
          read_outline(ImageView(far.scene.image), coarse(far.corners, trial % 4, 0.3, rng), Family(n));
      ASSERT_TRUE(reading);
      if (!acceptable(*reading, params)) continue;
      ++read;
      EXPECT_EQ(reading->id, id) << n << "x" << n << " trial " << trial;
      EXPECT_EQ(reading->smear, 0);
    }
    EXPECT_GE(read, 9) << n << "x" << n;
  }
}

namespace {

// A 64 px marker of family n at 5 m (2.9 px per unit for 3x3, 2.3 for 4x4) blurred by
// `units` of its own units at `angle` degrees, on a white margin of 6 units.
Far smeared_marker(int n, TagId id, double units, double angle) {
  SceneParams p;
  p.camera = paper_camera();
  p.blur_length_px = units * 64.0 / Family(n).side();
  p.blur_angle_deg = angle;
  SceneMarker m;
  m.family = Family(n);
  m.id = id;
  m.margin_units = 6;
  m.tvec = {0.01, -0.02, 5.0};
  Far far{render_scene(p, {m}), {}};
  for (int i = 0; i < 4; ++i) far.corners[i] = far.scene.truth[0].corners[i];
  return far;
}

}  // namespace

TEST(OutlineReading, FindsTheLengthOfAMotionBlur) {
  // 64 px 3x3 and 4x4 markers blurred by 4.8 units in several directions: the structure
  // is aligned smeared in the direction and by the length that correlate best, and the
  // cells are read with the blur's length fitted.
  std::mt19937_64 rng(16);
  DetectorParams params;
  const double units = 4.8;
  for (const int n : {3, 4})
    for (const double angle : {0.0, 30.0, 60.0, 90.0}) {
      const TagId id = random_id(Family(n), rng);
      const Far far = smeared_marker(n, id, units, angle);
      const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, 0, 1.0, rng), Family(n));
      const std::string what = std::to_string(n) + "x" + std::to_string(n) + ", " + std::to_string(angle) + " deg";
      ASSERT_TRUE(reading) << what;
      EXPECT_TRUE(acceptable(*reading, params)) << what << ": evidence " << reading->evidence;
      EXPECT_EQ(reading->id, id) << what;
      EXPECT_NEAR(reading->smear, units, 0.8) << what;
    }
}

TEST(OutlineReading, AnExpectedIdIsReadUnderItsOwnAlignmentAndNeverImposed) {
  // A tracked marker's id is known: its marker is aligned at once and read only there.
  // Blurred by 4.8 units, 3x3 and 4x4 read so are accepted as their own id, as without the
  // expectation; expecting an id one digit away never reads that id.
  std::mt19937_64 rng(23);
  DetectorParams params;
  for (const int n : {3, 4})
    for (const double angle : {0.0, 45.0, 90.0, 150.0}) {
      const Family family(n);
      const TagId id = random_id(family, rng);
      const Far far = smeared_marker(n, id, 4.8, angle);
      const std::array<cv::Point2d, 4> outline = coarse(far.corners, 0, 1.0, rng);
      const std::string what = std::to_string(n) + "x" + std::to_string(n) + ", " + std::to_string(angle) + " deg";
      const auto reading =
          read_outline(ImageView(far.scene.image), outline, family, params.min_pixels_per_unit, {}, nullptr, id);
      ASSERT_TRUE(reading) << what;
      EXPECT_TRUE(acceptable(*reading, params)) << what << ": evidence " << reading->evidence;
      EXPECT_EQ(reading->id, id) << what;
      EXPECT_NEAR(reading->smear, 4.8, 0.8) << what;

      const int digit = int(rng() % std::uint64_t(family.data_cell_count()));
      const TagId other = id.with_digit(digit, (id.digit(digit) + 1 + int(rng() % 3)) % 4);
      const auto refused =
          read_outline(ImageView(far.scene.image), outline, family, params.min_pixels_per_unit, {}, nullptr, other);
      EXPECT_FALSE(refused && acceptable(*refused, params) && refused->id == other) << what;
    }
}

TEST(OutlineReading, ReadsLargeMarkersOnTheirPixelsReducedToThreePerUnit) {
  // 3x3 and 4x4 at 2 m, turned: 6.6 and 5.3 px per unit, which the pixel model reads on
  // the marker's pixels reduced to 3 px per unit. Sharp, and smeared by 4.8 units: read
  // right, the smear's length found in units as at the frame's own resolution.
  std::mt19937_64 rng(31);
  DetectorParams params;
  for (const int n : {3, 4})
    for (const double units : {0.0, 4.8}) {
      const TagId id = random_id(Family(n), rng);
      const double per_unit = 0.47 * 28 / 2 * 24 / Family(n).side();  // the paper camera
      const Far far = far_marker(n, id, 2, 25, units * per_unit);
      const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, 1, 1.0, rng), Family(n));
      const std::string what = std::to_string(n) + "x" + std::to_string(n) + ", smear " + std::to_string(units);
      ASSERT_TRUE(reading) << what;
      EXPECT_GT(reading->pixels_per_unit, 4.5) << what;
      EXPECT_TRUE(acceptable(*reading, params))
          << what << ": evidence " << reading->evidence << ", margin " << reading->margin;
      EXPECT_EQ(reading->id, id) << what;
      EXPECT_NEAR(reading->smear, units, 0.8) << what;
    }
}

TEST(OutlineReading, BlursAsLongAsTheCellPitchAreReadOrRefusedNeverMisread) {
  // A blur as long as the cells' 6-unit pitch leaves a square's one-unit shift visible in
  // most directions and cells, not in all: there the fit can move a square to its
  // neighbour's position (a 3x3 blurred vertically read so, as another id), and that cell shows
  // too little of the difference its digit makes (the evidence check refuses it). Beyond
  // the lengths the alignment tries (6 units) some markers still align and show every
  // digit (the pixel model fits lengths 16 % beyond the one found); the others fail the
  // structure. No motion blur bound decides: 6 to 8 units read 9 of 24 3x3 and 9 of 24
  // 4x4 markers, every one right.
  std::mt19937_64 rng(17);
  DetectorParams params;
  for (const int n : {3, 4}) {
    int read = 0;
    for (const double units : {6.0, 6.5, 7.0, 8.0})
      for (const double angle : {0.0, 30.0, 45.0, 60.0, 90.0, 120.0}) {
        const TagId id = random_id(Family(n), rng);
        const Far far = smeared_marker(n, id, units, angle);
        const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, 0, 1.0, rng), Family(n));
        if (!reading || !acceptable(*reading, params)) continue;
        ++read;
        EXPECT_EQ(reading->id, id) << n << "x" << n << ", " << angle << " deg, " << units << " units";
      }
    EXPECT_GE(read, 6) << n << "x" << n;
  }
}

// A marker (4x4: about 32 px at 10 m, 1.05 px per unit), tilted by `tilt` degrees on a
// mid-grey background, defocused by a Gaussian of 1.45 px, with sensor noise and JPEG at
// quality 60 (the realistic video's worst clips); ink and paper albedos as given.
Far defocused_marker(TagId id, double distance, double ink, double paper, std::mt19937_64& rng, double tilt = 20,
                     Family family = Family(4)) {
  std::uniform_real_distribution<double> u(-1, 1);
  SceneParams p;
  p.camera = paper_camera();
  SceneMarker m;
  m.family = family;
  m.id = id;
  m.margin_units = 8;
  m.tvec = {0.2 * u(rng), 0.2 * u(rng), distance};
  m.rvec = rotation(180 * u(rng), tilt, 0);
  m.black = float(ink), m.white = float(paper);
  Far far{render_scene(p, {m}), {}};
  for (int i = 0; i < 4; ++i) far.corners[i] = far.scene.truth[0].corners[i];
  cv::Mat1b image;
  cv::GaussianBlur(far.scene.image, image, cv::Size(), 1.45);
  cv::Mat1f noisy, noise(image.size());
  cv::randn(noise, 0, 2.5);
  image.convertTo(noisy, CV_32F);
  cv::Mat1b(noisy + noise).copyTo(image);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 60});
  far.scene.image = cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE);
  return far;
}

// A random marker of `family` drawn by defocused_marker, and its outline read from a
// coarse outline of it (the trial's turn, corners off by up to half a pixel).
struct Defocused {
  TagId id;
  Far far;
  std::optional<OutlineReading> reading;
};
Defocused read_defocused(const Family& family, double distance, double ink, double paper, double tilt, int trial,
                         std::mt19937_64& rng) {
  const TagId id = random_id(family, rng);
  Far far = defocused_marker(id, distance, ink, paper, rng, tilt, family);
  auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, trial % 4, 0.5, rng), family);
  return {id, std::move(far), std::move(reading)};
}

TEST(OutlineReading, ReadsDefocusedMarkersOfAboutAPixelPerUnit) {
  // Against the template blurred only by its pixels the structure correlates under 0.75
  // and the contrast looks a third of the ink's (none of the ten was read so); blurred by
  // the defocus it aligns, and the cells read right. The defocus is found and not taken
  // for a motion blur, and the outline found is the true one (the template blurred with
  // paper beyond its ring; mirrored, the alignment shrank it by 0.7 px).
  std::mt19937_64 rng(21);
  DetectorParams params;
  int read = 0;
  for (int trial = 0; trial < 10; ++trial) {
    const auto [id, far, reading] = read_defocused(Family(4), 10, 0.05, 0.9, 20, trial, rng);
    ASSERT_TRUE(reading) << "trial " << trial;
    if (!acceptable(*reading, params)) continue;
    ++read;
    EXPECT_EQ(reading->id, id) << "trial " << trial;
    EXPECT_EQ(reading->smear, 0) << "trial " << trial;
    EXPECT_GE(reading->defocus, 1.1) << "trial " << trial;  // 1.45 px at 1.05 px per unit: 1.38 units
    const double side = Family(4).side();
    const std::array<cv::Point2d, 4> unit = {cv::Point2d(0, 0), {side, 0}, {side, side}, {0, side}};
    for (int i = 0; i < 4; ++i)
      EXPECT_LT(cv::norm(apply(reading->homography, unit[i]) - far.corners[i]), 0.35) << "trial " << trial;
  }
  EXPECT_GE(read, 9);
}

TEST(OutlineReading, ReadsDefocusedMarkersSeenObliquely) {
  // The same markers tilted by 60 degrees at 7.5 m: about 0.7 px per unit across the
  // tilt. Against the sharper template many align under 0.6, where no blur was sought
  // before (6 of the 60 read so); the defocus is sought from 0.55 (20 read), and as the
  // frame blurs them: in the template, twice as long across the tilt's axis as along it
  // (50 read; 20 with a round blur). Those the sharp structure aligns under 0.55 align
  // from the start's best smear, and their defocus is found from there (60 read). Those
  // read are read right, every one under a defocus found.
  std::mt19937_64 rng(23);
  DetectorParams params;
  int read = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const auto [id, far, reading] = read_defocused(Family(4), 7.5, 0.05, 0.9, 60, trial, rng);
    if (!reading || !acceptable(*reading, params)) continue;
    ++read;
    EXPECT_EQ(reading->id, id) << "trial " << trial;
    EXPECT_GT(reading->defocus, 0) << "trial " << trial << ", smear " << reading->smear;
  }
  EXPECT_GE(read, 55);
}

TEST(OutlineReading, MarkersDefocusedBeyondTheBlursSoughtFailTheContrastCheck) {
  // 5x5 markers at 10.5 m (0.83 px per unit), defocused by 1.45 px: 1.75 units, more than
  // the 1.5 sought beyond the pixels' own blur. The structure aligns, but the white ring
  // shows darker than the cores (so a 30 px 5x5 of the realistic video did): each such
  // reading is returned, and fails at the contrast check, not at the alignment.
  std::mt19937_64 rng(24);
  DetectorParams params;
  int dark_rings = 0;
  for (int trial = 0; trial < 20; ++trial) {
    const auto [id, far, reading] = read_defocused(Family(5), 10.5, 0.05, 0.9, 20, trial, rng);
    if (!reading) continue;
    if (acceptable(*reading, params)) {
      EXPECT_EQ(reading->id, id) << "trial " << trial;
    }
    if (reading->contrast > 0) continue;
    ++dark_rings;
    EXPECT_EQ(outline_stage(*reading, params), Stage::contrast) << "trial " << trial;
  }
  EXPECT_GE(dark_rings, 15);  // 20 in the release build
}

TEST(OutlineReading, DimDefocusedMarkersAreNeverMisread) {
  // The same markers printed in grey on grey (ink 0.3, paper 0.4 to 0.45: 25 to 38 grey
  // levels), from 9.5 to 10.5 m. The contrast seen is a few grey levels and margins
  // measured against it let misreadings through: the evidence check, measured against the
  // model's own prediction, refuses them. Some are read, none wrongly.
  std::mt19937_64 rng(22);
  DetectorParams params;
  int accepted = 0;
  for (const double paper : {0.4, 0.42, 0.45})
    for (const double distance : {9.5, 10.0, 10.5})
      for (int trial = 0; trial < 5; ++trial) {
        const auto [id, far, reading] = read_defocused(Family(4), distance, 0.3, paper, 20, trial, rng);
        if (!reading || !acceptable(*reading, params)) continue;
        ++accepted;
        EXPECT_EQ(reading->id, id) << "paper " << paper << ", " << distance << " m, trial " << trial;
      }
  EXPECT_GE(accepted, 1);
}

TEST(OutlineReading, RefusesQuadsWithoutTheMarkersStructure) {
  // Quadrilaterals that are not markers: a dark square, a grid of dark tiles centred in
  // their cells (a facade), noise in a black frame, a marker of another family.
  DetectorParams params;
  const std::array<cv::Point2d, 4> quad = {cv::Point2d(40, 40), {111, 40}, {111, 111}, {40, 111}};
  std::vector<cv::Mat1b> images;
  cv::Mat1b dark(160, 160, std::uint8_t(230));
  cv::rectangle(dark, cv::Rect(40, 40, 72, 72), 20, cv::FILLED);
  images.push_back(dark);
  cv::Mat1b facade = dark.clone();
  cv::rectangle(facade, cv::Rect(46, 46, 60, 60), 230, cv::FILLED);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) cv::rectangle(facade, cv::Rect(55 + 18 * c, 55 + 18 * r, 9, 9), 20, cv::FILLED);
  images.push_back(facade);
  cv::Mat1b noise = dark.clone();
  cv::Mat1b inside(60, 60);
  cv::randu(inside, 0, 256);
  inside.copyTo(noise(cv::Rect(46, 46, 60, 60)));
  images.push_back(noise);
  cv::Mat1b other(160, 160, std::uint8_t(230));
  const cv::Mat1b five = rasterize_marker(Family(5), 123456, 72.0 / Family(5).side(), 0);
  five.copyTo(other(cv::Rect(40, 40, five.cols, five.rows)));
  images.push_back(other);
  for (std::size_t i = 0; i < images.size(); ++i) {
    const auto reading = read_outline(ImageView(images[i]), quad, Family(3));
    EXPECT_FALSE(reading && acceptable(*reading, params)) << "image " << i;
  }
}

TEST(OutlineReading, MarkersBelowTheReadableResolutionAreRefused) {
  // 3x3 at 36 m: 0.37 px per unit, under DetectorParams::min_pixels_per_unit (0.43).
  std::mt19937_64 rng(13);
  DetectorParams params;
  const Far far = far_marker(3, 777, 36, 20);
  const auto reading = read_outline(ImageView(far.scene.image), coarse(far.corners, 0, 0.3, rng), Family(3));
  ASSERT_TRUE(reading);
  EXPECT_LT(reading->pixels_per_unit, params.min_pixels_per_unit);
  EXPECT_FALSE(acceptable(*reading, params));
  EXPECT_EQ(outline_stage(*reading, params), Stage::resolution);

  // At 50 m (0.27 px per unit) the start is far under the bound: refused before the
  // alignment, nothing read.
  const Far farther = far_marker(3, 777, 50, 20);
  const auto early = read_outline(ImageView(farther.scene.image), coarse(farther.corners, 0, 0.3, rng), Family(3));
  ASSERT_TRUE(early);
  EXPECT_LT(early->pixels_per_unit, 0.8 * params.min_pixels_per_unit);
  EXPECT_FALSE(early->read);
  EXPECT_EQ(outline_stage(*early, params), Stage::resolution);
}

TEST(CoarseOutlines, FindsTheMarkerInsideARingOfBackground) {
  // A patch's binary image: a dark background's ring around the white margin, the
  // marker's black pieces inside it.
  cv::Mat1b black(100, 100, std::uint8_t(0));
  cv::rectangle(black, cv::Rect(10, 10, 80, 80), 255, 3);  // the ring
  cv::rectangle(black, cv::Rect(30, 30, 40, 40), 255, cv::FILLED);
  cv::rectangle(black, cv::Rect(36, 36, 28, 28), 0, cv::FILLED);  // the marker's inside
  BinaryImage binary;
  binary.width = 100, binary.height = 100, binary.words_per_row = 2;
  binary.bits.assign(200, 0);
  for (int y = 0; y < 100; ++y)
    for (int x = 0; x < 100; ++x)
      if (black(y, x)) binary.bits[y * 2 + (x >> 6)] |= std::uint64_t{1} << (x & 63);
  PatchFrame frame;
  frame.origin = {200, 100};
  frame.scale = 2;
  const auto outlines = coarse_outlines(binary, frame);
  const auto near = [](cv::Point2d a, cv::Point2d b) { return cv::norm(a - b) < 1.0; };
  bool marker = false;
  for (const auto& o : outlines) {
    // Clockwise on screen, in frame pixels: patch pixel 30 is frame pixel 214.75.
    if (near(o[0], {214.75, 114.75}) || near(o[1], {214.75, 114.75}) || near(o[2], {214.75, 114.75}) ||
        near(o[3], {214.75, 114.75}))
      marker = true;
    double twice_area = 0;
    for (int i = 0; i < 4; ++i) twice_area += o[i].x * o[(i + 1) % 4].y - o[(i + 1) % 4].x * o[i].y;
    EXPECT_GT(twice_area, 0);
  }
  EXPECT_TRUE(marker);
}

TEST(CoarseOutlines, LeavesOutASpeckBesideTheMarker) {
  // A marker's border turned 30 degrees with rounded corners, a speck of the margin a
  // little off one side: one outline is the border's, within a few pixels of its corners.
  cv::Mat1b black(140, 140, std::uint8_t(0));
  const cv::RotatedRect border({70, 70}, {70, 70}, 30);
  cv::Point2f corners[4];
  border.points(corners);
  std::vector<cv::Point> outer(corners, corners + 4);
  cv::fillConvexPoly(black, outer, 255);
  cv::polylines(black, outer, true, 255, 5);  // rounds the corners
  cv::Point2f inside[4];
  cv::RotatedRect({70, 70}, {56, 56}, 30).points(inside);
  cv::fillConvexPoly(black, std::vector<cv::Point>(inside, inside + 4), 0);
  black(cv::Rect(60, 4, 6, 3)).setTo(255);  // the speck, 13 px above the top corner
  const BinaryImage binary = test::binary_from_mask(black);
  PatchFrame frame;  // the frame's own pixels
  const auto outlines = coarse_outlines(binary, frame);
  ASSERT_FALSE(outlines.empty());
  double best = 1e9;  // the farthest corner from the border's, of the closest outline
  for (const auto& o : outlines) {
    double worst = 0;
    for (const cv::Point2f& c : corners) {
      double nearest = 1e9;
      for (const cv::Point2d& q : o) nearest = std::min(nearest, cv::norm(q - cv::Point2d(c)));
      worst = std::max(worst, nearest);
    }
    best = std::min(best, worst);
  }
  EXPECT_LT(best, 4.0) << "no outline near the border's corners: " << corners[0] << corners[1] << corners[2]
                       << corners[3] << " outlines " << outlines.size() << " first " << outlines[0][0] << outlines[0][1]
                       << outlines[0][2] << outlines[0][3];
}

TEST(CoarseOutlines, TakesTheLargestQuadrilateralWhereTheApproximationSkipsFour) {
  // The hull of a defocused marker's pieces in a video frame, whose polygon approximation
  // goes from five vertices to three: its largest quadrilateral is the outline.
  const std::vector<cv::Point> hull = {{100, 82}, {74, 111}, {39, 96}, {37, 95}, {36, 94}, {35, 92},
                                       {29, 72},  {21, 40},  {21, 36}, {23, 33}, {36, 29}, {73, 21},
                                       {84, 21},  {90, 37},  {94, 49}, {100, 75}};
  cv::Mat1b black(130, 130, std::uint8_t(0));
  cv::fillConvexPoly(black, hull, 255);
  PatchFrame frame;
  const auto outlines = coarse_outlines(test::binary_from_mask(black), frame);
  ASSERT_EQ(outlines.size(), 1u);
  EXPECT_GT(quad_area(outlines[0]), 0.75 * cv::contourArea(hull)) << "clockwise, and most of the hull";
}

TEST(CoarseOutlines, TriesABorderAroundSquaresAloneBesideTheGroundsEdge) {
  // A far marker's patch as binarised at 27 m: the ground's edge beside the sheet is a
  // black band open on one side (so the sheet's white joins the patch's), and the
  // marker's border a closed ring around its squares inside the band's box. The two are
  // one group whose hull is the band's; the ring is also tried alone.
  cv::Mat1b black(96, 96, std::uint8_t(0));
  cv::rectangle(black, cv::Rect(14, 21, 63, 56), 255, 7);
  black(cv::Rect(30, 70, 30, 12)).setTo(0);  // the band's opening
  const cv::Rect ring(34, 35, 26, 26);
  cv::rectangle(black, ring, 255, 2);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) black(cv::Rect(39 + 6 * c, 40 + 6 * r, 3, 3)).setTo(255);
  PatchFrame frame;  // the frame's own pixels
  const auto outlines = coarse_outlines(test::binary_from_mask(black), frame);
  const std::array<cv::Point2d, 4> corners = {cv::Point2d(34, 35), {59, 35}, {59, 60}, {34, 60}};
  bool found = false;
  for (const auto& o : outlines) {
    double worst = 0;
    for (const cv::Point2d& c : corners) {
      double nearest = 1e9;
      for (const cv::Point2d& q : o) nearest = std::min(nearest, cv::norm(q - c));
      worst = std::max(worst, nearest);
    }
    found |= worst < 1.5;
  }
  EXPECT_TRUE(found) << outlines.size() << " outlines";
}

TEST(CoarseOutlines, TriesABorderJoinedByItsSquaresAloneBesideTheGroundsSpecks) {
  // A defocused marker seen obliquely in a video frame, binarised: most of its squares
  // joined its border, so its hole holds one piece, and specks of the ground lie within
  // the group's reach off two corners, pulling the group's hull out. The border, closed
  // around a hole that holds one piece and is a tenth of its hull or more, is also tried
  // alone.
  cv::Mat1b black(140, 140, std::uint8_t(0));
  black(cv::Rect(40, 40, 60, 60)).setTo(255);
  black(cv::Rect(46, 46, 48, 48)).setTo(0);  // the border, 6 px wide
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) black(cv::Rect(46 + 18 * c, 46 + 18 * r, 12, 12)).setTo(255);  // the outer 8 touch it
  black(cv::Rect(31, 31, 5, 5)).setTo(255);                                                    // the ground's specks
  black(cv::Rect(104, 32, 6, 4)).setTo(255);
  const std::array<cv::Point2d, 4> corners = {cv::Point2d(40, 40), {99, 40}, {99, 99}, {40, 99}};
  const auto border_alone = [&](const cv::Mat1b& mask) {
    PatchFrame frame;  // the frame's own pixels
    for (const auto& o : coarse_outlines(test::binary_from_mask(mask), frame)) {
      double worst = 0;
      for (const cv::Point2d& c : corners) {
        double nearest = 1e9;
        for (const cv::Point2d& q : o) nearest = std::min(nearest, cv::norm(q - c));
        worst = std::max(worst, nearest);
      }
      if (worst < 1.5) return true;
    }
    return false;
  };
  EXPECT_TRUE(border_alone(black));
  // An empty hole (a letter O, a window frame: most such shapes in photos) is not: it
  // would cost outline reads for nothing.
  black(cv::Rect(64, 64, 12, 12)).setTo(0);
  EXPECT_FALSE(border_alone(black));
}

TEST(OutlineReading, AMarkerCutByTheFrameEdgeIsReadOnlyWhereItsSquaresAreSeen) {
  // A far 3x3 (one pixel per unit, 24 px) whose outline reaches past the frame's right or
  // bottom edge, cut anywhere from a quarter to three quarters of its side. Where a row or
  // column of squares (units 4 to 20 of 24) lies wholly beyond the edge, nothing can read
  // it: the reading is refused, without error. Where part of every square is seen, an
  // accepted reading must be the right one.
  DetectorParams params;
  const Family family(3);
  const TagId id = 4321;
  const cv::Mat1b marker = rasterize_marker(family, id, 1.0, 0);
  ASSERT_EQ(marker.cols, family.side());
  cv::Mat1b sheet(marker.rows + 40, marker.cols + 40, std::uint8_t(235));
  marker.copyTo(sheet(cv::Rect(20, 20, marker.cols, marker.rows)));
  const double s = family.side();
  const std::array<cv::Point2d, 4> outline = {
      cv::Point2d(19.5, 19.5), {19.5 + s, 19.5}, {19.5 + s, 19.5 + s}, {19.5, 19.5 + s}};
  for (int cut = family.side() / 4; cut <= 3 * family.side() / 4; ++cut)
    for (const bool across : {false, true}) {
      const cv::Mat1b frame = across ? sheet(cv::Rect(0, 0, 20 + cut, sheet.rows)).clone()
                                     : sheet(cv::Rect(0, 0, sheet.cols, 20 + cut)).clone();
      std::optional<OutlineReading> reading;
      ASSERT_NO_THROW(reading = read_outline(ImageView(frame), outline, family)) << cut;
      const bool accepted = reading && acceptable(*reading, params);
      if (cut <= 16) {
        EXPECT_FALSE(accepted) << cut;
      } else if (accepted) {
        EXPECT_EQ(reading->id, id) << cut;
      }
    }
}

TEST(OutlineReading, OtherMarkersAreRefusedBeforeTheAlignment) {
  // Sharp markers at three to four pixels per unit that are not 3x3 LFTags: 4x4 and 5x5
  // LFTags and square binary markers like AprilTag 36h11's (a black border around 6 x 6
  // random bits). Their structure correlates too little at the start, even smeared, so
  // the reading stops there: nothing aligned, no contrast measured. The 4x4s are the
  // near-misses of kMinResolvedStartCorrelation (0.66): they start at 0.60 to 0.64
  // (measured), so a gate loosened to 0.60 aligns them. A 3x3 in the same place starts
  // far above it and is read.
  DetectorParams params;
  std::mt19937_64 rng(21);
  const std::array<cv::Point2d, 4> quad = {cv::Point2d(40, 40), {119.5, 40}, {119.5, 119.5}, {40, 119.5}};
  const auto on_white = [](int n, TagId id) {
    cv::Mat1b image(160, 160, std::uint8_t(230));
    const cv::Mat1b marker = rasterize_marker(Family(n), id, 80.0 / Family(n).side(), 0);
    marker.copyTo(image(cv::Rect(40, 40, marker.cols, marker.rows)));
    return image;
  };
  std::vector<cv::Mat1b> images;
  for (const int n : {4, 4, 4, 4, 4, 4, 5}) images.push_back(on_white(n, random_id(Family(n), rng)));
  for (int k = 0; k < 4; ++k) {
    cv::Mat1b image(160, 160, std::uint8_t(230));
    cv::rectangle(image, cv::Rect(40, 40, 80, 80), 20, cv::FILLED);
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c)
        if (rng() % 2) cv::rectangle(image, cv::Rect(50 + 10 * c, 50 + 10 * r, 10, 10), 230, cv::FILLED);
    images.push_back(image);
  }
  int at_the_gate = 0;
  double highest_start = 0;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const auto reading = read_outline(ImageView(images[i]), quad, Family(3));
    if (!reading) continue;  // refused even earlier, under kMinStartCorrelation
    ++at_the_gate;
    highest_start = std::max(highest_start, reading->correlation);
    EXPECT_FALSE(reading->read) << "image " << i;
    EXPECT_EQ(reading->contrast, 0) << "image " << i << ": aligned";
    EXPECT_LT(reading->correlation, kMinResolvedStartCorrelation) << "image " << i;
    EXPECT_EQ(outline_stage(*reading, params), Stage::structure) << "image " << i;
  }
  EXPECT_GE(at_the_gate, 8);       // the 4x4s, the 5x5 and a square binary marker (measured)
  EXPECT_GT(highest_start, 0.62);  // the near-misses are there
  const TagId id = random_id(Family(3), rng);
  const auto reading = read_outline(ImageView(on_white(3, id)), quad, Family(3));
  ASSERT_TRUE(reading);
  EXPECT_TRUE(acceptable(*reading, params));
  EXPECT_EQ(reading->id, id);
}

TEST(OutlineReading, TheBaselinesMustStandOutByAQuarterOfTheContrast) {
  // Glare on one baseline square: its outer strip (a unit wide, the height of a data
  // square) lightened to grey level g, so that one corner of the top pair looks less like
  // a baseline and the turn is less certain. The baseline gap falls with g (about 0.035 a
  // grey level step of 10, measured): at g = 160 (gap 0.30 to 0.34) the marker is read
  // with its id; at g = 190 (0.18 to 0.23) the reading is refused as baselines, on the
  // near side of kMinBaselineGap (0.25), so a bound loosened to 0.15 accepts it.
  DetectorParams params;
  std::mt19937_64 rng(5);
  const double per_unit = 4;
  for (const int n : {3, 4}) {
    const TagId id = random_id(Family(n), rng);
    for (const int g : {160, 190}) {
      cv::Mat1b image(200, 200, std::uint8_t(230));
      const cv::Mat1b marker = rasterize_marker(Family(n), id, per_unit, 0);
      const int at = 20;
      marker.copyTo(image(cv::Rect(at, at, marker.cols, marker.rows)));
      cv::rectangle(image, cv::Rect(at + int(4 * per_unit), at + int(4 * per_unit), int(per_unit), int(4 * per_unit)),
                    g, cv::FILLED);
      const double s = Family(n).side() * per_unit;
      const std::array<cv::Point2d, 4> quad = {cv::Point2d(at - 0.5, at - 0.5),
                                               {at + s - 0.5, at - 0.5},
                                               {at + s - 0.5, at + s - 0.5},
                                               {at - 0.5, at + s - 0.5}};
      const auto reading = read_outline(ImageView(image), quad, Family(n));
      ASSERT_TRUE(reading) << n << " " << g;
      if (g == 160) {
        EXPECT_GT(reading->baseline_gap, 0.28) << n;
        EXPECT_TRUE(acceptable(*reading, params)) << n;
        EXPECT_EQ(reading->id, id) << n;
      } else {
        EXPECT_GT(reading->baseline_gap, 0.16) << n;
        EXPECT_LT(reading->baseline_gap, kMinBaselineGap) << n;
        EXPECT_EQ(outline_stage(*reading, params), Stage::baselines) << n;
      }
    }
  }
}

TEST(OutlineReading, SmallerFamiliesAreRefusedBeforeTheAlignmentFromOneAndAHalfPixelsPerUnit) {
  // 6x6 LFTags at 4 m (80 px, 1.67 px per unit of a 7x7, as in the crowded speed scenes)
  // read as 7x7: their structure starts at about 0.4, under 0.55 even smeared, so no
  // alignment is tried (in those scenes three, none converging, took up to 28 ms; with
  // the gate from 2 px per unit none of these reach it, their alignments failing). 7x7
  // markers at the same distance are still read.
  DetectorParams params;
  std::mt19937_64 rng(24);
  std::uniform_real_distribution<double> u(-1, 1);
  int at_the_gate = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const Far other = far_marker(6, random_id(Family(6), rng), 4.0, 180 * u(rng));
    const auto refused = read_outline(ImageView(other.scene.image), other.corners, Family(7));
    if (refused) {  // else refused even earlier, under kMinStartCorrelation
      ++at_the_gate;
      EXPECT_FALSE(refused->read) << "trial " << trial;
      EXPECT_EQ(refused->contrast, 0) << "trial " << trial << ": aligned";
      EXPECT_GE(refused->pixels_per_unit, kSharpPixelsPerUnit) << "trial " << trial;
      EXPECT_LT(refused->correlation, kMinSharpStartCorrelation) << "trial " << trial;
    }
    const TagId id = random_id(Family(7), rng);
    const Far far = far_marker(7, id, 4.0, 180 * u(rng));
    const auto reading = read_outline(ImageView(far.scene.image), far.corners, Family(7));
    ASSERT_TRUE(reading) << "trial " << trial;
    EXPECT_TRUE(acceptable(*reading, params)) << "trial " << trial;
    EXPECT_EQ(reading->id, id) << "trial " << trial;
  }
  // Their starts lie about 0.4, where the first gate refuses some of them: 13 of the 30
  // reach this one (16 in the sanitizer build, whose compiler rounds differently).
  EXPECT_GE(at_the_gate, 8);
}

TEST(OutlineReading, StopsAtTheFramesDeadline) {
  // 4x4 markers at 12 m (1.2 px per unit), read in full without a deadline; with one that
  // has passed the reading stops before its alignment and says so, never with an id.
  std::mt19937_64 rng(31);
  DetectorParams params;
  const Deadline passed(Deadline::thread_time() - 2, 1.0);
  ASSERT_TRUE(passed.passed());
  EXPECT_FALSE(Deadline().passed());
  int read = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const TagId id = random_id(Family(4), rng);
    const Far far = far_marker(4, id, 12, 37 * trial);
    const auto outline = coarse(far.corners, trial % 4, 0.3, rng);
    const auto full = read_outline(ImageView(far.scene.image), outline, Family(4));
    if (full && acceptable(*full, params) && full->id == id) ++read;
    const auto cut = read_outline(ImageView(far.scene.image), outline, Family(4), params.min_pixels_per_unit, passed);
    ASSERT_TRUE(cut.has_value()) << trial;
    EXPECT_TRUE(cut->past_deadline) << trial;
    EXPECT_FALSE(cut->read) << trial;
    EXPECT_EQ(outline_stage(*cut, params), Stage::deadline) << trial;
  }
  EXPECT_GE(read, 6) << "the markers are no longer read without a deadline: the test shows nothing";
}

namespace {

// A fronto-parallel 3x3 marker at `pixels_per_unit` on a 4-unit white margin, rendered by
// exact area coverage, with data cell `cell`'s square moved `shift` units to the right of
// where `id` puts it (its digit's bit 1 moves it one unit right) and printed with `ink`
// of the full ink's darkness; and its outer corners.
struct Shifted {
  cv::Mat1b image;
  std::array<cv::Point2d, 4> corners;
};
Shifted shifted_marker(TagId id, int cell, double shift, double pixels_per_unit, double ink = 1) {
  const Family f(3);
  constexpr int kFine = 20;  // grid cells per unit: shifts of 0.05 units
  const int margin = 4, side = f.side() + 2 * margin;
  cv::Mat1f grid(side * kFine, side * kFine, 1.0f);
  const auto fill = [&](double x, double y, double w, double h, double darkness = 1) {
    grid(cv::Rect(int(std::lround((x + margin) * kFine)), int(std::lround((y + margin) * kFine)),
                  int(std::lround(w * kFine)), int(std::lround(h * kFine)))) = float(1 - darkness);
  };
  const double s = f.side();
  fill(0, 0, s, 2), fill(0, s - 2, s, 2), fill(0, 0, 2, s), fill(s - 2, 0, 2, s);
  for (int g = 0; g < f.cell_count(); ++g) {
    const UnitRect q = f.square(g, f.is_baseline(g) ? 0 : id.digit(f.data_index(g)));
    fill(q.x + (g == cell ? shift : 0), q.y, q.width, q.height, g == cell ? ink : 1);
  }
  const double ppc = pixels_per_unit / kFine;
  const cv::Size size(int(std::ceil(side * pixels_per_unit)), int(std::ceil(side * pixels_per_unit)));
  const cv::Mat1f grey = resample_cells(grid, size, ppc, {-0.5, -0.5});
  Shifted out;
  grey.convertTo(out.image, CV_8U, 190, 40);  // ink 40, paper 230
  const auto at = [&](double x, double y) {
    return cv::Point2d((x + margin) * pixels_per_unit - 0.5, (y + margin) * pixels_per_unit - 0.5);
  };
  out.corners = {at(0, 0), at(s, 0), at(s, s), at(0, s)};
  return out;
}

}  // namespace

TEST(OutlineReading, EveryCellMustShowMostOfTheDifferenceItsDigitMakes) {
  // The evidence check at its boundary: a square moved part of the way towards its next
  // position shows that share less of the difference between them (1 - 2 x share of a
  // unit, on an exact render: the bound, 0.4, is a shift of 0.3). Moved 0.25 units it
  // still reads as itself; moved 0.35 (the cell's evidence is then 0.3, and the
  // per-pixel margin still passes), halfway or 0.65 (the near miss of the other id), no
  // digit is certain and the reading is refused; from 0.75 units on it reads as that
  // other id.
  DetectorParams params;
  const Family f(3);
  const TagId id(6789);
  const int cell = 4;  // a data cell of the middle row
  ASSERT_FALSE(f.is_baseline(cell));
  const int digit = id.digit(f.data_index(cell));
  ASSERT_EQ(digit >> 1, 0) << "the square must be free to move right";
  const TagId moved = id.with_digit(f.data_index(cell), digit | 2);
  for (const double ppu : {1.0, 2.5}) {
    for (const auto& [shift, expected] :
         {std::pair{0.0, std::optional<TagId>(id)}, std::pair{0.25, std::optional<TagId>(id)},
          std::pair{0.35, std::optional<TagId>()}, std::pair{0.5, std::optional<TagId>()},
          std::pair{0.65, std::optional<TagId>()}, std::pair{0.75, std::optional<TagId>(moved)},
          std::pair{1.0, std::optional<TagId>(moved)}}) {
      const std::string what = std::to_string(ppu) + " px per unit, moved " + std::to_string(shift);
      const Shifted m = shifted_marker(id, cell, shift, ppu);
      const auto reading = read_outline(ImageView(m.image), m.corners, f);
      ASSERT_TRUE(reading) << what;
      if (expected) {
        EXPECT_TRUE(acceptable(*reading, params)) << what << ": evidence " << reading->evidence;
        EXPECT_EQ(reading->id, *expected) << what;
        EXPECT_GE(reading->evidence, kMinEvidence) << what;
      } else {
        EXPECT_FALSE(acceptable(*reading, params)) << what << " read " << reading->id.to_decimal();
        EXPECT_LT(reading->evidence, kMinEvidence) << what;
        EXPECT_EQ(outline_stage(*reading, params), Stage::margin) << what;
      }
    }
  }
}

TEST(OutlineReading, AgainstCompleteIdsTheRunnerUpIsTheNearestListedId) {
  // A square moved 0.35 units towards its next position (evidence 0.3): refused against
  // every id one square off. With the ids in use complete, the runner-up is the nearest
  // other listed id: far from it (every square, or four, elsewhere) the reading is taken
  // in; with the id one square off listed too, that one is the runner-up and the reading
  // stays refused, as it does when its own id is not listed. Both directions: moved 0.65
  // units (the near miss of the other id), it reads as that one, and is taken in only
  // where that one is listed and this one is not.
  const Family f(3);
  const TagId id(6789);
  const int cell = 4;
  const int digit = id.digit(f.data_index(cell));
  ASSERT_EQ(digit >> 1, 0) << "the square must be free to move right";
  const TagId moved = id.with_digit(f.data_index(cell), digit | 2);
  const TagId far_a(6789 ^ 0x3fff), far_b(6789 ^ 0x0ff0);  // 7 and 4 squares elsewhere
  DetectorParams plain, complete;
  complete.ids_complete = true;
  struct Case {
    double shift;
    std::vector<TagId> listed;
    std::optional<TagId> taken;  // what is taken in, if anything
  };
  for (const double ppu : {1.0, 2.5})
    for (const Case& c : {Case{0.35, {id, far_a, far_b}, id}, Case{0.35, {id, moved, far_a}, std::nullopt},
                          Case{0.35, {far_a, far_b}, std::nullopt}, Case{0.65, {moved, far_a, far_b}, moved},
                          Case{0.65, {id, moved, far_b}, std::nullopt}}) {
      const std::string what = std::to_string(ppu) + " px per unit, moved " + std::to_string(c.shift) + ", " +
                               std::to_string(c.listed.size()) + " listed, first " + c.listed[0].to_decimal();
      const Shifted m = shifted_marker(id, cell, c.shift, ppu);
      const auto reading = read_outline(ImageView(m.image), m.corners, f, plain.min_pixels_per_unit, {}, nullptr,
                                        std::nullopt, &c.listed);
      ASSERT_TRUE(reading) << what;
      EXPECT_FALSE(acceptable(*reading, plain)) << what;
      complete.ids = c.listed;
      EXPECT_EQ(acceptable(*reading, complete), c.taken.has_value())
          << what << ": read " << reading->id.to_decimal() << ", listed noise margin " << reading->listed_noise_margin;
      if (c.taken) {
        EXPECT_EQ(reading->id, *c.taken) << what;
        EXPECT_GE(reading->listed_noise_margin, kMinListedNoiseMargin) << what;
        EXPECT_GE(reading->listed_evidence, kMinEvidence) << what;
      } else {
        // On a render without noise the neighbour stands many deviations away: the
        // evidence (0.3 of the difference shown) is what keeps it the runner-up.
        EXPECT_LT(reading->listed_evidence, kMinEvidence) << what;
      }
    }
  // Complete ids need ids.
  DetectorParams none;
  none.ids_complete = true;
  EXPECT_THROW(none.validate(), std::invalid_argument);
}

TEST(OutlineReading, ASquareFadedIntoThePaperIsNoEvidence) {
  // A data square printed fainter than the rest (glare, a shadow's edge) is no evidence
  // for any position, whichever it seems to fit. At half the ink it reads. At 0.3 and a
  // quarter it still fits its own position best but shows too little of the difference
  // its digit makes (kMinEvidence); at a tenth it may fit another position, and the
  // reading is refused all the same.
  DetectorParams params;
  const Family f(3);
  const TagId id(6789);
  const int cell = 4;
  ASSERT_FALSE(f.is_baseline(cell));
  for (const double ppu : {1.5, 4.0}) {
    for (const auto& [ink, accepted] : {std::pair{1.0, true}, std::pair{0.5, true}, std::pair{0.3, false},
                                        std::pair{0.25, false}, std::pair{0.1, false}}) {
      const std::string what = std::to_string(ppu) + " px per unit, ink " + std::to_string(ink);
      const Shifted m = shifted_marker(id, cell, 0, ppu, ink);
      const auto reading = read_outline(ImageView(m.image), m.corners, f);
      ASSERT_TRUE(reading) << what;
      EXPECT_EQ(acceptable(*reading, params), accepted)
          << what << ": margin " << reading->margin << ", evidence " << reading->evidence;
      if (accepted) {
        EXPECT_EQ(reading->id, id) << what;
        EXPECT_GE(reading->evidence, kMinEvidence) << what;
        continue;
      }
      EXPECT_EQ(outline_stage(*reading, params), Stage::margin) << what;
      EXPECT_LT(reading->evidence, kMinEvidence) << what;
      if (ink >= 0.25) {
        EXPECT_EQ(reading->id, id) << what;
      }
    }
  }
}

// The acceptance checks at their bounds, on a reading of a real far marker with one
// measurement moved to each side of one bound: a measurement the data put on the wrong
// side is refused at its own check, and the same reading just inside is accepted. The
// values are the ones stages.hpp and docs/detector.md give for the bound: true readings
// align at 0.78 or more as a whole marker; wrong readings above the resolution bound had
// margins up to 0.022; a contrast of 16 grey levels is what a defocused marker's white
// ring keeps over its cores where its margins still mean something; the ink the pixel
// model fits must be 0.4 of that contrast.
TEST(OutlineReading, EachCheckRefusesAReadingJustOutsideItsBound) {
  std::mt19937_64 rng(31);
  DetectorParams params;
  const Far far = far_marker(3, 4242, 20, 25);
  const auto read = read_outline(ImageView(far.scene.image), coarse(far.corners, 1, 0.3, rng), Family(3));
  ASSERT_TRUE(read);
  ASSERT_EQ(read->id, TagId(4242));
  ASSERT_EQ(outline_stage(*read, params), Stage::detected);
  // Inside every bound, with room: the checks below move one measurement at a time.
  OutlineReading base = *read;
  base.correlation = std::max(base.correlation, 0.8);
  base.marker_correlation = std::max(base.marker_correlation, 0.8);
  base.contrast = std::max(base.contrast, 40.0);
  base.margin = std::max(base.margin, 0.1);
  base.evidence = std::max(base.evidence, 0.6);
  base.model_ink = std::max(base.model_ink, 0.8);
  ASSERT_EQ(outline_stage(base, params), Stage::detected);
  struct Bound {
    double OutlineReading::*field;
    double inside, outside;
    Stage refused_at;
    const char* name;
  };
  for (const Bound& b : {Bound{&OutlineReading::marker_correlation, 0.78, 0.72, Stage::marker, "marker correlation"},
                         Bound{&OutlineReading::correlation, 0.78, 0.72, Stage::structure, "structure correlation"},
                         Bound{&OutlineReading::contrast, 17, 12, Stage::contrast, "contrast"},
                         Bound{&OutlineReading::margin, 0.032, 0.022, Stage::margin, "margin"},
                         Bound{&OutlineReading::evidence, 0.41, 0.38, Stage::margin, "evidence"},
                         Bound{&OutlineReading::model_ink, 0.42, 0.38, Stage::margin, "model ink"},
                         Bound{&OutlineReading::baseline_gap, 0.3, 0.2, Stage::baselines, "baseline gap"}}) {
    OutlineReading r = base;
    r.*b.field = b.inside;
    EXPECT_EQ(outline_stage(r, params), Stage::detected) << b.name << " " << b.inside;
    r.*b.field = b.outside;
    EXPECT_EQ(outline_stage(r, params), b.refused_at) << b.name << " " << b.outside;
  }
}

// Two 4x4 markers cut from the field experiment's motion clips (tuning set): 59 px at 30
// degrees of tilt smeared by 13.7 px, and 36 px at 27 degrees smeared by 10.1 px, with
// rolling shutter, defocus, noise and JPEG. The sharp structure aligned first does not
// converge or lands under kMinSmearedCorrelation, so no smear was sought after it; sought
// at the start, the smear aligns and the marker reads. Its contrast is then checked as
// the unsmeared template would show it (the smear's grey cores once failed that check).
TEST(OutlineReading, LongMotionBlursAreSoughtAtTheStartWhereTheSharpStructureDoesNotAlign) {
  for (const auto& [file, id] : {std::pair<const char*, std::uint64_t>{"motion-4x4-id94099419.png", 94099419},
                                 {"motion-4x4-id234906164.png", 234906164}}) {
    const cv::Mat1b frame = read_grey_image(std::string(LFTAG_TEST_DATA) + "/" + file);
    ASSERT_FALSE(frame.empty()) << file;
    DetectorParams p;
    p.families = {Family(4)};
    p.camera = Camera::pinhole(1280, 1280, frame.cols / 2.0, frame.rows / 2.0);
    DetectionTrace trace;
    const std::vector<Detection> found = Detector(p).detect(ImageView(frame), nullptr, &trace);
    ASSERT_EQ(found.size(), 1u) << file;
    EXPECT_EQ(found[0].id, TagId(id)) << file;
    bool smeared = false;
    for (const OutlineVerdict& v : trace.outline_reads) smeared |= v.stage == Stage::detected && v.smear >= 4;
    EXPECT_TRUE(smeared) << file << ": read from an outline, a smear of 4 units or more found";
  }
}
