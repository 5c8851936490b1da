// SPDX-License-Identifier: LGPL-2.1-or-later
// The detector's stages as plain functions over plain data, in pipeline order
// (paper section IV). Private to the library.
//
// The paper's symbols and where they live:
//
//   paper                     parameter (DetectorParams)        function (file)
//   M, mean threshold         threshold_window (+ _offset)      threshold_mean (threshold.cpp)
//   topological CCA           -                                 RegionLabeller::label (regions.cpp)
//   n^2 children, noise       min_child_fraction,               find_candidates (candidates.cpp)
//                             max_child_ratio, max_extra_children
//   delta, vertex estimation  dilation, centroid_reference      BlobMeasurer (candidates.cpp)
//   tau1, area constraint     max_ink_ratio                     perspective_free_ink_ratio (candidates.cpp)
//   K0, K1 (baseline), K2, K3 -                                 hull_corners, find_keypoints (keypoints.cpp)
//   geometry, angle           -                                 find_keypoints (keypoints.cpp)
//   tau2, collinearity        min_spread_ratio (scale-free)     spread_ratio (keypoints.cpp)
//   16 hypotheses, gradient   -                                 decode, edge_gradient (decode.cpp)
//   tau3, decoding error      max_decode_error,                 decode (decode.cpp)
//                             max_cell_residual, min_decode_margin, max_ink_spread
//   final pose (IPPE)         refine_pose, tag_size, camera     cell_centroids (cell_centroids.cpp),
//                                                               border_edges (border_edges.cpp),
//                                                               estimate_pose (pose.cpp)
//   (not in the paper)        second_look, max_second_looks     near_candidates, enlarge_patch,
//                                                               binarise_patch (second_look.cpp)
//   (not in the paper)        second_look, min_pixels_per_unit  coarse_outlines, read_outline,
//                                                               acceptable (outline.cpp)
//   (not in the paper)        max_candidates (the budget)       find_candidates (candidates.cpp)
//   (not in the paper)        FrameHints (a track's outline)    measure_tracked (tracked.cpp)
#pragma once

#include <algorithm>
#include <array>
#include <bitset>
#include <chrono>
#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/detector.hpp"
#include "lftag/trace.hpp"

namespace lftag::detail {

// When a frame's remaining work is to be skipped (DetectorParams::deadline_ms): `ms` of the
// calling thread's processor time after `start` (thread_time()); never when
// default-constructed.
class Deadline {
 public:
  Deadline() = default;
  Deadline(double start_ms, double ms) : set_(ms > 0), at_ms_(start_ms + ms) {}
  bool passed() const { return set_ && thread_time() >= at_ms_; }
  // The processor time the calling thread has used, in milliseconds: the work a frame
  // has cost, whatever else the machine runs.
  static double thread_time();

 private:
  bool set_ = false;
  double at_ms_ = 0;
};

// ---------------------------------------------------------------- threshold.cpp
// A buffer kept from frame to frame, made ready for `need` elements; released first when
// it holds over four times that and a megabyte more, so that one hostile frame leaves no
// gigabytes behind, and second looks' patches of all sizes still reuse theirs.
template <class T>
void reserve_for_frame(std::vector<T>& v, std::size_t need) {
  if (v.capacity() > 4 * need + (std::size_t{1} << 20) / sizeof(T)) std::vector<T>().swap(v);
  v.reserve(need);
}

// One bit per pixel, set for black, rows padded to whole 64-bit words (padding is white).
struct BinaryImage {
  int width = 0, height = 0, words_per_row = 0;
  std::vector<std::uint64_t> bits;
  const std::uint64_t* row(int y) const { return bits.data() + std::size_t(y) * words_per_row; }
  bool black(int x, int y) const { return (row(y)[x >> 6] >> (x & 63)) & 1; }
  // Pixels x to x + 63 of row y, one to a bit (0 beyond the row's end).
  std::uint64_t bits_at(int x, int y) const {
    const std::uint64_t* r = row(y);
    const int word = x >> 6, shift = x & 63;
    const std::uint64_t low = word < words_per_row ? r[word] >> shift : 0;
    const std::uint64_t high = shift && word + 1 < words_per_row ? r[word + 1] << (64 - shift) : 0;
    return low | high;
  }
  cv::Mat1b to_mat() const;  // 255 black, 0 white (for debug images)
};

// Black where a pixel is darker than the mean of the M x M window around it by more than
// `offset`. `mean` is scratch space kept between frames.
void threshold_mean(const ImageView& image, int window, int offset, cv::Mat& mean, BinaryImage& out);

// The standard deviation of the image's pixel noise in grey levels, from the median
// response of a mask that cancels planes (the product of two second differences,
// Immerkaer 1996) over every `row_step`-th row: a texture shows in a minority of pixels,
// noise in all (a frame of dense texture reads as noisy).
double estimate_noise(const ImageView& image, int row_step = 16);

// ---------------------------------------------------------------- regions.cpp
// Set bits of x, inline: the build targets x86-64 without POPCNT, where the builtin is a
// library call that took a fifth of a clean frame's labelling.
inline int count_bits(std::uint64_t x) {
  x -= (x >> 1) & 0x5555555555555555u;
  x = (x & 0x3333333333333333u) + ((x >> 2) & 0x3333333333333333u);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fu;
  return int((x * 0x0101010101010101u) >> 56);
}

// 28 bytes: a 1-px checkerboard has a region for every other pixel.
struct Region {
  int parent = -1;  // enclosing region (-1 for the frame)
  int area = 0;
  int x0 = 0, y0 = 0, x1 = 0;  // bounding box, inclusive, with y1
  int y1 : 31;                 // beside `black` (a frame has under 2^30 rows: RegionLabeller)
  bool black : 1;
  int child_count = 0;  // RegionTree::children_of
  Region() : y1(0), black(false) {}
};

// The containment tree of the binary image. Black regions are 4-connected and white
// regions 8-connected, so every boundary separates exactly one region from its parent.
// The image is framed by white: region 0 is the white frame, holding every white pixel
// connected to the image border.
//
// Its runs (horizontal runs of one colour, row by row, left to right) keep only their
// regions: a run starts where `starts` has a bit and ends where the next one starts or at
// the row's end. A 1-px checkerboard, the worst case (regions.cpp), takes 20.5 bytes a
// pixel in all (bytes_reserved), sensor noise 6, a photo under 1.
struct RegionTree {
  std::vector<Region> regions;
  std::vector<int> children;  // region by region, each region's in raster order
  int width = 0, words_per_row = 0;
  std::vector<std::uint64_t> starts;  // bit x of row y (words_per_row words a row): a run starts at x
  std::vector<int> runs_before;       // for each word of `starts`, the runs that start before it
  std::vector<int> runs;              // the region of each run
  std::vector<int> child_base;        // first_child(8k) for each k
  static constexpr int kFrame = 0;

