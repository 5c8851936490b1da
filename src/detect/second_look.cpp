// SPDX-License-Identifier: LGPL-2.1-or-later
// The second look: markers the frame's binary image could not resolve, re-examined in
// their neighbourhood at a higher resolution and with a threshold of their own.
//
// At about half a pixel per unit, the two-unit gaps of a marker are one pixel wide: one
// binarisation at the frame's resolution cannot keep a diagonal black border 4-connected
// and the diagonal white gaps beside it 8-connected, and a 16-pixel mean next to a white
// margin sinks the gaps into the squares. So the squares join the border and the white
// region loses its n^2 children, although the grey levels still hold the marker. Such a
// marker leaves a small, isolated cluster of black regions in the binary image: those
// clusters are enlarged, binarised at the midpoint of their own dark and bright levels
// and handed to the usual stages, with every measurement taken back to the frame.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "stages.hpp"

namespace lftag::detail {
namespace {

// ------------------------------------------------------------------------------ limits
// Every bound that decides whether a cluster of the frame is looked at again, in one
// place. They spend the second look's time and can lose a marker, but they cannot add a
// wrong id: what a second look finds passes the checks the frame's own candidates pass.
// "Markers found" below: the boxes whose second look found a marker in the range, blur
// and video sweeps and the field experiment's tuning set, 3x3 and 4x4 (docs/detector.md,
// Limits, has the validation set's figures beside them).

// A marker's box: longer side over shorter, a square seen at up to about 70 degrees
// (markers found: 2.0 or less).
constexpr double kMaxBoxAspect = 3;
// Ink over the box, about half: markers found 0.351 to 0.713 (0.42 to 0.68 measured
// from 13 px to blurred 70 px markers when it was chosen).
constexpr double kMinClusterFill = 0.35, kMaxClusterFill = 0.8;
// Black regions and their holes in a cluster: one piece or a ring is a blob or a letter
// (markers found: 4 or more); a small marker's broken border with the pieces in its box
// needs one more, its box being the border's own.
constexpr int kMinClusterPieces = 4, kMinBorderPieces = 5;
// Black pixels on the ring just outside the box (or around a border's grown hull) over
// the ring's length: a marker alone on its white margin (markers found: 0.20 or less).
constexpr double kMaxRingInk = 0.25;
// A closed border's largest hole with what it holds, over the border's box: markers found
// 0.200 to 0.693 (a solid blob fills nothing, a frame around a plain hole most).
constexpr double kMinHoleFill = 0.2, kMaxHoleFill = 0.8;
// A closed border holds this many squares (of 2 px or more) in its hole at least, unless
// smeared (a round bound; markers found held 2 to 27).
constexpr int kMinHeldSquares = 2;
// A border whose squares a motion blur smeared into it: its hole spans this share of the
// border's box each way at least (markers found 0.515 or more) and fills at most this
// share of its own box.
constexpr double kMinSmearedHoleSpan = 0.6, kMaxSmearedHoleFill = 0.6;
// ... and lines the border on this share of its rows or columns (see lines_opposite_sides).
constexpr double kMinLinedShare = 0.8;
// Ink on the grown hull of a region whose cluster outgrew a marker, at most: its own margin.
constexpr double kCleanMargin = 0.02;
// Resolved markers of other families (see unsought_marker): squares of at least this many
// pixels; largest over smallest at most 3 for a family larger than every one sought (a
// steep perspective), kMaxSmallerMarkerSpread for a smaller one.
constexpr int kMinSquarePixels = 16;
constexpr double kMaxLargerMarkerSpread = 3;
// The resolved LFTag markers of the speed scenes, 2x2 to 8x8: largest squares (the
// baselines, 16/9 of the others) 1.64 to 2.11 times their smallest.
constexpr double kMaxSmallerMarkerSpread = 2.3;
// A cluster whose binary image fits its grey levels this well is resolved (see
// near_candidates). Measured on the AprilTag, ArUco and LFTag 2x2 markers of the speed
// scenes: 0.23 to 0.51 mid-grey pixels per edge, features 12 px wide or more. On every
// marker of 64 px or more that a second look found in the range, angle, blur, pose and
// video sweeps: 0.83 or more, but for sharp 5x5 to 8x8 markers tilted 60 to 70 degrees
// (0.37 to 0.47), whose features along the tilt are a pixel or two wide (5.1 px or less
// on average) and which the frame's 16 px mean threshold did not resolve.
constexpr double kResolvedMidGreyPerEdge = 0.6;
constexpr double kResolvedFeatureWidth = 8;  // px
// A cluster's ink must stand out of the paper between its pieces (mean grey levels) by
// this many times the frame's noise (SecondLook::noise). The clusters that sensor noise
// makes, its dark tail just past the threshold's offset, stand 1 to 3 noise deviations
// out (1,740 clusters in 10 frames of the field experiment's low-light tuning clips, one
// at 5); every cluster whose second look found a marker in the field experiment (both
// sets) stood 10.5 or more.
constexpr double kMinNoiseContrast = 6;
// A patch pixel is black only where its local darkest and brightest levels differ by this
// many grey levels or more: less is the grain of plain paper or ink, not a printed edge.
constexpr int kMinPatchRange = 24;
// ------------------------------------------------------------------------------

struct Cluster {
  int x0, y0, x1, y1;  // inclusive box
  int ink = 0;         // black pixels of its regions
  int pieces = 0;      // its black regions and their holes
  // One of its regions is a resolved marker of a family not sought (see unsought_marker):
  bool larger_marker = false;   // larger than every one sought
  bool smaller_marker = false;  // smaller than one
  int region = 0;               // its first region
};

int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

// Black pixels on the one-pixel ring just outside box b (clipped to the frame) over
// the ring's length.
double ring_ink(const BinaryImage& binary, const Cluster& b) {
  int black = 0, count = 0;
  auto visit = [&](int x, int y) {
    if (x < 0 || y < 0 || x >= binary.width || y >= binary.height) return;
    ++count;
    black += binary.black(x, y);
  };
  for (int x = b.x0 - 1; x <= b.x1 + 1; ++x) visit(x, b.y0 - 1), visit(x, b.y1 + 1);
  for (int y = b.y0; y <= b.y1; ++y) visit(b.x0 - 1, y), visit(b.x1 + 1, y);
  return count ? double(black) / count : 1.0;
}

// The mean grey level of a box's white pixels less that of its black ones.
double ink_contrast(const BinaryImage& binary, const ImageView& grey, const cv::Rect& box) {
  double dark = 0, light = 0;
  int darks = 0, lights = 0;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const std::uint8_t* g = grey.data + std::ptrdiff_t(y) * grey.stride;
    for (int x = box.x; x < box.x + box.width; ++x)
      if (binary.black(x, y))
        dark += g[x], ++darks;
      else
        light += g[x], ++lights;
  }
  return darks && lights ? light / lights - dark / darks : 0.0;
}

// The convex hull of some regions' pixels (frame pixels): that of the first and last
// pixels of each row (a marker's regions have thousands of runs, and the hull of their
// ends was most of the search's time in frames crowded with markers).
std::vector<cv::Point> region_hull(const RegionTree& tree, const std::vector<int>& regions) {
  if (regions.empty()) return {};
  int y0 = tree.regions[regions[0]].y0, y1 = tree.regions[regions[0]].y1;
  for (const int r : regions) y0 = std::min(y0, tree.regions[r].y0), y1 = std::max(y1, tree.regions[r].y1);
  std::vector<std::pair<int, int>> rows(  // first and last pixel of each row
      y1 - y0 + 1, {std::numeric_limits<int>::max(), std::numeric_limits<int>::min()});
  for (const int r : regions)
    tree.for_each_run(r, [&](int y, int x0, int x1) {
      auto& [first, last] = rows[y - y0];
      first = std::min(first, x0), last = std::max(last, x1 - 1);
    });
  std::vector<cv::Point> ends, hull;
  for (int y = y0; y <= y1; ++y)
    if (const auto [first, last] = rows[y - y0]; first <= last) ends.emplace_back(first, y), ends.emplace_back(last, y);
  cv::convexHull(ends, hull);
  return hull;
}

// Black pixels on the outline of region g's convex hull `hull` moved out by a tenth of its
// size (at least two pixels), over the outline's length: unlike its box's ring, this stays
// on the white margin of a turned sheet.
double hull_ring_ink(const BinaryImage& binary, const Region& g, const std::vector<cv::Point>& hull) {
  const double size = std::max(g.x1 - g.x0, g.y1 - g.y0) + 1;
  const double grow = 1 + std::max(0.2, 4 / size);
  const cv::Point2d centre((g.x0 + g.x1) / 2.0, (g.y0 + g.y1) / 2.0);
  int black = 0, count = 0;
  for (std::size_t i = 0; i < hull.size(); ++i) {
    const cv::Point2d a = centre + (cv::Point2d(hull[i]) - centre) * grow;
    const cv::Point2d b = centre + (cv::Point2d(hull[(i + 1) % hull.size()]) - centre) * grow;
    const int steps = std::max(1, int(std::ceil(cv::norm(b - a))));
    for (int k = 0; k < steps; ++k) {
      const cv::Point q(cvRound(a.x + (b.x - a.x) * k / steps), cvRound(a.y + (b.y - a.y) * k / steps));
      if (q.x < 0 || q.y < 0 || q.x >= binary.width || q.y >= binary.height) continue;
      ++count;
      black += binary.black(q.x, q.y);
    }
  }
  return count ? double(black) / count : 1.0;
}

// Whether white region `hole` runs along two opposite sides of its box: on at least four
// fifths of its rows it reaches both its left and its right edge (within a thirtieth of
// its size), or so on its columns with its top and bottom edge. A marker's white ring
// does that beside a border whose squares a motion blur smeared into it.
bool lines_opposite_sides(const RegionTree& tree, int hole) {
  const Region& g = tree.regions[hole];
  const int w = g.x1 - g.x0 + 1, h = g.y1 - g.y0 + 1;
  const int tol = std::max(1, std::max(w, h) / 30);
  std::vector<int> row_lo(h, g.x1), row_hi(h, g.x0), col_lo(w, g.y1), col_hi(w, g.y0);
  tree.for_each_run(hole, [&](int y, int x0, int x1) {
    row_lo[y - g.y0] = std::min(row_lo[y - g.y0], x0), row_hi[y - g.y0] = std::max(row_hi[y - g.y0], x1 - 1);
    for (int x = x0; x < x1; ++x)
      col_lo[x - g.x0] = std::min(col_lo[x - g.x0], y), col_hi[x - g.x0] = std::max(col_hi[x - g.x0], y);
  });
  int rows = 0, cols = 0;
  for (int y = 0; y < h; ++y) rows += row_lo[y] <= g.x0 + tol && row_hi[y] >= g.x1 - tol;
  for (int x = 0; x < w; ++x) cols += col_lo[x] <= g.y0 + tol && col_hi[x] >= g.y1 - tol;
  return rows >= kMinLinedShare * h || cols >= kMinLinedShare * w;
}

// The largest hole of black region r.
int largest_hole(const RegionTree& tree, int r) {
  int hole = -1;
  for (int i = 0; i < tree.regions[r].child_count; ++i)
    if (hole < 0 || tree.regions[tree.children_of(r)[i]].area > tree.regions[hole].area) hole = tree.children_of(r)[i];
  return hole;
}

// The n of the family not sought whose resolved marker black region r is, or 0: its
// largest hole holds exactly n x n squares, each of kMinSquarePixels or more and of about
// one size.
// - Larger than every family sought: blur only joins a resolved marker's squares, so no
//   second look makes it a marker of a family sought, and it is not looked at. Its
//   squares are within 3 times of each other (the spread of a steep perspective).
// - Smaller than one: the squares of a larger marker joined in pairs and threes could
//   number n x n too. Two joined data squares are at least 22 units to a single one's 9,
//   so the squares must be within kMaxSmallerMarkerSpread; and such a marker is only
//   taken for what it shows when its binary image explains its grey levels (a blur that
//   joins squares leaves mid grey between them; see near_candidates).
// Small markers are another matter: in the range sweep a 3x3 marker of 31 px (1.3 px per
// unit) showed 16 pieces of 2 to 15 pixels in its hole, its squares broken by the mean
// threshold; and a large square hollowed by it breaks into pieces of unequal sizes. The
// other families' markers of the speed scenes (70 px and more) have squares of
// kMinSquarePixels or more (a bound of 25 lets some of them through again).

// `max_n`: the largest n of the families `sought`.
int unsought_marker(const RegionTree& tree, int r, const std::bitset<Family::kMaxN + 1>& sought, int max_n) {
  const int hole = largest_hole(tree, r);
  if (hole < 0) return 0;
  const Region& white = tree.regions[hole];
  const int n = int(std::lround(std::sqrt(double(white.child_count))));
  if (n < 2 || n > Family::kMaxN || n * n != white.child_count || sought[n]) return 0;
  int smallest = white.area, largest = 0;
  for (int i = 0; i < white.child_count; ++i) {
    const int area = tree.regions[tree.children_of(hole)[i]].area;
    smallest = std::min(smallest, area), largest = std::max(largest, area);
  }
  const double spread = n > max_n ? kMaxLargerMarkerSpread : kMaxSmallerMarkerSpread;
  return smallest >= kMinSquarePixels && largest <= spread * smallest ? n : 0;
}

// How well a cluster's binary image accounts for its grey levels, within the convex hull
// of its regions (`hull`, frame pixels, within `box`). An edge is a pixel and its right or lower neighbour of the other
// colour.
struct BinaryFit {
  // Mid-grey pixels (more than a quarter of the way from the hull's darkest levels to its
  // brightest and back, a fiftieth of the pixels left out at each end for noise) per
  // edge. A sharp resolved marker has its few mid-grey pixels on its edges; blur widens
  // the edges, and gaps the threshold closed are mid grey away from any edge.
  double mid_grey_per_edge = 0;
  // Twice the hull's pixels over its edges: the width of the stripes that would have as
  // many edges (px).
  double feature_width = 0;
};

BinaryFit binary_fit(const BinaryImage& binary, const ImageView& grey, std::vector<cv::Point> hull,
                     const cv::Rect& box) {
  for (cv::Point& p : hull) p -= box.tl();
  cv::Mat1b inside(box.size(), std::uint8_t(0));
  cv::fillConvexPoly(inside, hull, 255);
  // The hull's span on each row, in frame pixels: [first, last], empty when last < first.
  std::vector<std::pair<int, int>> spans(box.height, {0, -1});
  for (int y = 0; y < box.height; ++y) {
    const std::uint8_t* m = inside.ptr<std::uint8_t>(y);
    int first = 0, last = box.width - 1;
    while (first < box.width && !m[first]) ++first;
    while (last >= first && !m[last]) --last;
    spans[y] = {box.x + first, box.x + last};
  }
  std::array<int, 256> histogram{};
  int pixels = 0;
  for (int y = 0; y < box.height; ++y) {
    const std::uint8_t* g = grey.data + (box.y + y) * grey.stride;
    for (int x = spans[y].first; x <= spans[y].second; ++x) ++histogram[g[x]];
    pixels += std::max(0, spans[y].second - spans[y].first + 1);
  }
  const int tail = pixels / 50;
  int dark = 0, bright = 255;
  for (int sum = 0; dark < 255 && sum + histogram[dark] <= tail; ++dark) sum += histogram[dark];
  for (int sum = 0; bright > 0 && sum + histogram[bright] <= tail; --bright) sum += histogram[bright];
  const double lo = dark + 0.25 * (bright - dark), hi = bright - 0.25 * (bright - dark);
  int mid = 0, edges = 0;
  for (int v = 0; v < 256; ++v) mid += v > lo && v < hi ? histogram[v] : 0;
  for (int y = 0; y < box.height; ++y) {
    const int fy = box.y + y;
    const auto [first, last] = spans[y];
    // Edges 64 pixels at a time: the row against itself moved by one pixel, and against
    // the row below.
    for (int x = first; x <= last; x += 64) {
      const int n = std::min(64, last - x + 1);
      const std::uint64_t span = n == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << n) - 1;
      const std::uint64_t here = binary.bits_at(x, fy);
      if (x + 1 < binary.width) {
        const int pairs = std::min(n, binary.width - 1 - x);  // with a right neighbour in the frame
        const std::uint64_t within = pairs == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << pairs) - 1;
        edges += __builtin_popcountll((here ^ binary.bits_at(x + 1, fy)) & within);
      }
      if (fy + 1 < binary.height) edges += __builtin_popcountll((here ^ binary.bits_at(x, fy + 1)) & span);
    }
  }
  return {double(mid) / std::max(1, edges), 2.0 * pixels / std::max(1, edges)};
}

}  // namespace

