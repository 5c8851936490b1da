// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological filtering, vertex estimation and the area constraint (src/detect/candidates.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "binary.hpp"
#include "lftag/render.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::BinaryImage;
using lftag::detail::Blob;
using lftag::detail::Candidate;
using lftag::detail::RegionLabeller;
using lftag::detail::RegionTree;

namespace {

// The runs of region r as (row, x0, x1), top to bottom.
struct RowRun {
  int y, x0, x1;
};
std::vector<RowRun> runs_of(const RegionTree& t, int r) {
  std::vector<RowRun> out;
  t.for_each_run(r, [&](int y, int x0, int x1) { out.push_back({y, x0, x1}); });
  return out;
}

// A grey image, its binary image (black below a global level, so that these tests do not
// depend on the threshold stage), its region tree and the region of every pixel.
struct Analysed {
  cv::Mat1b grey;
  BinaryImage binary;
  RegionTree tree;
  cv::Mat1i map;
  ImageView view() const { return ImageView(grey); }
  int at(int x, int y) const { return map(y, x); }
  int at(cv::Point2d p) const { return map(cvRound(p.y), cvRound(p.x)); }
};

Analysed analyse(const cv::Mat1b& grey, const cv::Mat1b& black) {
  Analysed a;
  a.grey = grey;
  a.binary = lftag::test::binary_from_mask(black);
  RegionLabeller().label(a.binary, a.tree);
  a.map = cv::Mat1i(grey.size(), -1);
  for (int r = 0; r < int(a.tree.regions.size()); ++r)
    for (const RowRun& run : runs_of(a.tree, r))
      for (int x = run.x0; x < run.x1; ++x) a.map(run.y, x) = r;
  return a;
}

Analysed analyse(const cv::Mat1b& grey, int level = 128) {
  cv::Mat1b black = grey < level;
  return analyse(grey, black);
}

// '#' black (grey 0), '.' white (255).
cv::Mat1b from_rows(const std::vector<std::string>& rows) {
  cv::Mat1b m(int(rows.size()), int(rows[0].size()), uchar(255));
  for (int y = 0; y < m.rows; ++y)
    for (int x = 0; x < m.cols; ++x) m(y, x) = rows[y][x] == '#' ? 0 : 255;
  return m;
}

// A white pixel that should count for a blob with `share`, at grey `grey`.
struct Probe {
  int x, y, grey;
  double share;
};

// BlobMeasurer::measure's expected output from first principles: every pixel of the region with
// weight white - grey, plus the probes with their share.
void expect_blob(const Analysed& a, int region, int reach, double white, const std::vector<Probe>& probes,
                 const std::string& what) {
  double m = 0, mx = 0, my = 0;
  for (int y = 0; y < a.grey.rows; ++y)
    for (int x = 0; x < a.grey.cols; ++x)
      if (a.map(y, x) == region) {
        const double w = std::max(0.0, white - a.grey(y, x));
        m += w, mx += w * x, my += w * y;
      }
  for (const Probe& p : probes) {
    const double w = p.share * std::max(0.0, white - p.grey);
    m += w, mx += w * p.x, my += w * p.y;
  }
  const Blob b = detail::BlobMeasurer().measure(a.tree, region, a.view(), a.binary, reach, white);
  EXPECT_EQ(b.region, region) << what;
  EXPECT_EQ(b.area, a.tree.regions[region].area) << what;
  EXPECT_NEAR(b.mass, m, 1e-9) << what;
  EXPECT_NEAR(b.centroid.x, mx / m, 1e-9) << what;
  EXPECT_NEAR(b.centroid.y, my / m, 1e-9) << what;
}

// The marker's position of unit point u in rasterize_marker's image.
cv::Point2d raster_pixel(cv::Point2d u, double ppu, double margin) {
  return {(u.x + margin) * ppu - 0.5, (u.y + margin) * ppu - 0.5};
}

// A black box (outer size `size`, border `border`) on white, with filled black squares in it.
cv::Mat1b boxed(int size, int border, const std::vector<cv::Rect>& squares, int margin = 5) {
  cv::Mat1b m(size + 2 * margin, size + 2 * margin, uchar(255));
  m(cv::Rect(margin, margin, size, size)).setTo(0);
  m(cv::Rect(margin + border, margin + border, size - 2 * border, size - 2 * border)).setTo(255);
  for (const cv::Rect& r : squares) m(r + cv::Point(margin, margin)).setTo(0);
  return m;
}

// A 3 x 3 grid of s x s squares, `pitch` apart, starting at `first` inside a box.
std::vector<cv::Rect> grid(int s, int pitch, int first) {
  std::vector<cv::Rect> out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.emplace_back(first + c * pitch, first + r * pitch, s, s);
  return out;
}

DetectorParams params_for(std::vector<Family> families) {
  DetectorParams p;
  p.families = std::move(families);
  return p;
}

std::vector<Candidate> run(const Analysed& a, const DetectorParams& p, DetectionStats& stats,
                           const Camera& camera = Camera::default_for(640, 480)) {
  std::vector<Candidate> out;
  detail::find_candidates(a.tree, a.binary, a.view(), p, camera, out, stats);
  return out;
}

std::set<int> regions_of(const Candidate& c) {
  std::set<int> s;
  for (const Blob& b : c.blobs) s.insert(b.region);
  return s;
}

}  // namespace

// ---------------------------------------------------------------------------- BlobMeasurer