  // The children of r, children_of(r)[0 .. child_count - 1], come after those of the
  // regions before it: counted from the last multiple of 8.
  int first_child(int r) const {
    int first = child_base[r >> 3];
    for (int q = r & ~7; q < r; ++q) first += regions[q].child_count;
    return first;
  }
  const int* children_of(int r) const { return children.data() + first_child(r); }

  std::size_t bytes_reserved() const;

  // Calls f(y, x0, x1) for every run of region r (pixels x0 .. x1 - 1 of row y), top to
  // bottom, left to right: the runs that start inside its box and carry its number.
  template <class F>
  void for_each_run(int r, F&& f) const {
    const Region& reg = regions[r];
    const int last = reg.x1 >> 6;
    for (int y = reg.y0; y <= reg.y1; ++y) {
      const std::size_t row = std::size_t(y) * words_per_row;
      for (int i = reg.x0 >> 6; i <= last; ++i) {
        std::uint64_t s = starts[row + i];
        if (i == reg.x0 >> 6) s &= ~std::uint64_t{0} << (reg.x0 & 63);
        if (i == last && (reg.x1 & 63) != 63) s &= (std::uint64_t{2} << (reg.x1 & 63)) - 1;
        if (!s) continue;
        const int* run = runs.data() + runs_before[row + i] +
                         count_bits(starts[row + i] & ((std::uint64_t{1} << __builtin_ctzll(s)) - 1));
        for (; s; s &= s - 1, ++run) {
          if (*run != r) continue;
          const int x0 = i * 64 + __builtin_ctzll(s);
          // Its end: the next start in the row (within the box), or the row's end.
          int k = i;
          std::uint64_t next = starts[row + i] & (~std::uint64_t{1} << (x0 & 63));
          while (!next && ++k < words_per_row) next = starts[row + k];
          const int x1 = next ? k * 64 + __builtin_ctzll(next) : width;
          f(y, x0, x1);
        }
      }
    }
  }
};

// Calls f(y, x0, x1, region) for every run of the image (pixels x0 .. x1 - 1 of row y),
// in raster order.
template <class F>
void for_all_runs(const RegionTree& tree, int height, F&& f) {
  const int* run = tree.runs.data();
  for (int y = 0; y < height; ++y) {
    const std::uint64_t* row = tree.starts.data() + std::size_t(y) * tree.words_per_row;
    int x0 = -1, region = -1;
    for (int i = 0; i < tree.words_per_row; ++i)
      for (std::uint64_t s = row[i]; s; s &= s - 1) {
        const int x = i * 64 + __builtin_ctzll(s);
        if (x0 >= 0) f(y, x0, x, region);
        x0 = x, region = *run++;
      }
    if (x0 >= 0) f(y, x0, tree.width, region);
  }
}

// Single-pass labelling over runs with union-find. The provisional labels live in the
// tree's regions and become them in place, so the buffers are the tree's, kept between
// frames. A binary image of 2^30 runs or more is refused (std::length_error).
class RegionLabeller {
 public:
  void label(const BinaryImage& binary, RegionTree& tree);
  std::size_t bytes_reserved() const { return (row_x_[0].capacity() + row_x_[1].capacity()) * sizeof(int); }