std::vector<cv::Rect> near_candidates(const RegionTree& tree, const BinaryImage& binary, const ImageView& grey,
                                      const SecondLook& look, const std::vector<cv::Rect>& taken) {
  const int max_n = look.max_n();
  // Small black regions, clustered when their boxes touch or overlap (a far marker's
  // border breaks into pieces on the diagonals). Each starts as a cluster of its own. The
  // tree numbers regions in the raster order of their first pixels, so their tops never
  // decrease and a region meets only those that start before its bottom.
  std::vector<Cluster> small;
  for (int r = 1; r < int(tree.regions.size()); ++r) {
    const Region& g = tree.regions[r];
    if (!g.black || g.area < 2) continue;
    if (g.x1 - g.x0 + 1 > look.max_size || g.y1 - g.y0 + 1 > look.max_size) continue;
    const int unsought = unsought_marker(tree, r, look.sought, max_n);
    small.push_back(
        {g.x0, g.y0, g.x1, g.y1, g.area, 1 + g.child_count, unsought > max_n, unsought != 0 && unsought < max_n, r});
  }
  std::vector<int> parent(small.size());
  std::iota(parent.begin(), parent.end(), 0);
  // Regions meet only regions of the same 64-pixel column strip: each strip lists the
  // regions that reach into it, still top to bottom.
  constexpr int kStrip = 64;
  std::vector<std::vector<int>> strips((binary.width + kStrip) / kStrip + 1);
  for (int i = 0; i < int(small.size()); ++i)
    for (int t = std::max(0, small[i].x0 - 1) / kStrip; t <= (small[i].x1 + 1) / kStrip; ++t)
      strips[std::min(t, int(strips.size()) - 1)].push_back(i);
  for (const std::vector<int>& strip : strips)
    for (std::size_t i = 0; i < strip.size(); ++i) {
      const Cluster& a = small[strip[i]];
      for (std::size_t j = i + 1; j < strip.size() && small[strip[j]].y0 <= a.y1 + 1; ++j) {
        const Cluster& b = small[strip[j]];
        if (b.x0 > a.x1 + 1 || a.x0 > b.x1 + 1) continue;
        parent[find_root(parent, strip[j])] = find_root(parent, strip[i]);
      }
    }
  // Each cluster's box, ink, pieces and flags, by its root. A region alone is its own
  // cluster (most of a noisy frame's regions are), so only clusters of two regions or
  // more are gathered apart: a frame of specks needs no second copy of `small`.
  std::vector<int> gathered(small.size(), -1);  // by root: into `joined`; -1 for a region alone
  std::vector<Cluster> joined;
  for (std::size_t i = 0; i < small.size(); ++i) {
    const int root = find_root(parent, int(i));
    if (root == int(i)) continue;
    if (gathered[root] < 0) {
      gathered[root] = int(joined.size());
      joined.push_back(small[root]);
    }
    const Cluster& g = small[i];
    Cluster& c = joined[gathered[root]];
    c.x0 = std::min(c.x0, g.x0), c.y0 = std::min(c.y0, g.y0);
    c.x1 = std::max(c.x1, g.x1), c.y1 = std::max(c.y1, g.y1);
    c.ink += g.ink;
    c.pieces += g.pieces;
    c.larger_marker = c.larger_marker || g.larger_marker;
    c.smaller_marker = c.smaller_marker || g.smaller_marker;
  }
  const auto cluster_of = [&](int root) -> const Cluster& {
    return gathered[root] < 0 ? small[root] : joined[gathered[root]];
  };
  // The regions of each cluster, by root (a counting sort of `small` by root): made the
  // first time a hull is needed.
  std::vector<int> member_start, members;
  const auto members_of = [&](int root) {
    if (member_start.empty()) {
      member_start.assign(small.size() + 1, 0);
      for (std::size_t k = 0; k < small.size(); ++k) ++member_start[find_root(parent, int(k)) + 1];
      for (std::size_t k = 0; k < small.size(); ++k) member_start[k + 1] += member_start[k];
      members.resize(small.size());
      std::vector<int> next(member_start.begin(), member_start.end() - 1);
      for (std::size_t k = 0; k < small.size(); ++k) members[next[find_root(parent, int(k))]++] = small[k].region;
    }
    return std::vector<int>(members.begin() + member_start[root], members.begin() + member_start[root + 1]);
  };

  std::vector<std::pair<double, cv::Rect>> found;  // ring ink, box
  // A marker's size, a square seen at up to about 70 degrees.
  const auto marker_sized = [&](int w, int h) {
    return std::max(w, h) >= look.min_size && std::max(w, h) <= look.max_size &&
           std::max(w, h) <= kMaxBoxAspect * std::min(w, h);
  };
  // About half ink (0.42 to 0.68 measured from 13 px to blurred 70 px markers) and broken
  // into pieces or holed by its gaps: one piece or a ring is a blob or a letter.
  const auto marker_like = [](int ink, int pieces, int w, int h, int min_pieces) {
    const double fill = double(ink) / (w * h);
    return fill >= kMinClusterFill && fill <= kMaxClusterFill && pieces >= min_pieces;
  };
  // A cluster of 64 px or more is looked at again in the frame's own pixels: when its
  // binary image already explains its grey levels and its features are several pixels
  // wide, or it shows the squares of a smaller family's marker not sought, it is resolved
  // (a marker of another kind, or none), and a second look would see it the same way.
  // Frames crowded with other markers spent most of their time on those.
  const auto resolved = [&](const cv::Rect& box, const auto& hull, bool smaller_marker) {
    if (std::max(box.width, box.height) < look.enlarge_below) return false;
    const BinaryFit fit = binary_fit(binary, grey, hull(), box);
    return fit.mid_grey_per_edge < kResolvedMidGreyPerEdge &&
           (fit.feature_width >= kResolvedFeatureWidth || smaller_marker);
  };
  const auto overlaps_any = [](const cv::Rect& box, const std::vector<cv::Rect>& boxes) {
    return std::any_of(boxes.begin(), boxes.end(), [&](const cv::Rect& t) { return (t & box).area() > 0; });
  };
  for (std::size_t i = 0; i < small.size(); ++i) {
    if (find_root(parent, int(i)) != int(i)) continue;
    const Cluster& c = cluster_of(int(i));
    const int w = c.x1 - c.x0 + 1, h = c.y1 - c.y0 + 1;
    // A marker's size, like a marker in ink and in pieces (4 at least; the markers measured
    // had 5 or more), and alone
    // on its white margin. Of the clusters in photos, about 2 in 1,000 pass.
    if (!marker_sized(w, h)) continue;
    if (!marker_like(c.ink, c.pieces, w, h, kMinClusterPieces) || c.larger_marker) continue;
    const double ring = ring_ink(binary, c);
    if (ring > kMaxRingInk) continue;
    const cv::Rect box(c.x0, c.y0, w, h);
    const auto hull = [&] { return region_hull(tree, members_of(int(i))); };
    if (!overlaps_any(box, taken) && !resolved(box, hull, c.smaller_marker)) found.emplace_back(ring, box);
  }
  // A marker's border closed around a white hole that holds some of its squares, the
  // others joined to the border: its cluster can take in the background's dark specks
  // beside the sheet (the box of a turned sheet reaches past its margin), so the border
  // is also looked at alone.
  for (int r = 1; r < int(tree.regions.size()); ++r) {
    const Region& g = tree.regions[r];
    if (!g.black || g.child_count == 0) continue;
    const int w = g.x1 - g.x0 + 1, h = g.y1 - g.y0 + 1;
    if (!marker_sized(w, h)) continue;
    const int unsought = unsought_marker(tree, r, look.sought, max_n);
    if (unsought > max_n) continue;
    // Its largest hole with what the hole holds: the marker inside its border.
    const int hole = largest_hole(tree, r);
    const Region& white = tree.regions[hole];
    int inside = white.area, squares = 0;
    for (int i = 0; i < white.child_count; ++i) {
      const Region& k = tree.regions[tree.children_of(hole)[i]];
      inside += k.area;
      squares += k.area >= 2;
    }
    const double hole_fill = double(inside) / (w * h);
    if (hole_fill < kMinHoleFill || hole_fill > kMaxHoleFill) continue;
    // The hole holds two squares or more; or, under a long motion blur that smeared
    // every column of squares into the border, nothing: then the hole is the gaps,
    // spanning most of the border's box but filling little of its own (a frame around a
    // plain hole fills it), and the white ring's two sides along the blur still line
    // the border.
    const int hw = white.x1 - white.x0 + 1, hh = white.y1 - white.y0 + 1;
    const bool smeared = squares == 0 && white.child_count == 0 && hw >= kMinSmearedHoleSpan * w &&
                         hh >= kMinSmearedHoleSpan * h && white.area <= kMaxSmearedHoleFill * hw * hh &&
                         lines_opposite_sides(tree, hole);
    if (squares < kMinHeldSquares && !smeared) continue;
    const cv::Rect box(g.x0, g.y0, w, h);
    if (overlaps_any(box, taken) ||
        std::any_of(found.begin(), found.end(), [&](const auto& f) { return (f.second & box).area() > 0; }))
      continue;
    const std::vector<cv::Point> hull = region_hull(tree, {r});
    const double ring = hull_ring_ink(binary, g, hull);
    if (ring <= kMaxRingInk && !resolved(
                                   box, [&] { return hull; }, unsought != 0))
      found.emplace_back(ring, box);
  }
  // A small marker whose border the threshold broke open (defocus and a steep tilt at
  // about a pixel per unit) has no hole, and its cluster takes in the background's specks
  // around the sheet until it outgrows a marker. So a black region of a small marker's
  // size (under look.enlarge_below) in a larger cluster is also looked at with the pieces
  // inside its box, when those look like a marker as a cluster does above (at least five
  // pieces) and its own hull stands on a clean margin: the grown hull meets almost no ink.
  // Larger markers keep their borders closed; resolved markers of other families in
  // crowded frames are larger and would be read again for nothing.
  for (std::size_t i = 0; i < small.size(); ++i) {
    const Cluster& seed = small[i];
    const int w = seed.x1 - seed.x0 + 1, h = seed.y1 - seed.y0 + 1;
    if (!marker_sized(w, h) || std::max(w, h) >= look.enlarge_below || seed.larger_marker) continue;
    const Cluster& whole = cluster_of(find_root(parent, int(i)));
    if (whole.x0 == seed.x0 && whole.y0 == seed.y0 && whole.x1 == seed.x1 && whole.y1 == seed.y1) continue;
    const cv::Rect box(seed.x0, seed.y0, w, h);
    if (overlaps_any(box, taken) ||
        std::any_of(found.begin(), found.end(), [&](const auto& f) { return (f.second & box).area() > 0; }))
      continue;
    // `small` is in the raster order of the regions' first pixels: their tops never decrease.
    int ink = 0, pieces = 0;
    auto k = std::lower_bound(small.begin(), small.end(), seed.y0, [](const Cluster& c, int y) { return c.y0 < y; });
    for (; k != small.end() && k->y0 <= seed.y1; ++k)
      if (k->x0 >= seed.x0 && k->x1 <= seed.x1 && k->y1 <= seed.y1) ink += k->ink, pieces += k->pieces;
    if (!marker_like(ink, pieces, w, h, kMinBorderPieces)) continue;
    const double ring = hull_ring_ink(binary, tree.regions[seed.region], region_hull(tree, {seed.region}));
    if (ring <= kCleanMargin) found.emplace_back(ring, box);
  }
  // Sensor noise: in a dim frame the threshold's offset is within the noise, and flat
  // paper breaks into specks whose clusters pass every test above.
  if (look.noise > 0) {
    const double least = kMinNoiseContrast * look.noise;
    const auto specks = [&](const auto& f) { return ink_contrast(binary, grey, f.second) < least; };
    found.erase(std::remove_if(found.begin(), found.end(), specks), found.end());
  }
  // The most isolated first: a printed marker sits on its white margin.
  std::stable_sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<cv::Rect> out;
  for (const auto& f : found) out.push_back(f.second);
  return out;
}