TEST(MeasureBlob, ExactOnAPixelAlignedMarker) {
  // 5 pixels per unit: every edge on a pixel boundary, pixels 0 or 255. With white = 255
  // the ring weighs nothing and each blob's mass is 255 x its area, its centroid the centre.
  const Family f(3);
  const TagId id = 6789;
  const double ppu = 5, margin = 2;
  const Analysed a = analyse(rasterize_marker(f, id, ppu, margin));
  const std::vector<UnitRect> squares = f.black_squares(id);
  for (int g = 0; g < f.cell_count(); ++g) {
    const cv::Point2d centre = raster_pixel(f.centers(id)[g], ppu, margin);
    const int r = a.at(centre);
    ASSERT_GE(r, 0);
    ASSERT_TRUE(a.tree.regions[r].black);
    const Blob b = detail::BlobMeasurer().measure(a.tree, r, a.view(), a.binary, 1, 255.0);
    EXPECT_EQ(b.area, int(squares[g].width * squares[g].height * ppu * ppu)) << "cell " << g;
    EXPECT_DOUBLE_EQ(b.mass, 255.0 * b.area) << "cell " << g;
    EXPECT_NEAR(b.centroid.x, centre.x, 1e-9) << "cell " << g;
    EXPECT_NEAR(b.centroid.y, centre.y, 1e-9) << "cell " << g;
  }
}

TEST(MeasureBlob, CentroidsOfRasterisedMarkersAreTheSquareCentres) {
  // Off-grid scales: the anti-aliased edge pixels straddle the binary boundary; the ring of
  // one pixel brings back the ink that the binary image left outside. Tolerance 0.02 px.
  for (const auto& [n, id, ppu] : {std::tuple{3, TagId(6789), 4.3}, std::tuple{3, TagId(1234), 7.7},
                                   std::tuple{4, TagId(98765432), 3.6}, std::tuple{5, TagId(123456789), 5.45}}) {
    const Family f(n);
    const double margin = 2;
    const Analysed a = analyse(rasterize_marker(f, id, ppu, margin));
    for (int g = 0; g < f.cell_count(); ++g) {
      const cv::Point2d truth = raster_pixel(f.centers(id)[g], ppu, margin);
      const int r = a.at(truth);
      ASSERT_GE(r, 0);
      ASSERT_TRUE(a.tree.regions[r].black) << f.name() << " cell " << g;
      const Blob b = detail::BlobMeasurer().measure(a.tree, r, a.view(), a.binary, 1, 255.0);
      EXPECT_LT(cv::norm(b.centroid - truth), 0.02)
          << f.name() << " at " << ppu << " px/u, cell " << g << ": " << b.centroid << " vs " << truth;
      // The mass is the square's ink: area in pixels x 255.
      const UnitRect s = f.black_squares(id)[g];
      EXPECT_NEAR(b.mass, 255.0 * s.width * s.height * ppu * ppu, 0.02 * 255.0 * s.width * s.height * ppu * ppu);
    }
  }
}

TEST(MeasureBlob, CentroidsOfATiltedSceneAreTheProjectedSquareCentroids) {
  // A 100 px marker tilted 35 degrees: centroids within 0.02 px of the area centroids of the
  // projected squares (the ground truth), with the white region's own grey as zero weight.
  SceneParams p;
  p.camera = Camera::pinhole(500, 500, 319.5, 239.5, 640, 480);
  p.background = 0.9;
  SceneMarker m;
  m.family = Family(3);
  m.id = 4242;
  m.tag_size = 0.2;
  m.tvec = {0.03, -0.02, 1.0};
  cv::Matx33d rx;
  cv::Rodrigues(cv::Vec3d(35 * CV_PI / 180, 0, 0), rx);
  cv::Matx33d rz;
  cv::Rodrigues(cv::Vec3d(0, 0, 20 * CV_PI / 180), rz);
  cv::Rodrigues(rx * rz, m.rvec);
  const RenderedScene scene = render_scene(p, {m});
  const MarkerTruth& t = scene.truth[0];
  const Analysed a = analyse(scene.image, int(255 * (m.white + m.black) / 2));
  const double white = 255.0 * m.white;
  for (int g = 0; g < m.family.cell_count(); ++g) {
    const int r = a.at(t.centers[g]);
    ASSERT_TRUE(r >= 0 && a.tree.regions[r].black);
    const Blob b = detail::BlobMeasurer().measure(a.tree, r, a.view(), a.binary, 1, white);
    EXPECT_LT(cv::norm(b.centroid - t.centroids[g]), 0.02)
        << "cell " << g << ": " << b.centroid << " vs " << t.centroids[g];
  }
}

TEST(MeasureBlob, RingPixelsGoToTheNearestBlobAndTiesCountHalf) {
  // A black U (9 pixels) around a single black pixel B at (3, 1). Seen from the U, reach 1:
  // (2,1), (4,1) and (3,2) are one pixel from both: half; (2,2) and (4,2) are one pixel from
  // the U and sqrt(2) from B: whole; (0,1) and (6,3) whole; (3,0) touches only B: nothing;
  // (0,0) is sqrt(2) from the U, beyond the reach: nothing.
  cv::Mat1b grey = from_rows({
      ".........",
      ".#.#.#...",
      ".#...#...",
      ".#####...",
      ".........",
      ".........",
  });
  const std::vector<Probe> probes = {{2, 1, 155, 0.5}, {4, 1, 135, 0.5}, {3, 2, 95, 0.5},  {2, 2, 205, 1.0},
                                     {4, 2, 175, 1.0}, {0, 1, 225, 1.0}, {6, 3, 185, 1.0}, {3, 0, 15, 0.0},
                                     {0, 0, 35, 0.0},  {0, 2, 245, 1.0}, {4, 4, 55, 1.0},  {6, 0, 5, 0.0}};
  for (const Probe& p : probes) grey(p.y, p.x) = uchar(p.grey);
  cv::Mat1b black = from_rows({
                        ".........",
                        ".#.#.#...",
                        ".#...#...",
                        ".#####...",
                        ".........",
                        ".........",
                    }) == 0;
  const Analysed a = analyse(grey, black);
  const int u = a.at(1, 1);
  ASSERT_EQ(a.tree.regions[u].area, 9);
  ASSERT_NE(a.at(3, 1), u);
  expect_blob(a, u, 1, 255.0, probes, "U, reach 1");
  // Reach 0: the region's own pixels only.
  expect_blob(a, u, 0, 255.0, {}, "U, reach 0");
}