 private:
  std::vector<int> row_x_[2];  // run starts of the row above and of this row, and the row's end
};

// ---------------------------------------------------------------- candidates.cpp
// Where the pixels handed to find_candidates lie in the frame: a patch enlarged `scale`
// times whose pixel (0, 0) covers frame pixel `origin` (the whole frame by default).
struct PatchFrame {
  cv::Point origin{0, 0};
  int scale = 1;
  cv::Point2d to_frame(cv::Point2d p) const {
    return {(p.x + 0.5) / scale - 0.5 + origin.x, (p.y + 0.5) / scale - 0.5 + origin.y};
  }
};

struct Blob {
  int region = -1;
  int area = 0;             // pixels
  double mass = 0;          // zeroth moment of the inverted grey image over the dilated region
  double relative_ink = 0;  // mass over what perspective alone gives it (see find_candidates)
  cv::Point2d centroid;     // image pixels, as observed (distorted)
  cv::Point2d point;        // undistorted pixels, for geometry
};

// The paper a square's ink is measured against: one level, or where the light varies
// across a marker, the level under each pixel (see paper_under).
struct PaperLevel {
  PaperLevel(double level = 255) : level(level) {}  // NOLINT: one level is the common case
  double level;
  cv::Mat1b local;
  cv::Point origin;
  // The ink of grey level g at pixel (x, y): how much darker than the paper there, in
  // units of `level`.
  double ink(int x, int y, double g) const {
    if (local.empty()) return std::max(0.0, level - g);
    const int u = x - origin.x, v = y - origin.y;
    if (u < 0 || v < 0 || u >= local.cols || v >= local.rows) return std::max(0.0, level - g);
    const double paper = std::max<double>(1, local(v, u));
    return std::max(0.0, paper - g) * level / paper;
  }
};

struct Candidate {
  Family family{3};
  int white_region = -1;
  double white_area = 0;    // pixels of the white region
  std::vector<Blob> blobs;  // the n^2 largest black children
  // The paper its squares were measured against: the upper quartile of the white region's
  // grey levels, and a local level in frame pixels where the light varies (only for
  // candidates at the frame's own resolution).
  PaperLevel paper;
};

// Topological filtering, vertex estimation and the area constraint. Counts into stats.
// `image` and `binary` may be a patch of the frame (see PatchFrame): the candidates'
// centroids, areas and inks are then given in the frame's pixels. Candidates that fail
// the area constraint go to `area_rejected` when it is not null (for the trace).
// `budget`, when not null, is the number of topological candidates the frame may still
// examine (DetectorParams::max_candidates): when there are more, the most plausible are
// examined (see DetectorParams), the budget is spent and the rest are counted into
// stats.skipped_by_budget and listed in `skipped` when it is not null, unmeasured (their
// blobs' centroids are the centres of their boxes).
void find_candidates(const RegionTree& tree, const BinaryImage& binary, const ImageView& image,
                     const DetectorParams& params, const Camera& camera, std::vector<Candidate>& out,
                     DetectionStats& stats, const PatchFrame& patch = {},
                     std::vector<Candidate>* area_rejected = nullptr, int* budget = nullptr,
                     std::vector<Candidate>* skipped = nullptr);

// The paper's grey level that a blob's ink is measured against: `level` everywhere, or,
// where `local` has pixels (from `origin` in the image measured), the paper under each
// pixel, so that a shadow across a marker takes the light from its squares' ink and
// not the paper from the light (see find_candidates). Inks stay in units of `level`.
// Squares of at least this many pixels (a candidate's median) have paper between them:
// gaps of 2 units are then 3.3 px or more, of which a pixel or more stays pure paper after
// paper_under's 3 x 3 mean. Below it the closing would take mixed pixels for paper.
constexpr int kMinLocalPaperArea = 25;
// The paper under a candidate is followed pixel by pixel only where its darkest tenth is
// under this share of its brightest tenth (over the white region): a shadow across the
// marker (the field experiment's: 0.35 to 0.6 of the light) and not the pattern's own
// unevenness under blur (6 % on a 60 px marker defocused by 1.2 px) nor a light gradient
// across a frame (0.4 across 1280 px: 6 % across a 200 px marker).
constexpr double kMinPaperSpread = 0.8;
// Before the closing, the paper between the squares where no blur of their edges reaches
// is looked at (pure_paper_even): where its darkest tenth is at kEvenPaperShare of its
// brightest tenth or more, over kMinEvenPaperPixels pixels or more, the light is taken as
// even without the closing. Set before any measurement (noise of 3 grey levels on paper
// at 180 leaves 0.96; the field experiment's low light, 6 on 70, 0.80, which the closing
// decides). On every frame of the field experiment (3x3, 4x4 and 6x6, both sets) and of
// the video experiment (3x3) no candidate it passed (7,377 and 2,089) had a closed level
// that varies, and it passed 72 % of those the closing was taken for.
constexpr double kEvenPaperShare = 0.9;
constexpr int kMinEvenPaperPixels = 50;
// Where the paper is followed, each square's centroid is measured against the one level
// too; a square whose centroid the choice moves by this much (units: a third of its side)
// straddles the shadow's edge, where neither level is its paper, and the candidate is not
// read by its blobs (half the distance between two of a square's positions: the paper
// model alone could decide its digit). A 3x3 square across a shadow's edge in the field
// experiment moved 1.9 units, and was read a unit off with the local paper alone.
constexpr double kMaxPaperShift = 0.5;

// The paper a candidate's `count` squares `kids` are measured against: the upper
// quartile of its white region's grey levels, and, where its squares are large enough for
// pure paper to show between them (a median of kMinLocalPaperArea pixels: gaps of 3.3 px
// and more) and the light varies across it (kMinPaperSpread), the paper under each pixel
// near them: the grey levels, averaged over 3 x 3 against the noise, closed (a dilation,
// then an erosion) by a square one pixel wider each way than the largest square's box.
// That fills every square and the border (2 units, narrower than any square) with the
// paper around them, and keeps the edge of a shadow across the paper where it lies, so
// that a shadowed square's ring of paper does not count as its ink.
PaperLevel paper_under(const RegionTree& tree, int white_region, const int* kids, int count, const ImageView& image,
                       const BinaryImage& binary, int reach);
// Whether the paper of `white_region` shows the light even before any closing
// (kEvenPaperShare), on the pixels that no blur of an edge reaches: two or more pixels
// inside its runs, the pixels two rows above and below white too. None when fewer than
// kMinEvenPaperPixels are so (a small or blurred marker).
std::optional<bool> pure_paper_even(const RegionTree& tree, int white_region, const BinaryImage& binary,
                                    const ImageView& image);

// Centroids of blobs, its buffers reused from one blob to the next.
class BlobMeasurer {
 public:
  // Centroid of the inverted grey image over `region` with its holes and the white pixels
  // within `reach` pixels of it that are nearer to it than to any other black pixel.
  // `paper` is the grey level that weighs zero (255 for the paper's plain inversion).
  // With `flat_centroid`, the centroid against paper.level alone as well, in the same pass.
  Blob measure(const RegionTree& tree, int region, const ImageView& image, const BinaryImage& binary, int reach,
               const PaperLevel& paper, cv::Point2d* flat_centroid = nullptr);