bool enlarge_patch(const ImageView& image, cv::Rect box, const SecondLook& look, Patch& patch) {
  // Paper all round the cluster, so that the patch's bright level is the margin's.
  const int side = std::max(box.width, box.height);
  const int grow = std::max(2, side / 4);
  const cv::Rect area = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) &
                        cv::Rect(0, 0, image.width, image.height);
  if (area.empty()) return false;
  const cv::Mat native = image.mat()(area);
  // Small clusters are enlarged, so that one-pixel gaps become two pixels wide, and
  // sharpened (unsharp mask of half a frame pixel), which the interpolation softened.
  const int scale = side < look.enlarge_below ? 2 : 1;
  patch.frame.origin = area.tl();
  patch.frame.scale = scale;
  // The patch's images are views of buffers kept from patch to patch.
  const cv::Size size(area.width * scale, area.height * scale);
  const auto view = [&](cv::Mat& buffer) {
    if (buffer.cols < size.width || buffer.rows < size.height)
      buffer.create(std::max(size.height, buffer.rows), std::max(size.width, buffer.cols), CV_8UC1);
    return buffer(cv::Rect(cv::Point(), size));
  };
  patch.grey = view(patch.grey_buffer);
  if (scale > 1) {
    cv::Mat enlarged = view(patch.enlarged_buffer), blurred = view(patch.blurred_buffer);
    cv::resize(native, enlarged, size, 0, 0, cv::INTER_CUBIC);
    // Isolated: the view's buffer holds older patches beyond its edges.
    cv::GaussianBlur(enlarged, blurred, cv::Size(0, 0), 0.5 * scale, 0, cv::BORDER_REPLICATE | cv::BORDER_ISOLATED);
    cv::addWeighted(enlarged, 2.0, blurred, -1.0, 0, patch.grey);
  } else {
    native.copyTo(patch.grey);
  }
  // The darkest and brightest levels within about a third of the cluster (a marker cell
  // or more), so that every square sees the paper of the gaps beside it: the extremes of
  // tiles of a ninth of the cluster, then of each tile's 3 x 3 neighbourhood (the tiles
  // keep this linear in the patch's pixels, where a sliding window was not).
  const int window = std::max(9, side * scale / 3) | 1;
  const int tile = std::max(2, window / 3);
  const int tw = (patch.grey.cols + tile - 1) / tile, th = (patch.grey.rows + tile - 1) / tile;
  cv::Mat1b lo(th, tw), hi(th, tw);
  const int cols = patch.grey.cols;
  std::vector<std::uint8_t> least(static_cast<std::size_t>(cols)), most(least.size());
  for (int band = 0; band < th; ++band) {
    // Down each column of the band's rows first (whole rows at a time, the compiler's
    // vectors), then along each tile's stretch of that.
    const int top = band * tile, bottom = std::min(patch.grey.rows, top + tile);
    const std::uint8_t* g = patch.grey.ptr<std::uint8_t>(top);
    std::copy(g, g + cols, least.begin());
    std::copy(g, g + cols, most.begin());
    for (int y = top + 1; y < bottom; ++y) {
      g = patch.grey.ptr<std::uint8_t>(y);
      for (int x = 0; x < cols; ++x) least[std::size_t(x)] = std::min(least[std::size_t(x)], g[x]);
      for (int x = 0; x < cols; ++x) most[std::size_t(x)] = std::max(most[std::size_t(x)], g[x]);
    }
    std::uint8_t* l = lo.ptr<std::uint8_t>(band);
    std::uint8_t* h = hi.ptr<std::uint8_t>(band);
    for (int t = 0; t < tw; ++t) {
      const auto begin = std::size_t(t * tile), end = std::size_t(std::min(cols, (t + 1) * tile));
      l[t] = *std::min_element(least.begin() + begin, least.begin() + end);
      h[t] = *std::max_element(most.begin() + begin, most.begin() + end);
    }
  }
  cv::erode(lo, lo, cv::Mat());  // 3 x 3
  cv::dilate(hi, hi, cv::Mat());
  cv::resize(lo, patch.dark, cv::Size(tw * tile, th * tile), 0, 0, cv::INTER_NEAREST);
  cv::resize(hi, patch.bright, cv::Size(tw * tile, th * tile), 0, 0, cv::INTER_NEAREST);
  return true;
}