TEST(MeasureBlob, RingPixelsNearerAnotherBlobDoNotCount) {
  // An L (x = 2, y = 1..6 and y = 6, x = 2..6) and a black pixel B at (5, 2), reach 2
  // (distances are Euclidean, squared up to 4):
  //   (3,2): 1 from the L, 2 from B: whole     (4,2): 2 from the L, 1 from B: nothing
  //   (5,4): 2 from both: half                  (4,4): 2 from the L, sqrt(5) from B: whole
  //   (4,3): 2 from the L, sqrt(2) from B: nothing
  //   (6,4): 2 from the L, sqrt(5) from B: whole (6,3): 3 from the L: nothing
  //   (8,6): 2 from the L: whole                (1,0): sqrt(2) from the L: whole
  //   (0,0): sqrt(5) from the L: nothing
  std::vector<std::string> rows(10, "..........");
  for (int y = 1; y <= 6; ++y) rows[y][2] = '#';
  for (int x = 2; x <= 6; ++x) rows[6][x] = '#';
  rows[2][5] = '#';
  cv::Mat1b grey = from_rows(rows);
  const cv::Mat1b black = grey == 0;
  const std::vector<Probe> probes = {{3, 2, 100, 1.0}, {4, 2, 10, 0.0},  {5, 4, 60, 0.5},  {4, 4, 170, 1.0},
                                     {4, 3, 20, 0.0},  {6, 4, 140, 1.0}, {6, 3, 30, 0.0},  {8, 6, 210, 1.0},
                                     {1, 0, 230, 1.0}, {0, 0, 40, 0.0},  {2, 8, 120, 1.0}, {0, 4, 190, 1.0}};
  for (const Probe& p : probes) grey(p.y, p.x) = uchar(p.grey);
  const Analysed a = analyse(grey, black);
  const int l = a.at(2, 1);
  ASSERT_EQ(a.tree.regions[l].area, 10);
  expect_blob(a, l, 2, 255.0, probes, "L, reach 2");
}

TEST(MeasureBlob, TiesAndNearerBlobsAcrossTheWindowEdge) {
  // Two bars one white pixel apart: the gap pixel (3, 1) is one pixel from each, so each
  // bar gets half of it, as in RingPixelsGoToTheNearestBlobAndTiesCountHalf; here the other
  // bar lies just outside the measured bar's window.
  cv::Mat1b grey = from_rows({"........", ".##.##..", "........"});
  const cv::Mat1b black = grey == 0;
  grey(1, 3) = 55;
  const Analysed a = analyse(grey, black);
  expect_blob(a, a.at(1, 1), 1, 255.0, {{3, 1, 55, 0.5}}, "left bar");
  expect_blob(a, a.at(4, 1), 1, 255.0, {{3, 1, 55, 0.5}, {6, 1, 255, 1.0}}, "right bar");
  // Reach 2: (4, 2) is 2 from the left pixel and 1 from the right one: not the left's.
  std::vector<std::string> rows(5, "........");
  rows[2][2] = '#', rows[2][5] = '#';
  cv::Mat1b g2 = from_rows(rows);
  const cv::Mat1b b2 = g2 == 0;
  g2(2, 4) = 75, g2(2, 3) = 175;
  const Analysed a2 = analyse(g2, b2);
  expect_blob(a2, a2.at(2, 2), 2, 255.0, {{3, 2, 175, 1.0}, {4, 2, 75, 0.0}}, "reach 2");
}

TEST(MeasureBlob, WhiteLevelIsTheZeroWeight) {
  // Pixels brighter than `white` weigh nothing, whether ring or blob.
  cv::Mat1b grey = from_rows({".....", ".##..", ".##..", "....."});
  const cv::Mat1b black = grey == 0;
  grey(1, 1) = 120, grey(1, 2) = 60, grey(2, 1) = 150, grey(2, 2) = 0;  // 150 > white below
  grey(1, 3) = 90, grey(2, 3) = 200, grey(0, 1) = 110;                  // ring
  const Analysed a = analyse(grey, black);
  const int r = a.at(1, 1);
  ASSERT_EQ(a.tree.regions[r].area, 4);
  expect_blob(a, r, 1, 140.0, {{3, 1, 90, 1.0}, {1, 0, 110, 1.0}}, "white 140");
  // A blob with no ink at all keeps the middle of its box as its centroid.
  const cv::Mat1b flat(grey.size(), uchar(250));
  const Analysed f = analyse(flat, black);
  const Blob b = detail::BlobMeasurer().measure(f.tree, f.at(1, 1), f.view(), f.binary, 1, 200.0);
  EXPECT_EQ(b.mass, 0.0);
  EXPECT_EQ(b.centroid, cv::Point2d(1.5, 1.5));
}

// ---------------------------------------------------------------------------- find_candidates