 private:
  std::vector<std::uint8_t> classes_, to_own_, to_other_;  // per pixel of the blob's window
  std::vector<int> inside_;                                // the region and what it encloses
};

// ---------------------------------------------------------------- second_look.cpp
struct SecondLook {
  int min_size = 6;  // frame pixels, the cluster's longer side
  int max_size = 192;
  int enlarge_below = 64;  // clusters smaller than this are enlarged twice
  double noise = 0;        // the frame's pixel noise (estimate_noise), grey levels
  // The n x n families sought (bit n): resolved markers of the others are not looked at
  // again (see near_candidates).
  std::bitset<Family::kMaxN + 1> sought = std::bitset<Family::kMaxN + 1>().set().reset(0).reset(1);
  int max_n() const {
    int n = Family::kMaxN;
    while (n > 0 && !sought[n]) --n;
    return n;
  }
};

// Boxes of small isolated clusters of black regions, part ink and part paper, that touch
// none of the `taken` boxes: where a marker may be that the binary image did not resolve.
// Resolved markers of families larger than every one sought are not, nor clusters of
// `look.enlarge_below` px or more whose binary image explains their `grey` levels and
// shows coarse features or a smaller family's marker not sought. The most isolated (the
// whitest ring around the box) come first.
std::vector<cv::Rect> near_candidates(const RegionTree& tree, const BinaryImage& binary, const ImageView& grey,
                                      const SecondLook& look, const std::vector<cv::Rect>& taken);

// A neighbourhood of the frame, enlarged, with its local darkest and brightest levels.
struct Patch {
  cv::Mat grey, dark, bright;
  PatchFrame frame;
  cv::Mat grey_buffer, enlarged_buffer, blurred_buffer;  // kept between patches
};

// The neighbourhood of `box` enlarged as `look` says; false when it is empty.
bool enlarge_patch(const ImageView& image, cv::Rect box, const SecondLook& look, Patch& patch);

// Black where a pixel lies below the midpoint of its local darkest and brightest levels,
// where those differ by a printed contrast; white elsewhere.
void binarise_patch(const Patch& patch, BinaryImage& out);

// ---------------------------------------------------------------- shading.cpp
// The paper's level under each pixel of `grey`: its levels closed (a dilation, then an
// erosion) by a square of `feature` px, wider than its darkest features.
cv::Mat1b paper_level(const cv::Mat& grey, int feature);
// A paper level with every basin filled: each place raised to the highest level at which
// a path no darker leads to the image's edge. No shadow lies wholly inside a marker, so a
// dim place that brighter paper encloses is the marker's own ink widened by a blur past
// the closing (a motion blur along a diagonal joins a baseline to the border's corner).
cv::Mat1b filled_basins(const cv::Mat1b& level);
// Whether the light under a closed paper level varies, as `even` (a level -> bool)
// judges it: a level that looks uneven has its basins filled (`paper` is left so) and is
// judged again. Filling only raises a level and costs more than the closing, so an even
// level is not filled.
template <class Even>
bool light_varies(cv::Mat1b& paper, const Even& even) {
  if (even(paper)) return false;
  paper = filled_basins(paper);
  return !even(paper);
}

// The neighbourhood of a marker's outline with the light taken out: each pixel over the
// paper under it (paper_level, the darkest features being the 4-unit baselines), at the
// lit paper's level.
struct EvenLight {
  cv::Mat1b pixels;
  cv::Point origin;  // the frame pixel of pixels(0, 0)
  cv::Mat1b paper;   // the paper's level under each pixel (frame grey levels), from origin
};
// None where the light is even along the marker's white ring (its dimmest tenth at
// kMinPaperSpread of its brightest or more, as paper_under decides for candidates) or the
// outline is under 1.67 px per unit of `family` (no pure paper between its squares).
std::optional<EvenLight> even_light(const ImageView& image, const std::array<cv::Point2d, 4>& outline,
                                    const Family& family);

// ---------------------------------------------------------------- borders.cpp
// What the grey levels along a quadrilateral say of a marker's black border there, were
// it the outer edge of a marker of some family: bands of the family's units along its
// four sides, sampled on their middle four fifths.
struct BorderEvidence {
  double contrast = 0;     // the margin's mean grey level (a unit outside) minus the border's (its middle unit)
  double noise = 0;        // the standard deviation of those samples about their band's mean, pooled
  double ring = 0;         // the white ring's mean level (its middle unit) above the border's, over
                           // the contrast: about 1 for a sharp marker, less when blur mixes them
  int darker_sides = 0;    // sides whose border band is darker than their own margin band
  double structure = 0;    // the white ring and the lines between cells above the cells' cores, over
                           // the contrast: about 1 for a sharp marker of the family, less blurred, about
                           // 0 for another family's or none
  double clarity() const;  // contrast over noise (noise at least one grey level)
  // A marker's border: darker than the margin on every side (each side against its own
  // margin, so that a shadow across the marker does not matter), by kMinBorderSeparation
  // times the noise overall, with a white ring inside it (kMinRingShare) and the family's
  // structure inside that (kMinStructure).
  bool plausible() const;
};
// Speed bounds: they spare the outline reads of what is no marker, and a proposal they
// refuse may still be a second look's cluster. Chosen on the field experiment's tuning set
// (every frame, 3x3 and 6x6): of the borders read as markers, all had a contrast of 1.09
// noise or more, a ring of 0.085 or more and a structure of 0.198 or more but one (a 3x3
// at -0.17, found by its patch's squares); of the proposals whose reads failed these
// bounds refuse 56 % (3x3) and 10 % (6x6), and on the validation set 87 % and 42 % (the
// letters of a printed page: structure -0.16 to -0.51) at the cost of 8 of 772 markers
// read (6x6), which a second look may still find.
constexpr double kMinBorderSeparation = 1;
constexpr double kMinRingShare = 0.08;
constexpr double kMinStructure = 0.15;
// A marker's border, with what joined it, is a region of kMinBorderSize px or more (a
// border of one or two pixels, under that, cannot be told from its margin) that covers
// kMinBorderFill to kMaxBorderFill of its box: in the field experiment's tuning set every
// border read as a marker covered 0.106 to 0.582 and was 20 px or more (validation set:
// 0.104 to 0.562, 18 px). Thin lines and solid blobs, most of a photo's regions, are not.
constexpr int kMinBorderSize = 16;
constexpr double kMinBorderFill = 0.05, kMaxBorderFill = 0.7;
// A black region's convex hull is a quadrilateral when the largest quadrilateral of its
// simplified outline covers this share of its area.
constexpr double kMinQuadFill = 0.85;

// The evidence along `corners` (the outer edge, frame pixels, clockwise on screen) for a
// marker of `family`; none when they span no homography.
std::optional<BorderEvidence> border_evidence(const ImageView& image, const std::array<cv::Point2d, 4>& corners,
                                              const Family& family);

struct BorderProposal {
  std::array<cv::Point2d, 4> corners;       // frame pixels, clockwise on screen
  std::optional<BorderEvidence> evidence;   // for the family it is clearest for (of those it passes for)
  std::bitset<Family::kMaxN + 1> families;  // the families (bit n) whose border it plausibly is
  int region = -1;                          // the black region of the frame's binary image
};

// The outer edges of the black regions of the frame's binary image that may be markers'
// borders: regions of `look`'s sizes (no more than 4:1) touching none of the `taken`
// boxes, whose convex hull is a quadrilateral and whose border evidence is plausible for
// one of `families`; the clearest first. Those refused on their evidence go to `refused`
// when it is not null.
std::vector<BorderProposal> propose_borders(const RegionTree& tree, const ImageView& image, const SecondLook& look,
                                            const std::vector<Family>& families, const std::vector<cv::Rect>& taken,
                                            std::vector<BorderProposal>* refused = nullptr);

// ---------------------------------------------------------------- alignment.cpp
// The alignment of a template to an image under a homography that maximises their
// enhanced correlation coefficient, as cv::findTransformECC(templ, image, warp,
// MOTION_HOMOGRAPHY, criteria, noArray(), 3) computes it, with the image's smoothing and
// gradients made once for every template aligned to it.
class EccAlignment {
 public:
  explicit EccAlignment(const cv::Mat1f& image);
  // Moves `warp` (template pixels -> image pixels) for at most `max_steps` steps, until the
  // correlation changes by less than `min_change`; returns the correlation measured before
  // the last step, or none where cv::findTransformECC throws (the correlation undefined or
  // about to be minimised).
  std::optional<double> align(const cv::Mat1f& templ, cv::Matx33f& warp, int max_steps, double min_change) const;