namespace {

// The lowest bits of 64 bytes of 0 or 1, the first byte's the word's lowest bit: eight
// bytes at a time, each multiplied into its place among the top eight bits (no two
// products share a bit, so nothing carries).
std::uint64_t pack_flags(const std::array<std::uint8_t, 64>& flags) {
  std::uint64_t word = 0;
  for (int i = 0; i < 64; i += 8) {
    std::uint64_t eight = 0;
    for (int k = 0; k < 8; ++k) eight |= std::uint64_t{flags[std::size_t(i + k)]} << (8 * k);
    word |= ((eight * 0x0102040810204080u) >> 56) << i;
  }
  return word;
}

}  // namespace

void binarise_patch(const Patch& patch, BinaryImage& binary) {
  const cv::Mat& grey = patch.grey;
  binary.width = grey.cols, binary.height = grey.rows, binary.words_per_row = (grey.cols + 63) / 64;
  binary.bits.assign(std::size_t(binary.words_per_row) * grey.rows, 0);
  std::array<std::uint8_t, 64> black{};
  for (int y = 0; y < grey.rows; ++y) {
    const std::uint8_t* g = grey.ptr<std::uint8_t>(y);
    const std::uint8_t* l = patch.dark.ptr<std::uint8_t>(y);
    const std::uint8_t* h = patch.bright.ptr<std::uint8_t>(y);
    std::uint64_t* bits = binary.bits.data() + std::size_t(y) * binary.words_per_row;
    for (int x0 = 0; x0 < grey.cols; x0 += 64) {
      // 64 pixels flagged without a branch (the compiler's vectors), then packed.
      const int n = std::min(64, grey.cols - x0);
      for (int i = 0; i < n; ++i) {
        const int dark = l[x0 + i], bright = h[x0 + i];
        black[std::size_t(i)] = (bright - dark >= kMinPatchRange) & (2 * g[x0 + i] < dark + bright);
      }
      std::fill(black.begin() + n, black.end(), 0);
      bits[x0 / 64] = pack_flags(black);
    }
  }
}

}  // namespace lftag::detail