TEST(FindCandidates, AMarkerIsOneCandidate) {
  const Family f(3);
  const TagId id = 6789;
  const double ppu = 6.3, margin = 2;
  const Analysed a = analyse(rasterize_marker(f, id, ppu, margin));
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3), Family(4)}), stats);
  ASSERT_EQ(out.size(), 1u);
  const Candidate& c = out[0];
  EXPECT_EQ(c.family, f);
  EXPECT_EQ(c.white_region, a.at(raster_pixel({3, 3}, ppu, margin)));
  EXPECT_EQ(c.white_area, a.tree.regions[c.white_region].area);
  ASSERT_EQ(c.blobs.size(), 9u);
  std::set<int> expected;
  for (int g = 0; g < 9; ++g) expected.insert(a.at(raster_pixel(f.centers(id)[g], ppu, margin)));
  EXPECT_EQ(regions_of(c), expected);
  std::vector<int> kids;
  for (const Blob& b : c.blobs) kids.push_back(b.region);
  const detail::PaperLevel paper =
      detail::paper_under(a.tree, c.white_region, kids.data(), int(kids.size()), a.view(), a.binary, 1);
  EXPECT_TRUE(paper.local.empty());  // evenly lit: the white region's level everywhere
  EXPECT_EQ(paper.level, c.paper.level);
  for (const Blob& b : c.blobs) {
    const Blob direct = detail::BlobMeasurer().measure(a.tree, b.region, a.view(), a.binary, 1, paper);
    EXPECT_EQ(b.mass, direct.mass);
    EXPECT_EQ(b.centroid, direct.centroid);
    EXPECT_EQ(b.point, b.centroid);  // no distortion
  }
  // The paper's level: the upper quartile of the white region's grey levels (the least level
  // that at least 3/4 of its pixels do not exceed), from its pixels.
  std::vector<int> levels;
  for (int y = 0; y < a.grey.rows; ++y)
    for (int x = 0; x < a.grey.cols; ++x)
      if (a.map(y, x) == c.white_region) levels.push_back(a.grey(y, x));
  std::sort(levels.begin(), levels.end());
  const std::size_t q = (3 * levels.size() + 3) / 4 - 1;  // ceil(3/4 count) - 1
  EXPECT_EQ(c.paper.level, levels[q]);
  EXPECT_EQ(stats.regions, std::int64_t(a.tree.regions.size()));
  EXPECT_EQ(stats.topology, 1);
  EXPECT_EQ(stats.area, 1);
  // Counters add up over calls.
  run(a, params_for({Family(3)}), stats);
  EXPECT_EQ(stats.regions, 2 * std::int64_t(a.tree.regions.size()));
  EXPECT_EQ(stats.topology, 2);
  EXPECT_EQ(stats.area, 2);
}

TEST(FindCandidates, WhiteLevelFollowsTheCentroidReference) {
  // Paper at grey 200: the local white is the white region's level (200), the full scale 255.
  cv::Mat1b grey = rasterize_marker(Family(3), 77, 5.0, 2.0);
  grey = grey * (200.0 / 255.0);
  const Analysed a = analyse(grey, 100);
  DetectorParams p = params_for({Family(3)});
  DetectionStats stats;
  std::vector<Candidate> out = run(a, p, stats);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_NEAR(out[0].paper.level, 200.0, 1e-9);  // pixel-aligned: the white region is all 200
  const double local_mass = out[0].blobs[0].mass;
  p.centroid_reference = CentroidReference::full_scale;
  out = run(a, p, stats);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].paper.level, 255.0);
  // The ring now weighs 55 per pixel on top of 200 per black pixel.
  EXPECT_GT(out[0].blobs[0].mass, local_mass * 255.0 / 200.0);
}

TEST(FindCandidates, LocalWhiteIsTheUpperQuartileOfTheWhiteRegion) {
  // The white room of a boxed grid painted in four bands of 120, 160, 200 and 240 (and the
  // squares' rings), so the quartiles are far apart: the level is the least grey level that
  // at least 3/4 of the room's pixels do not exceed.
  cv::Mat1b grey = boxed(100, 3, grid(12, 28, 12));
  const cv::Mat1b black = grey == 0;
  for (int y = 0; y < grey.rows; ++y)
    for (int x = 0; x < grey.cols; ++x)
      if (!black(y, x) && x > 8 && x < 102 && y > 8 && y < 102)
        grey(y, x) = uchar(120 + 40 * std::min(3, (x - 8) * 4 / 94));
  const Analysed a = analyse(grey, black);
  const int room = a.at(10, 10);
  std::vector<int> levels;
  for (int y = 0; y < grey.rows; ++y)
    for (int x = 0; x < grey.cols; ++x)
      if (a.map(y, x) == room) levels.push_back(grey(y, x));
  std::sort(levels.begin(), levels.end());
  const int expected = levels[(3 * levels.size() + 3) / 4 - 1];
  ASSERT_NE(expected, levels.back());  // the case tells the quartile from the maximum
  double mean = 0;
  for (int v : levels) mean += v;
  mean /= levels.size();
  ASSERT_GT(std::abs(expected - mean), 20);  // and from the mean
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].paper.level, expected);
}