 private:
  cv::Mat3f prepared_;  // per pixel: smoothed grey level, its x and y derivatives
};

// ---------------------------------------------------------------- outline.cpp
// The quadrilateral outlines of the largest groups of black pieces of a patch's binary
// image that lie in one white region clear of the patch's edge, without specks far from
// the rest, then of the pieces of such groups closed around their squares (a hole that
// holds two or more pieces, or one and is a tenth of the piece's hull or more), alone
// (at most three, the groups largest first), in frame pixels, clockwise on screen.
std::vector<std::array<cv::Point2d, 4>> coarse_outlines(const BinaryImage& binary, const PatchFrame& frame);

// A marker read from the grey levels under its aligned outline.
struct OutlineReading {
  bool read = false;  // the cells were read: `id` holds the reading
  TagId id;
  cv::Matx33d homography;          // units -> frame pixels (as observed), in the marker's true turn
  double correlation = 0;          // of the marker's fixed structure with the image (ECC)
  double marker_correlation = 0;   // of the whole marker read, aligned again (ECC)
  double contrast = 0;             // the white ring's grey level minus the cells' cores' (under
                                   // a defocus found: as the template's own blur shows them)
  double margin = 0;               // least, over the data cells, of how much worse the runner-up
                                   // square position fits than the best: mean squared grey
                                   // difference per sample over the contrast squared
  double noise_margin = 0;         // standard deviations of the fit's residuals by which the
                                   // least certain cell stands from another digit (least of
                                   // the readings made; see Detection::noise_margin)
  double evidence = 0;             // least, over the data cells and their other positions, of
                                   // how much the fit worsens when the square moves there, over
                                   // how much the model predicts (1: the image shows the whole
                                   // difference; 0: it lies halfway), under the final alignment
  double listed_noise_margin = 0;  // with the ids in use complete (DetectorParams::ids_complete):
                                   // standard deviations of the fit's residuals by which the
                                   // nearest other listed id, all its differing squares moved,
                                   // fits worse (0: the id read is not listed; under the final
                                   // alignment)
  double listed_evidence = 0;      // the same rival's worsening over the model's prediction of
                                   // it (as `evidence`, over all the squares that differ)
  double model_ink = 0;            // the ink (paper minus ink level) the pixel model fits to the
                                   // whole marker of the id read, over `contrast` (least of the
                                   // readings made)
  double baseline_gap = 0;         // how much more the two baseline corners look like baselines
                                   // than the other two (0..1 of the contrast)
  double pixels_per_unit = 0;      // along the most foreshortened direction, at the centre
  double smear = 0;                // length of the motion blur found, units (0: none)
  double defocus = 0;              // Gaussian blur found beyond the pixels', units (0: none)
  bool past_deadline = false;      // cut short by the frame's deadline: not acceptable
  bool repeated = false;           // aligned where the frame's readings found a marker already: not read
};

// Where a frame's outline readings found a marker (the aligned outer corners, frame
// pixels), so that another outline of the same marker, from another patch or group of
// pieces, is not read again: its alignment lands where the first one did, and its
// detection would be dropped as a duplicate after the pixel models (most of a reading's
// cost). Refused readings are not recorded: another start can align a little differently
// and read the marker (in the full field plan, 12 markers of 3x3, 4x4 and 6x6 through
// H.264 and small at 1080p were read so, and lost when refused places were skipped too).
struct ReadPlaces {
  struct Place {
    int n = 0;
    std::array<cv::Point2d, 4> corners;
    double pixels_per_unit = 0;
  };
  std::vector<Place> places;
  // Whether a marker of family n was found with every corner within a unit of `corners`
  // (in any turn).
  bool seen(int n, const std::array<cv::Point2d, 4>& corners, double pixels_per_unit) const;
  void add(int n, const cv::Matx33d& homography, const Family& family, double pixels_per_unit);
};

// Aligns the fixed structure of `family` to the image from `outline` (its outer corners,
// clockwise on screen, from any of them) and reads the id; none when the alignment fails.
// A start well under `min_pixels_per_unit` is not aligned: the reading returned has only
// its correlation and pixels per unit, which fail the checks. Each alignment starts only
// while `deadline` has not passed; after it the reading returned is marked past_deadline.
// With `read_places`, an outline aligned where a marker was found already is not read
// again (the reading returned is marked repeated). With `expected` (a tracked marker's
// id), that id's marker is aligned at once and read only under its final alignment.
std::optional<OutlineReading> read_outline(const ImageView& image, const std::array<cv::Point2d, 4>& outline,
                                           const Family& family,
                                           double min_pixels_per_unit = DetectorParams{}.min_pixels_per_unit,
                                           const Deadline& deadline = {}, ReadPlaces* read_places = nullptr,
                                           std::optional<TagId> expected = std::nullopt,
                                           const std::vector<TagId>* complete_ids = nullptr);

// The checks an outline reading must pass to be a detection, each scale-free.
constexpr double kMinStartCorrelation = 0.4;  // before the alignment, where the outline puts it
// From kResolvedPixelsPerUnit, at the start too, with the best motion blur; from
// kSharpPixelsPerUnit, kMinSharpStartCorrelation.
constexpr double kMinResolvedStartCorrelation = 0.66, kResolvedPixelsPerUnit = 2;
constexpr double kMinSharpStartCorrelation = 0.55, kSharpPixelsPerUnit = 1.5;
// Aligned, below which no motion blur or defocus is sought. A 31 px 4x4 at 60 degrees of
// tilt, defocused by 1.45 px, aligned at 0.58 to 0.60 before its defocus took it to 0.76.
// Where the sharp structure aligned under it, or not at all, the best smear at the start
// must reach it to be aligned.
constexpr double kMinSmearedCorrelation = 0.55;
// Where the sharp structure did not align, a smear is sought from the start only at this
// resolution or more (the start's pixels per unit): under it a smeared marker's squares
// are not told apart. Chosen on the field's tuning set, where every reading this search got
// accepted started at 1.10 px per unit or more (4x4; 3x3 1.27, 6x6 1.47) and the refused
// ones at medians of 0.54 to 0.96.
constexpr double kMinSmearedStartPixelsPerUnit = 1.0;
constexpr double kMinCorrelation = 0.75, kMinMarkerCorrelation = 0.75, kMinContrast = 16, kMinMargin = 0.03;
// The turn: the two corners taken as the baselines must look more like baselines than
// the other two by this fraction of the contrast (OutlineReading::baseline_gap). A round
// quarter, not tuned on any set: sharp markers show 0.74 to 0.91, and glare that
// lightens one baseline's outer strip takes it below (test_outline's boundary test).
constexpr double kMinBaselineGap = 0.25;
// Every data cell must show this much of the difference between its square's position and
// each other one (OutlineReading::evidence): a cell under it lies within 0.3 of the way
// from halfway, where compression or noise decides the digit (the blobs' counterpart is
// DetectorParams::max_cell_residual). Scale- and contrast-free: the model's prediction is
// the yardstick. Chosen on the field experiment's tuning set, where every wrong outline
// reading (small markers through H.264 at 1080p) had 0.38 or less, and on the outline
// and detector tests' renders at the resolution and blur limits, whose right readings had
// 0.37 (one) and 0.41 or more; the validation set's wrong ones had 0.16 at most.
constexpr double kMinEvidence = 0.4;
// An unsmeared reading refused with under this evidence marks its place read for the rest
// of the frame (read_one_outline in detector.cpp): half the bound, under the least (0.26)
// of the readings that the field experiment's tuning set read again and accepted.
constexpr double kEvidenceNotReadAgain = kMinEvidence / 2;
// The ink (paper minus ink level) that the pixel model fits to the whole marker must be
// more than this share of the contrast measured between its white ring and its squares'
// cores (OutlineReading::model_ink): squares at the positions read that explain the grey
// levels only with a faint print explain something else. A round share, not tuned. The
// margin check nearly implies it: a square moved one unit changes 6 of a cell's 25 unit
// areas, so a sharp reading's margin is at most 0.24 x model_ink squared, and a margin of
// kMinMargin needs a model ink of 0.35; blur lowers the margin further.
constexpr double kMinModelInk = 0.4;
// With the ids in use complete (DetectorParams::ids_complete), a reading that the margin
// and evidence checks refuse against the ids one square off is taken in when, against
// every other listed id (all its differing squares moved), its evidence reaches
// kMinEvidence and its noise margin this. The evidence keeps a listed id one square off,
// whose square the image shows part of the way, the runner-up it is; the noise margin
// asks the difference to stand out of the residuals. Three deviations, a round bound: the
// field experiment's tuning set took its readings in at 2.8 or more (a list of its 60 ids
// per family, or of 2,060 to 10,060), and its wrong readings that were listed stood at
// 0.52 at most.
constexpr double kMinListedNoiseMargin = 3;
// The longest motion blur the alignment tries, units (the pixel model fits lengths up to
// 16 % either side of the one found). A blur near the cells' 6-unit pitch leaves little of
// a square's one-unit shifts; how much is left is the evidence check's to judge, cell by
// cell, as under any other blur (a 4x4 blurred by 5.9 units was misread when blur of over
// 5 units was refused outright and evidence was not yet measured).
constexpr double kLongestSmearSought = 6;
// The first check `reading` fails (Stage::detected when it passes them all), and whether
// it passes them all.
Stage outline_stage(const OutlineReading& reading, const DetectorParams& params);
inline bool acceptable(const OutlineReading& reading, const DetectorParams& params) {
  return outline_stage(reading, params) == Stage::detected;
}

// ---------------------------------------------------------------- keypoints.cpp
// Blob indices of K0..K3 after the geometry, angle and collinearity constraints.
struct KeyPoints {
  std::array<int, 4> blob{};
};

// Blob indices of the four vertices of the centroids' convex hull that span the largest
// quadrilateral, clockwise on screen; empty when the centroids do not span one.
std::vector<int> hull_corners(const Candidate& c);

// K0..K3 for each side of the centroids' hull that passes the constraints (in the order of
// the paper's funnel, counted into stats when any side passes).
std::vector<KeyPoints> find_keypoints(const Candidate& c, const DetectorParams& params, DetectionStats& stats);

// Signed angle from a to b (radians), positive when b turns clockwise from a on screen (y down).
double signed_angle(cv::Point2d a, cv::Point2d b);

// ---------------------------------------------------------------- decode.cpp
// How a decoding ended: rejected because the marker is too small to read, by tau3 or the
// cell residual bound, because no hypothesis's squares' ink matches the design (checked
// before the grey levels, when no hypothesis could pass it), because another id fits
// within the margin, or accepted (the best reading's own ink check comes after). In the
// order a decoding gets through them: detector.cpp compares verdicts by it (a later one
// passed every check of the earlier ones).
enum class Verdict { resolution, residual, ink, margin, accepted };

struct Decoding {
  Verdict verdict = Verdict::accepted;
  TagId id;
  cv::Matx33d homography;         // units -> undistorted pixels
  std::vector<int> blob_of_cell;  // grid order
  double error = 0;               // the paper's decoding error metric
  double edge_score = 0;          // mean Sobel magnitude along the inner border edge
  double worst_cell = 0;          // largest distance of a centroid from its cell's position, units
  // Spread of the squares' ink per unit of design area (largest / smallest) under the
  // homography fitted to all n^2 blobs: about 1 for the marker's true turn, about 2 to 3
  // when the baseline is taken on another side.
  double ink_spread = 0;
  double noise_margin = 0;  // Detection::noise_margin (filled once every other check passed)
};

// Tries the 16 key point hypotheses and returns the best one with its verdict and its ink
// spread; none when no hypothesis could be read at all. When no hypothesis passes the
// checks that need no grey levels (resolution, cell residual, ink spread), the side is
// rejected before the edge scores and decoding errors are computed: the reading returned
// is then the one with the least residual, its error and edge score filled in only when
// `hypotheses` is not null.
// `hypotheses`, when not null, receives every hypothesis' projected inner edge.
// Times the hypotheses and the decoding into `stats`.
std::optional<Decoding> decode(const Candidate& c, const KeyPoints& k, const ImageView& image, const Camera& camera,
                               const DetectorParams& params, DetectionStats& stats,
                               std::vector<std::vector<cv::Point2d>>* hypotheses);

// The reading of a candidate whose blob g is cell g of marker `id` (a tracked marker
// measured where its id puts its squares, tracked.cpp): that one reading, held to every
// bound decode() holds its best reading to on its own (resolution, cell residual, even
// ink, tau3, the noise margins), and none when its digits read another id or it fails one.
// The other key-point hypotheses are not tried: the squares' order is known.
std::optional<Decoding> decode_expected(const Candidate& c, TagId id, const ImageView& image, const Camera& camera,
                                        const DetectorParams& params, DetectionStats& stats);

// Mean 3x3 Sobel magnitude along the square x, y in {a, b} (units) under homography h.
double edge_gradient(const ImageView& image, const Camera& camera, const cv::Matx33d& h, double a, double b);

// Least-squares homography (h33 = 1) taking `from` to `to`; none when degenerate.
std::optional<cv::Matx33d> fit_homography(const std::vector<cv::Point2d>& from, const std::vector<cv::Point2d>& to);

// The grey level at a sub-pixel point, bilinear between the four pixels around it (the
// point clamped into the image).
double grey_at(const ImageView& image, cv::Point2d p);

// Pixels per unit along the marker's most foreshortened direction at unit point u: the
// smaller singular value of h's Jacobian there (0 when not finite).
double smallest_scale(const cv::Matx33d& h, cv::Point2d u);

// Undistorted pixels -> distorted pixels of `camera`, in place.
void distort(const Camera& camera, std::vector<cv::Point2d>& points);

// Milliseconds since `start`, for the stage timings.
double elapsed_ms(std::chrono::steady_clock::time_point start);

// ---------------------------------------------------------------- cell_centroids.cpp
// The ink centroids of marker `id`'s squares (grid order, image pixels as observed), each
// over its square grown by half a unit under `homography` (units -> undistorted pixels),
// the ink weighed against the median grey of the ring half a unit further out, or where
// `paper` has a local level (a shadow across the marker), against the paper under each
// pixel; empty when the marker has under 1.25 pixels per unit, or a window is not wholly
// inside the image or holds no ink. `inks`, when not null, receives each square's ink.
struct CellInk {
  double mass = 0;   // the ink over the window (the zeroth moment its centroid divides by)
  double paper = 0;  // the ring's median grey
};
// `grow`: the units each window adds round its square (half the narrowest gap, 2 units,
// unless a caller needs to reach further); `ring_units`: the width of the ring round it;
// `stride`: every stride-th row and column of both taken (a coarse look, for finding
// where the squares are rather than measuring them).
std::vector<cv::Point2d> cell_centroids(const ImageView& image, const Camera& camera, const Family& family, TagId id,
                                        const cv::Matx33d& homography, const PaperLevel& paper = {},
                                        std::vector<CellInk>* inks = nullptr, double grow = 0.5,
                                        double ring_units = 0.5, int stride = 1);

// ---------------------------------------------------------------- border_edges.cpp
// A point of the border's stroke, seen: the marker-frame point `object` on the stroke's
// centre line was found at `observed` (undistorted pixels); `normal` is the unit normal
// of its side's line there; `weight` is how many points it stands for.
struct EdgePoint {
  cv::Point3d object;
  cv::Point2d observed, normal;
  double weight = 1;
};
struct BorderEdges {
  std::vector<EdgePoint> points;  // as found, outliers to their side's line dropped
  // Each side's line, as two points standing for that side's points (what the pose uses).
  std::vector<EdgePoint> sides;
  double noise = 0;  // the points' RMS scatter about their sides' lines, pixels
};
// Points of the centre line of the black border of a marker of `family` under
// `homography` (units -> undistorted pixels), up to 16 a side; none when the marker has
// under 1.25 pixels per unit or its stroke is blurred by more than about 0.6 to 0.8
// units, and none where the stroke has no white margin beside it.
BorderEdges border_edges(const ImageView& image, const Camera& camera, const Family& family,
                         const cv::Matx33d& homography, double tag_size);

// ---------------------------------------------------------------- tracked.cpp
// A marker expected with `id` under `outline` (outer corners, frame pixels as observed),
// measured there from the grey levels alone, ready to be posed: its squares' centroids as
// the candidate's blobs (grid order), its key points, its decoding and its border's
// stroke. None unless the outline settles on the squares, the paper round them is evenly
// lit and they decode as `id`.
struct TrackedMeasurement {
  Candidate candidate;
  KeyPoints keypoints;
  Decoding decoding;
  BorderEdges edges;
};
std::optional<TrackedMeasurement> measure_tracked(const ImageView& image, const Camera& camera,
                                                  const DetectorParams& params, const Family& family, TagId id,
                                                  const std::array<cv::Point2d, 4>& outline, DetectionStats& stats);

// ---------------------------------------------------------------- pose.cpp
// Final pose from all n^2 centroids and, when given, the border's stroke; fills the pose
// fields, corners and centre.
bool estimate_pose(const Candidate& c, const Decoding& d, const Camera& camera, const DetectorParams& params,
                   Detection& out, const BorderEdges& edges = {});
// The projections of `object` through `k` under a pose, with no distortion: what
// cv::projectPoints computes there (the same operations in the same order, so the same
// bits), without its cost for the handful of points of a marker (3 % of a tracked frame).
std::vector<cv::Point2d> project_pinhole(const std::vector<cv::Point3d>& object, const cv::Vec3d& rvec,
                                         const cv::Vec3d& tvec, const cv::Matx33d& k);
// The pose (marker -> camera) whose projections of `object` through `k` (no distortion)
// lie nearest `observed` (least squares in pixels), by Levenberg-Marquardt from
// (rvec, tvec), which it replaces; left where it is when no pose in front of the camera
// fits better.
// Stroke points, when given, add their distances along their normals, times
// `edge_weight` and the square root of their own weight, to the squares minimised.
void refine_pose(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& observed, const cv::Matx33d& k,
                 cv::Vec3d& rvec, cv::Vec3d& tvec, const std::vector<EdgePoint>& edges = {}, double edge_weight = 0);

}  // namespace lftag::detail
