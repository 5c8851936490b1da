// SPDX-License-Identifier: LGPL-2.1-or-later
// A tracked marker measured where its track predicts it (FrameHints::expected), without
// binarising, labelling or measuring blobs: its id is known, so each square's window is
// known too once the outline is. Its squares' ink centroids are taken from the grey
// levels under the predicted outline (cell_centroids.cpp), the outline is refitted to
// them until it settles, and the centroids are then decoded as the expected id's reading
// (decode_expected: the resolution, cell residual, ink spread, decoding error and noise
// margin bounds of every candidate's reading apply, and each digit must read as expected).
// A search's candidate is decoded under 16 hypotheses of which squares are its key
// points; here the windows say which square each centroid is, and that one reading is
// judged. A different marker under the windows would have to place every square within
// the noise margin of the expected id's positions to pass.
//
// A window centred where the track puts a square finds some centroid there whatever the
// window holds (on bare paper, the window's centre: a perfect grid), so it is the
// decoding's checks that say whether the marker is there: its decoding error weighs the
// residuals against the gradient along the border's inner edge, which bare paper lacks.
// A marker gone, covered, blurred past its squares, or further from where its track
// puts it than the windows reach is left to the patch's search.
#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {
namespace {

// The windows' growth round each square, units: a unit to find the squares from where
// the track puts them, then the half unit of the pose's centroids (cell_centroids.cpp).
constexpr double kCoarseGrow = 1, kFineGrow = 0.5;
constexpr double kRing = 0.5;  // the paper's ring round each window, units (as the pose's)
// Refits of the outline to the centroids, at most kMaxRefits for each growth: until no
// square moves by more than kCoarseSettled units, then by more than kSettled pixels. A
// motion blur longer than a window's margin is clipped by it, so each refit moves the
// squares only part of the way: 2 to 3 units of smear settle in four to six refits
// (test_tracked). Three refits left a quarter of the field clips' motion-blurred 4x4s
// (both sets) to the patch's search or an outline reading, at several times the cost.
// A prediction that takes longer is too far off for the windows; the patch's search
// finds it.
constexpr int kMaxRefits = 6;
constexpr double kCoarseSettled = 0.2, kSettled = 0.05;
// The wide windows only bring the squares within the narrow ones' reach: from this many
// pixels per unit they take every other row and column (still a sample a unit each way),
// a quarter of the pixels; the narrow windows, whose centroids the pose uses, take all.
constexpr double kCoarseStridePixels = 2;
}  // namespace

std::optional<TrackedMeasurement> measure_tracked(const ImageView& image, const Camera& camera,
                                                  const DetectorParams& params, const Family& family, TagId id,
                                                  const std::array<cv::Point2d, 4>& outline, DetectionStats& stats) {
  const int cells = family.cell_count();
  std::vector<cv::Point2d> design;  // the squares' centres for this id, units
  for (int g = 0; g < cells; ++g)
    design.push_back(family.center(g, family.is_baseline(g) ? 0 : id.digit(family.data_index(g))));
  const std::array<cv::Point2d, 4> corners = family.outer_corners();
  std::optional<cv::Matx33d> h =
      fit_homography({corners.begin(), corners.end()}, camera.undistort({outline.begin(), outline.end()}));
  if (!h) return std::nullopt;

  const double unit = smallest_scale(*h, {family.side() / 2.0, family.side() / 2.0});  // pixels
  // First with windows a unit wider than the squares each way, so that a square up to a
  // unit from where the track puts it still lies wholly in its window (and no neighbour
  // does: the gaps are 2 units), then with the half unit that the pose's centroids use,
  // until the squares stay where they are.
  std::vector<cv::Point2d> centroids, points;
  std::vector<CellInk> inks;
  const int coarse_stride = unit >= kCoarseStridePixels ? 2 : 1;
  for (const auto& [grow, settled, stride] :
       {std::tuple(kCoarseGrow, kCoarseSettled * unit, coarse_stride), std::tuple(kFineGrow, kSettled, 1)})
    for (int refit = 0;; ++refit) {
      centroids = cell_centroids(image, camera, family, id, *h, PaperLevel(), &inks, grow, kRing, stride);
      if (centroids.empty()) return std::nullopt;
      const std::vector<cv::Point2d> before = std::exchange(points, camera.undistort(centroids));
      double moved = before.empty() ? HUGE_VAL : 0;
      for (std::size_t g = 0; g < before.size(); ++g) moved = std::max(moved, cv::norm(points[g] - before[g]));
      h = fit_homography(design, points);
      if (!h) return std::nullopt;
      if (moved < settled) break;
      if (refit + 1 == kMaxRefits) return std::nullopt;
    }

  // Light that varies across the marker (a shadow's edge) needs the search's paper level
  // under each pixel (paper_under), which this measurement does not have: the squares'
  // papers must be as even as the search's even light (kEvenPaperShare).
  const auto [dimmest, brightest] = std::minmax_element(
      inks.begin(), inks.end(), [](const CellInk& a, const CellInk& b) { return a.paper < b.paper; });
  if (!(dimmest->paper >= kEvenPaperShare * brightest->paper)) return std::nullopt;

  TrackedMeasurement out;
  Candidate& c = out.candidate;
  c.family = family;
  const double s = family.side();
  const std::array<cv::Point2d, 4> interior = {apply(*h, {2, 2}), apply(*h, {s - 2, 2}), apply(*h, {s - 2, s - 2}),
                                               apply(*h, {2, s - 2})};  // the white inside the border
  c.white_area = std::abs(quad_area(interior));
  for (int g = 0; g < cells; ++g) {
    Blob b;
    b.centroid = centroids[g], b.point = points[g], b.mass = inks[g].mass;
    c.blobs.push_back(b);
  }
  const std::array<int, 4> keypoint_cells = family.keypoint_cells();
  for (int i = 0; i < 4; ++i) out.keypoints.blob[i] = keypoint_cells[i];

  // Its one reading first (the squares' order is known); the key points' 16 hypotheses
  // only where that fails, for the bowed grid a bent sheet is read again on.
  std::optional<Decoding> d = decode_expected(c, id, image, camera, params, stats);
  if (!d) d = decode(c, out.keypoints, image, camera, params, stats, nullptr);
  if (!d || d->verdict != Verdict::accepted || !(d->ink_spread <= params.max_ink_spread) || d->id != id)
    return std::nullopt;
  out.decoding = std::move(*d);
  out.edges = border_edges(image, camera, family, out.decoding.homography, params.tag_size);
  return out;
}

}  // namespace lftag::detail