TEST(FindCandidates, EachSquaresInkIsMeasuredAgainstThePaperAroundIt) {
  // Squares of ink 0 on paper lit in three vertical bands (120, 180 and 240, a hard
  // shadow's edges), none across a band's edge: each square's ink is its own pixels'
  // darkness below the paper around it, so all nine weigh alike (144 px at the white
  // level each, their rings of paper nothing). Against one paper level for the whole
  // marker the shadowed squares' rings of paper would count as ink.
  cv::Mat1b grey = boxed(100, 3, grid(12, 28, 12));
  const cv::Mat1b black = grey == 0;
  for (int y = 8; y < 103; ++y)
    for (int x = 8; x < 103; ++x)
      if (!black(y, x)) grey(y, x) = x < 37 ? 120 : x < 65 ? 180 : 240;
  const Analysed a = analyse(grey, black);
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
  ASSERT_EQ(out.size(), 1u);
  const double level = out[0].paper.level;
  std::vector<int> kids;
  for (const Blob& b : out[0].blobs) {
    EXPECT_NEAR(b.mass, 144 * level, 0.005 * 144 * level) << b.centroid;
    kids.push_back(b.region);
  }
  const detail::PaperLevel paper =
      detail::paper_under(a.tree, out[0].white_region, kids.data(), int(kids.size()), a.view(), a.binary, 1);
  ASSERT_FALSE(paper.local.empty());
  EXPECT_NEAR(paper.ink(30, 20, 120), 0, 1e-9);         // paper in the darkest band
  EXPECT_NEAR(paper.ink(60, 20, 90), level / 2, 1e-9);  // half the paper's light, in the middle band
  // One level for the marker: the first column's rings (48 px of paper at 120) weigh as ink.
  const auto mass_at = [&](const Blob& b, const detail::PaperLevel& p) {
    return detail::BlobMeasurer().measure(a.tree, b.region, a.view(), a.binary, 1, p).mass;
  };
  const Blob& dark = *std::min_element(out[0].blobs.begin(), out[0].blobs.end(),
                                       [](const Blob& u, const Blob& v) { return u.centroid.x < v.centroid.x; });
  EXPECT_EQ(mass_at(dark, detail::PaperLevel(level)), 144 * level + 48 * (level - 120));
}

TEST(FindCandidates, SmallSquaresAreMeasuredAgainstTheWhiteRegionsLevel) {
  // Under kMinLocalPaperArea pixels a square, no pixel between squares is pure paper: the
  // white region's level stands for every pixel.
  const Analysed a = analyse(boxed(22, 1, grid(4, 6, 3)));
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
  ASSERT_EQ(out.size(), 1u);
  std::vector<int> kids;
  for (const Blob& b : out[0].blobs) kids.push_back(b.region);
  const detail::PaperLevel paper =
      detail::paper_under(a.tree, out[0].white_region, kids.data(), int(kids.size()), a.view(), a.binary, 1);
  EXPECT_TRUE(paper.local.empty());
  EXPECT_EQ(paper.level, out[0].paper.level);
}

TEST(FindCandidates, PointsAreUndistortedCentroids) {
  const Analysed a = analyse(rasterize_marker(Family(3), 300, 6.0, 2.0));
  Camera cam = Camera::pinhole(150, 150, 0, 0, 160, 160);
  cam.distortion = {-0.3, 0.1, 0.001, 0.002, 0};
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats, cam);
  ASSERT_EQ(out.size(), 1u);
  for (const Blob& b : out[0].blobs) {
    const cv::Point2d expected = cam.undistort({b.centroid})[0];
    EXPECT_NEAR(b.point.x, expected.x, 1e-9);
    EXPECT_NEAR(b.point.y, expected.y, 1e-9);
    EXPECT_GT(cv::norm(b.point - b.centroid), 0.1);  // the distortion is not negligible here
  }
}

TEST(FindCandidates, NoiseChildrenAreIgnored) {
  // A 100 px box, 3 px border: a white room of 94 x 94 holding nine 12 x 12 squares
  // (white area 7540, noise below 7540 / 500 = 15.08 px), plus specks of 1 and 4 px.
  std::vector<cv::Rect> squares = grid(12, 28, 12);
  std::vector<cv::Rect> specks;
  for (int i = 0; i < 8; ++i) specks.emplace_back(6 + 11 * i, 6, i % 2 ? 2 : 1, i % 2 ? 2 : 1);
  std::vector<cv::Rect> all = squares;
  all.insert(all.end(), specks.begin(), specks.end());
  const Analysed a = analyse(boxed(100, 3, all));
  const int room = a.at(10, 10);
  ASSERT_EQ(a.tree.regions[room].child_count, 17);
  ASSERT_EQ(a.tree.regions[room].area, 94 * 94 - 9 * 144 - 4 * 1 - 4 * 4);
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
  ASSERT_EQ(out.size(), 1u);
  std::set<int> expected;
  for (const cv::Rect& r : squares) expected.insert(a.at(r.x + 5 + 1, r.y + 5 + 1));
  EXPECT_EQ(regions_of(out[0]), expected);
  EXPECT_EQ(stats.topology, 1);

  // The noise bound is a fraction of the white region: with a fraction that puts it
  // between 1 and 4 px, the four 2 x 2 specks count and the room has 13 > 9 + 3 children.
  // (A loose tau1 keeps any bound tied to the largest child below 4 px.)
  DetectorParams p = params_for({Family(3)});
  p.min_child_fraction = 3.0 / a.tree.regions[room].area;
  p.max_ink_ratio = 50;
  DetectionStats none;
  EXPECT_TRUE(run(a, p, none).empty());
  EXPECT_EQ(none.topology, 0);
  EXPECT_EQ(none.area, 0);
}

TEST(FindCandidates, ChildrenTooSmallBesideTheLargestAreNoise) {
  // Eight 12 x 12 squares, one 30 x 30 and four 7 x 7 extras (49 px, above the 15 px bound
  // from the white area): with max_child_ratio = 14 the bound from the largest child is
  // 900 / 14 = 64.3 px, so the extras are noise and the room is a candidate; with
  // max_child_ratio = 100 (9 px) the extras count, making 13 children.
  std::vector<cv::Rect> all = grid(12, 28, 12);
  all[8] = cv::Rect(62, 62, 30, 30);
  for (int i = 0; i < 4; ++i) all.emplace_back(6 + 16 * i, 4, 7, 7);
  const Analysed a = analyse(boxed(100, 3, all));
  const int room = a.at(10, 20);
  ASSERT_FALSE(a.tree.regions[room].black);
  ASSERT_EQ(a.tree.regions[room].child_count, 13);
  ASSERT_GT(49, a.tree.regions[room].area / 500.0);
  DetectorParams p = params_for({Family(3)});
  p.max_child_ratio = 14;
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, p, stats);
  ASSERT_EQ(out.size(), 1u);
  for (const Blob& b : out[0].blobs) EXPECT_GE(b.area, 144);
  p.max_child_ratio = 100;
  DetectionStats s2;
  EXPECT_TRUE(run(a, p, s2).empty());
  EXPECT_EQ(s2.topology, 0);
}

TEST(FindCandidates, ChildrenAtTheNoiseBoundCount) {
  // Nine 12 x 12 squares and max_child_ratio = 18, with no bound from the white area: the
  // bound is 144 / 18 = 8 px exactly. Four extra children of 8 px are children
  // (13 > 9 + 3: no candidate), four of 7 px are noise (a candidate).
  for (const auto& [w, h, kept] : {std::tuple{2, 4, true}, std::tuple{1, 7, false}}) {
    std::vector<cv::Rect> all = grid(12, 28, 12);
    for (int i = 0; i < 4; ++i) all.emplace_back(6 + 16 * i, 4, w, h);
    const Analysed a = analyse(boxed(100, 3, all));
    ASSERT_EQ(a.tree.regions[a.at(10, 20)].child_count, 13);
    DetectorParams p = params_for({Family(3)});
    p.min_child_fraction = 0;
    p.max_child_ratio = 18;
    DetectionStats stats;
    EXPECT_EQ(run(a, p, stats).size(), kept ? 0u : 1u) << w * h << " px";
    EXPECT_EQ(stats.topology, kept ? 0 : 1) << w * h << " px";
  }
}

TEST(FindCandidates, TooManyChildrenIsNoCandidate) {
  // Nine 12 x 12 squares and k extra 5 x 5 children (25 px, above the 15 px noise bound):
  // with max_extra_children = 3, up to 12 children are a candidate, 13 are not.
  const std::vector<cv::Rect> squares = grid(12, 28, 12);
  for (int extra = 0; extra <= 5; ++extra) {
    std::vector<cv::Rect> all = squares;
    for (int i = 0; i < extra; ++i) all.emplace_back(6 + 16 * i, 5, 5, 5);
    const Analysed a = analyse(boxed(100, 3, all));
    ASSERT_EQ(a.tree.regions[a.at(10, 10)].child_count, 9 + extra);
    DetectionStats stats;
    const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
    SCOPED_TRACE("extra children: " + std::to_string(extra));
    if (extra <= 3) {
      ASSERT_EQ(out.size(), 1u);
      std::set<int> expected;
      for (const cv::Rect& r : squares) expected.insert(a.at(r.x + 6, r.y + 6));
      EXPECT_EQ(regions_of(out[0]), expected);  // the nine largest
      EXPECT_EQ(stats.topology, 1);
    } else {
      EXPECT_TRUE(out.empty());
      EXPECT_EQ(stats.topology, 0);
    }
    // More extra children allowed: always a candidate.
    DetectorParams p = params_for({Family(3)});
    p.max_extra_children = 5;
    DetectionStats more;
    EXPECT_EQ(run(a, p, more).size(), 1u);
  }
  // Fewer than n^2 children: nothing.
  std::vector<cv::Rect> eight(squares.begin(), squares.begin() + 8);
  DetectionStats stats;
  EXPECT_TRUE(run(analyse(boxed(100, 3, eight)), params_for({Family(3)}), stats).empty());
  EXPECT_EQ(stats.topology, 0);
}

TEST(FindCandidates, TheNSquaredLargestChildrenAreKept) {
  // Twelve children of distinct sizes 9 x 9 .. 14 x 14 (and 9 x 10 ...): the nine largest
  // are the blobs, whatever the order in which the labeller met them.
  std::vector<cv::Rect> rects;
  const int sizes[12][2] = {{9, 9},   {14, 14}, {10, 9},  {13, 13}, {10, 10}, {12, 13},
                            {11, 10}, {12, 12}, {11, 11}, {9, 11},  {14, 13}, {11, 12}};
  for (int i = 0; i < 12; ++i) rects.emplace_back(8 + (i % 4) * 22, 8 + (i / 4) * 28, sizes[i][0], sizes[i][1]);
  const Analysed a = analyse(boxed(100, 3, rects));
  std::vector<std::pair<int, int>> by_area;  // (area, region)
  for (const cv::Rect& r : rects) {
    const int region = a.at(r.x + 5, r.y + 5);
    ASSERT_EQ(a.tree.regions[region].area, r.area());
    by_area.emplace_back(r.area(), region);
  }
  std::sort(by_area.rbegin(), by_area.rend());
  std::set<int> expected;
  for (int i = 0; i < 9; ++i) expected.insert(by_area[i].second);
  DetectionStats stats;
  const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(regions_of(out[0]), expected);
  // Blobs carry their region's area.
  for (const Blob& b : out[0].blobs) EXPECT_EQ(b.area, a.tree.regions[b.region].area);
}

TEST(FindCandidates, AreaConstraintOnTheBlobsInk) {
  // Eight 6 x 6 squares and one bigger square. The ink is the area (crisp pixels, ring at
  // the white level); the constraint divides it by a plane fitted to the cube roots of the
  // inks over the centroids, cubed, which takes up part of a lone heavy square: largest
  // over smallest normalised ink is 2.04 for 12 x 12, 4.09 for 20 x 20, 5.57 for 24 x 24.
  struct Case {
    int side;
    double normalised;
  };
  for (const Case& k : {Case{12, 2.04}, Case{20, 4.09}, Case{24, 5.57}}) {
    std::vector<cv::Rect> all;
    for (int i = 0; i < 8; ++i) all.emplace_back(10 + (i % 4) * 20, 10 + (i / 4) * 20, 6, 6);
    all.emplace_back(60, 60, k.side, k.side);
    const Analysed a = analyse(boxed(100, 3, all));
    SCOPED_TRACE("side " + std::to_string(k.side));
    ASSERT_EQ(a.tree.regions[a.at(10, 10)].child_count, 9);
    for (double tau1 : {k.normalised - 0.02, k.normalised + 0.02}) {
      DetectorParams p = params_for({Family(3)});
      p.max_ink_ratio = tau1;
      DetectionStats stats;
      const std::vector<Candidate> out = run(a, p, stats);
      EXPECT_EQ(stats.topology, 1);
      if (tau1 < k.normalised) {
        EXPECT_TRUE(out.empty()) << tau1;
        EXPECT_EQ(stats.area, 0) << tau1;
        continue;
      }
      ASSERT_EQ(out.size(), 1u) << tau1;
      EXPECT_EQ(stats.area, 1);
      double lo = 1e300, hi = 0;
      for (const Blob& b : out[0].blobs) lo = std::min(lo, b.mass), hi = std::max(hi, b.mass);
      EXPECT_DOUBLE_EQ(hi / lo, k.side * k.side / 36.0);  // the raw ink ratio
    }
  }
  // The default, the paper's tau1 of 5 (SPEC 4): the lone 20 x 20 square (4.09) passes,
  // the 24 x 24 (5.57) does not.
  for (const auto& [side, passes] : {std::pair{20, true}, std::pair{24, false}}) {
    std::vector<cv::Rect> all;
    for (int i = 0; i < 8; ++i) all.emplace_back(10 + (i % 4) * 20, 10 + (i / 4) * 20, 6, 6);
    all.emplace_back(60, 60, side, side);
    DetectionStats stats;
    EXPECT_EQ(run(analyse(boxed(100, 3, all)), params_for({Family(3)}), stats).size(), passes ? 1u : 0u) << side;
    EXPECT_EQ(stats.area, passes ? 1 : 0) << side;
  }
  // A real marker (design ratio 16/9) passes, also at a small scale.
  for (double ppu : {1.7, 3.0, 8.0}) {
    const Analysed m = analyse(rasterize_marker(Family(4), 4321, ppu, 2.0));
    DetectionStats stats;
    EXPECT_EQ(run(m, params_for({Family(4)}), stats).size(), 1u) << ppu << " px/u";
    EXPECT_EQ(stats.area, 1) << ppu << " px/u";
  }
}

TEST(FindCandidates, AreaConstraintTakesOutPerspective) {
  // Columns of squares 5, 8 and 12 px wide: the raw ink ratio 144 / 25 = 5.76 is over
  // tau1 = 5, but the cube roots of the inks grow nearly linearly across the grid, as
  // perspective makes them, and the normalised ratio is 1.06. The same squares out of
  // order (5, 12, 8) are no perspective: 3.73.
  auto columns = [](std::array<int, 3> sides) {
    std::vector<cv::Rect> all;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) all.emplace_back(10 + c * 28, 10 + r * 28, sides[c], sides[c]);
    return analyse(boxed(100, 3, all));
  };
  DetectorParams p = params_for({Family(3)});
  DetectionStats stats;
  EXPECT_EQ(run(columns({5, 8, 12}), p, stats).size(), 1u);
  p.max_ink_ratio = 1.1;
  EXPECT_EQ(run(columns({5, 8, 12}), p, stats).size(), 1u);
  p.max_ink_ratio = 3.7;
  EXPECT_TRUE(run(columns({5, 12, 8}), p, stats).empty());
  p.max_ink_ratio = 3.75;
  EXPECT_EQ(run(columns({5, 12, 8}), p, stats).size(), 1u);
}

TEST(FindCandidates, FamiliesShareTheRegionTree) {
  // 16 children: only 4x4 (9 + 3 < 16), unless 7 extra children are allowed, when the 3x3
  // family takes the nine largest of them as well; 12 children: only 3x3.
  std::vector<cv::Rect> sixteen;
  for (int i = 0; i < 16; ++i) sixteen.emplace_back(8 + (i % 4) * 22, 8 + (i / 4) * 22, 10, 10);
  const Analysed a16 = analyse(boxed(100, 3, sixteen));
  DetectionStats s;
  std::vector<Candidate> out = run(a16, params_for({Family(3), Family(4)}), s);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].family, Family(4));
  EXPECT_EQ(out[0].blobs.size(), 16u);
  EXPECT_EQ(s.topology, 1);

  DetectorParams both = params_for({Family(3), Family(4)});
  both.max_extra_children = 7;
  DetectionStats s2;
  out = run(a16, both, s2);
  ASSERT_EQ(out.size(), 2u);
  std::set<int> families = {out[0].family.n(), out[1].family.n()};
  EXPECT_EQ(families, (std::set<int>{3, 4}));
  EXPECT_EQ(s2.topology, 2);
  EXPECT_EQ(s2.area, 2);
  for (const Candidate& c : out) EXPECT_EQ(int(c.blobs.size()), c.family.cell_count());

  const std::vector<cv::Rect> twelve(sixteen.begin(), sixteen.begin() + 12);
  DetectionStats s3;
  out = run(analyse(boxed(100, 3, twelve)), params_for({Family(3), Family(4)}), s3);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].family, Family(3));
}

TEST(FindCandidates, ASquareAcrossAShadowsEdgeIsNotReadByItsBlobs) {
  // A hard shadow's edge (paper 240 | 110) through the middle column of squares, and the
  // local threshold drawing `strip` rows of the shadowed paper below the top one into its
  // black region: against the paper under it the strip weighs nothing, against the one
  // level it weighs as ink. When that choice moves the square's centroid by more than
  // kMaxPaperShift units (a third of its side), the candidate is not read by its blobs.
  const auto shift_and_count = [](int strip) {
    cv::Mat1b grey = boxed(100, 3, grid(12, 28, 12));
    cv::Mat1b black = grey == 0;
    black(cv::Rect(51, 29, 6, strip)).setTo(255);
    for (int y = 0; y < grey.rows; ++y)  // the shadow falls on the paper round the marker too
      for (int x = 0; x < grey.cols; ++x)
        if (grey(y, x) != 0) grey(y, x) = x < 51 ? 240 : 110;
    const Analysed a = analyse(grey, black);
    DetectionStats stats;
    DetectorParams p = params_for({Family(3)});
    p.max_ink_ratio = 100;  // the ink ratio is not what is tested
    const std::vector<Candidate> out = run(a, p, stats);
    // The top middle square's centroid under each paper model.
    const int region = a.at(47, 20);
    std::vector<int> kids;
    for (int i = 0; i < int(a.tree.regions.size()); ++i)
      if (a.tree.regions[i].area >= 100 && a.tree.regions[i].area < 400) kids.push_back(i);
    const int white = a.tree.regions[region].parent;
    const detail::PaperLevel local =
        detail::paper_under(a.tree, white, kids.data(), int(kids.size()), a.view(), a.binary, 1);
    EXPECT_FALSE(local.local.empty());
    const detail::Blob with_local = detail::BlobMeasurer().measure(a.tree, region, a.view(), a.binary, 1, local);
    const detail::Blob flat =
        detail::BlobMeasurer().measure(a.tree, region, a.view(), a.binary, 1, detail::PaperLevel(local.level));
    const double unit = std::sqrt(double(with_local.area)) / 3;
    return std::make_pair(cv::norm(with_local.centroid - flat.centroid) / unit, out.size());
  };
  // Just under the bound: read by its blobs; just over: not.
  const auto [under, read] = shift_and_count(10);
  EXPECT_GT(under, 0.4);
  EXPECT_LT(under, detail::kMaxPaperShift);
  EXPECT_EQ(read, 1u);
  const auto [over, refused] = shift_and_count(12);
  EXPECT_GT(over, detail::kMaxPaperShift);
  EXPECT_LT(over, 0.6);
  EXPECT_EQ(refused, 0u);
}

TEST(PaperUnder, TheLightIsTakenAsEvenBeforeTheClosingOnlyWhereThePurePaperShowsIt) {
  // A 3x3 of 12 px squares on paper at 180 with noise of 3 grey levels: even. Lit in two
  // bands (240 and 180, a shadow's edge: 0.75 of the light) or in a gradient down to
  // 0.85 of the light: not (the closing decides those). Squares of 3 px: too few pixels
  // out of a blur's reach to tell.
  const auto verdict = [](const cv::Mat1b& grey, const cv::Mat1b& black) {
    const Analysed a = analyse(grey, black);
    DetectionStats stats;
    const std::vector<Candidate> out = run(a, params_for({Family(3)}), stats);
    EXPECT_EQ(out.size(), 1u);
    return out.empty() ? std::nullopt : detail::pure_paper_even(a.tree, out[0].white_region, a.binary, a.view());
  };
  cv::Mat1b grey = boxed(100, 3, grid(12, 28, 12));
  const cv::Mat1b black = grey == 0;
  cv::Mat1b noisy = grey.clone(), banded = grey.clone(), graded = grey.clone();
  cv::Mat1f noise(grey.size());
  cv::RNG(7).fill(noise, cv::RNG::NORMAL, 0, 3);
  for (int y = 8; y < 103; ++y)
    for (int x = 8; x < 103; ++x) {
      if (black(y, x)) continue;
      noisy(y, x) = cv::saturate_cast<std::uint8_t>(180 + noise(y, x));
      banded(y, x) = x < 55 ? 240 : 180;
      graded(y, x) = cv::saturate_cast<std::uint8_t>(240 * (1 - 0.15 * (x - 8) / 95.0));
    }
  EXPECT_EQ(verdict(noisy, black), std::optional<bool>(true));
  EXPECT_EQ(verdict(banded, black), std::optional<bool>(false));
  EXPECT_EQ(verdict(graded, black), std::optional<bool>(false));
  const cv::Mat1b small = boxed(22, 1, grid(4, 6, 3));
  EXPECT_EQ(verdict(small, small == 0), std::nullopt);
}
