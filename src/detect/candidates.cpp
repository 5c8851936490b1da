// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological filtering (paper IV-B), vertex estimation (IV-C) and the area constraint.
#include <algorithm>
#include <cmath>
#include <numeric>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "stages.hpp"

namespace lftag::detail {
namespace {

// The grey levels of `image` (whose pixel (0, 0) lies at `origin` in the tree's image)
// over the pixels of `region` within it.
struct LevelHistogram {
  int count[256] = {};
  int total = 0;
  LevelHistogram() = default;
  LevelHistogram(const RegionTree& tree, int region, const cv::Mat1b& image, cv::Point origin = {}) {
    const int x_end = origin.x + image.cols;
    tree.for_each_run(region, [&](int y, int x0, int x1) {
      if (y < origin.y || y >= origin.y + image.rows) return;
      const std::uint8_t* row = image.ptr<std::uint8_t>(y - origin.y) - origin.x;
      x0 = std::max(x0, origin.x), x1 = std::min(x1, x_end);
      for (int x = x0; x < x1; ++x) ++count[row[x]];
      total += std::max(0, x1 - x0);
    });
  }
  // The least level that at least a share q of the pixels do not exceed (255 for none).
  int quantile(double q) const {
    int seen = 0;
    for (int level = 0; level < 256; ++level)
      if ((seen += count[level]) >= q * total && seen > 0) return level;
    return 255;
  }
};

// The white region's paper level: the upper quartile of its grey levels. Its mean would
// sink below the paper's white on a small marker, where most of the region's pixels are
// mixed with the squares around them, and bias every centroid towards the pixel grid
// (0.11 px at 0.67 px per unit, enough to misread an axis-aligned marker).
double white_level(const RegionTree& tree, int region, const ImageView& image) {
  return LevelHistogram(tree, region, image.mat()).quantile(0.75);
}

// The blobs' ink, largest over smallest, with the perspective taken out. A homography
// magnifies area by the cube of a function linear in the image position, so a plane is
// fitted to the cube roots of the inks and each ink is divided by its plane value cubed.
// Face-on this is the design's 16/9 or less; tilted 60 degrees at two tag sizes the raw
// ratio already passes 6, while this stays near the design's.
// Each blob keeps its normalised ink as relative_ink (its raw ink when no plane fits).
double perspective_free_ink_ratio(std::vector<Blob>& blobs) {
  double lo = 1e300, hi = 0;
  for (Blob& b : blobs) {
    b.relative_ink = b.mass;
    lo = std::min(lo, b.mass), hi = std::max(hi, b.mass);
  }
  if (!(lo > 0)) return HUGE_VAL;
  cv::Point2d mean;
  for (const Blob& b : blobs) mean += b.centroid;
  mean /= double(blobs.size());
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const Blob& b : blobs) {
    const Eigen::Vector3d row(1, b.centroid.x - mean.x, b.centroid.y - mean.y);
    normal += row * row.transpose();
    rhs += row * std::cbrt(b.mass);
  }
  const Eigen::Vector3d plane = normal.ldlt().solve(rhs);
  std::vector<double> ink;
  for (const Blob& b : blobs) {
    const double scale = plane[0] + plane[1] * (b.centroid.x - mean.x) + plane[2] * (b.centroid.y - mean.y);
    if (!(scale > 0)) return hi / lo;  // no sensible plane: the raw ratio
    ink.push_back(b.mass / (scale * scale * scale));
  }
  for (std::size_t i = 0; i < blobs.size(); ++i) blobs[i].relative_ink = ink[i];
  const auto [nlo, nhi] = std::minmax_element(ink.begin(), ink.end());
  return *nhi / *nlo;
}

}  // namespace

Blob BlobMeasurer::measure(const RegionTree& tree, int region, const ImageView& image, const BinaryImage& binary,
                           int reach, const PaperLevel& paper, cv::Point2d* flat_centroid) {
  // The blob's window: its box grown by `reach`. In it, each pixel is the blob's own,
  // another black region's, or white; a white pixel counts for the blob when the nearest
  // black pixel within `reach` is the blob's (ties count half). So the anti-aliased edge
  // of the blob counts and the edges of its neighbours and of the border do not. Pixels
  // are classified `reach` further out, where the competing black pixels may lie.
  const Region& r = tree.regions[region];
  const int x0 = std::max(0, r.x0 - reach), y0 = std::max(0, r.y0 - reach);
  const int x1 = std::min(image.width - 1, r.x1 + reach), y1 = std::min(image.height - 1, r.y1 + reach);
  const int cx0 = std::max(0, x0 - reach), cy0 = std::max(0, y0 - reach);
  const int cx1 = std::min(image.width - 1, x1 + reach), cy1 = std::min(image.height - 1, y1 + reach);
  const int w = cx1 - cx0 + 1, h = cy1 - cy0 + 1;
  enum : std::uint8_t { kWhite = 0, kOwn = 1, kOther = 2 };
  std::vector<std::uint8_t>& cls = classes_;
  cls.assign(std::size_t(w) * h, kWhite);
  for (int y = cy0; y <= cy1; ++y)
    for (int x = cx0; x <= cx1; ++x)
      if (binary.black(x, y)) cls[std::size_t(y - cy0) * w + (x - cx0)] = kOther;
  // The blob with everything it encloses: a marker's square has no holes, but one wider
  // than the threshold window binarises as a ring around a white hole, whose dark pixels
  // are as much the square's ink as the ring's.
  std::vector<int>& inside = inside_;
  inside.assign(1, region);
  for (std::size_t i = 0; i < inside.size(); ++i) {
    const int* child = tree.children_of(inside[i]);
    inside.insert(inside.end(), child, child + tree.regions[inside[i]].child_count);
  }
  for (int part : inside)
    tree.for_each_run(part, [&](int y, int rx0, int rx1) {
      std::fill_n(cls.begin() + std::size_t(y - cy0) * w + (rx0 - cx0), rx1 - rx0, kOwn);
    });

  // A white pixel counts by the nearest own and other black pixels within `reach` (a
  // Euclidean radius: twice as accurate at 1 px per unit as the L-infinity ring). Each
  // row's horizontal distance to the nearest pixel of each class (capped at reach + 1)
  // makes that search 2 reach + 1 lookups a pixel instead of (2 reach + 1)^2.
  const int limit = reach * reach, cap = std::min(reach + 1, 255);
  std::vector<std::uint8_t>& to_own = to_own_;
  std::vector<std::uint8_t>& to_other = to_other_;
  to_own.resize(cls.size()), to_other.resize(cls.size());
  for (int y = 0; y < h; ++y) {
    const std::uint8_t* c = cls.data() + std::size_t(y) * w;
    std::uint8_t* o = to_own.data() + std::size_t(y) * w;
    std::uint8_t* t = to_other.data() + std::size_t(y) * w;
    int dow = cap, dot = cap;
    for (int x = 0; x < w; ++x) {
      dow = c[x] == kOwn ? 0 : std::min(dow + 1, cap), dot = c[x] == kOther ? 0 : std::min(dot + 1, cap);
      o[x] = std::uint8_t(dow), t[x] = std::uint8_t(dot);
    }
    dow = cap, dot = cap;
    for (int x = w - 1; x >= 0; --x) {
      dow = c[x] == kOwn ? 0 : std::min(dow + 1, cap), dot = c[x] == kOther ? 0 : std::min(dot + 1, cap);
      o[x] = std::uint8_t(std::min<int>(o[x], dow)), t[x] = std::uint8_t(std::min<int>(t[x], dot));
    }
  }
  const bool flat = flat_centroid != nullptr;
  double m = 0, mx = 0, my = 0, fm = 0, fmx = 0, fmy = 0;
  for (int y = y0; y <= y1; ++y) {
    const std::uint8_t* row = image.data + y * image.stride;
    const std::uint8_t* c = cls.data() + std::size_t(y - cy0) * w;
    for (int x = x0; x <= x1; ++x) {
      double share = 0;
      if (c[x - cx0] == kOwn) {
        share = 1;
      } else if (c[x - cx0] == kWhite) {
        int own = limit + 1, other = limit + 1;  // squared distances
        for (int dy = std::max(-reach, cy0 - y); dy <= std::min(reach, cy1 - y); ++dy) {
          const std::size_t at = std::size_t(y + dy - cy0) * w + (x - cx0);
          if (const int d = to_own[at]; d <= reach) own = std::min(own, d * d + dy * dy);
          if (const int d = to_other[at]; d <= reach) other = std::min(other, d * d + dy * dy);
        }
        share = own > limit ? 0.0 : own < other ? 1.0 : own == other ? 0.5 : 0.0;
      }
      if (share == 0) continue;
      const double wgt = share * paper.ink(x, y, row[x]);
      m += wgt, mx += wgt * x, my += wgt * y;
      if (!flat) continue;
      const double fwgt = share * std::max(0.0, paper.level - row[x]);
      fm += fwgt, fmx += fwgt * x, fmy += fwgt * y;
    }
  }

  Blob b;
  b.region = region;
  b.area = r.area;
  b.mass = m;
  const cv::Point2d middle((r.x0 + r.x1) / 2.0, (r.y0 + r.y1) / 2.0);
  b.centroid = m > 0 ? cv::Point2d(mx / m, my / m) : middle;
  if (flat) *flat_centroid = fm > 0 ? cv::Point2d(fmx / fm, fmy / fm) : middle;
  return b;
}

std::optional<bool> pure_paper_even(const RegionTree& tree, int white_region, const BinaryImage& binary,
                                    const ImageView& image) {
  LevelHistogram pure;
  tree.for_each_run(white_region, [&](int y, int x0, int x1) {
    if (y < 2 || y + 2 >= image.height) return;
    const std::uint8_t* row = image.data + std::ptrdiff_t(y) * image.stride;
    for (int x = x0 + 2; x < x1 - 2; ++x)
      if (!binary.black(x, y - 2) && !binary.black(x, y + 2)) ++pure.count[row[x]], ++pure.total;
  });
  if (pure.total < kMinEvenPaperPixels) return std::nullopt;
  return pure.quantile(0.1) >= kEvenPaperShare * pure.quantile(0.9);
}

PaperLevel paper_under(const RegionTree& tree, int white_region, const int* kids, int count, const ImageView& image,
                       const BinaryImage& binary, int reach) {
  PaperLevel paper(white_level(tree, white_region, image));
  std::vector<int> areas;
  cv::Rect box;
  int largest = 0;
  for (int i = 0; i < count; ++i) {
    const Region& r = tree.regions[kids[i]];
    areas.push_back(r.area);
    const cv::Rect b(r.x0, r.y0, r.x1 - r.x0 + 1, r.y1 - r.y0 + 1);
    box = i == 0 ? b : box | b;
    largest = std::max({largest, b.width, b.height});
  }
  if (areas.empty()) return paper;
  std::nth_element(areas.begin(), areas.begin() + count / 2, areas.end());
  if (areas[std::size_t(count / 2)] < kMinLocalPaperArea) return paper;
  // Most markers are evenly lit, and their pure paper shows it at a fraction of the
  // closing's cost.
  if (pure_paper_even(tree, white_region, binary, image).value_or(false)) return paper;
  // Closed by a square one pixel wider each way than the largest square's box.
  const int k = largest + 2;
  const int grow = reach + k;
  const cv::Rect window = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) &
                          cv::Rect(0, 0, image.width, image.height);
  paper.local = paper_level(image.mat()(window), k);
  paper.origin = window.tl();
  // Only a light that varies across the marker is followed: the closing also varies with
  // the pattern where blur leaves no pure paper between squares (on a 60 px marker
  // defocused by 1.2 px, 6 % lower beside the border than at the crossings of the gaps,
  // which pulled the outer squares' centroids 0.03 px further inwards), and by the noise.
  const auto even = [&](const cv::Mat1b& level) {
    const LevelHistogram closed(tree, white_region, level, paper.origin);
    return closed.quantile(0.1) >= kMinPaperSpread * closed.quantile(0.9);
  };
  if (!light_varies(paper.local, even)) {
    paper.local.release();
    return paper;
  }
  const LevelHistogram closed(tree, white_region, paper.local, paper.origin);
  // Scaled so that its upper quartile over the white region is the white region's own:
  // the lit paper is then measured against the level every other marker is.
  if (const int quartile = closed.quantile(0.75); quartile > 0)
    paper.local.convertTo(paper.local, CV_8U, paper.level / quartile);
  return paper;
}

namespace {

// A white region with the child count of a family: a topological candidate, not yet measured.
struct Topological {
  int region;
  int family;                // index into params.families
  int first_kid, kid_count;  // into the kids list
};

// Topological candidates in the order they are to be examined when the budget cannot take
// them all: the first of every enclosing black region before the second of any, and within
// a round those whose region encloses fewest candidates first. A marker's border encloses
// its white interior alone; the grout of a tiled wall or a perforated sheet encloses every
// tile. Otherwise (stable) in the raster order of the white regions.
void order_by_plausibility(const RegionTree& tree, std::vector<Topological>& all) {
  std::vector<int> siblings(tree.regions.size() + 1, 0), rank(all.size());
  for (std::size_t i = 0; i < all.size(); ++i) rank[i] = siblings[tree.regions[all[i].region].parent + 1]++;
  std::vector<int> order(all.size());
  std::iota(order.begin(), order.end(), 0);
  const auto crowd = [&](int i) { return siblings[tree.regions[all[i].region].parent + 1]; };
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return rank[a] != rank[b] ? rank[a] < rank[b] : crowd(a) < crowd(b); });
  std::vector<Topological> sorted;
  sorted.reserve(all.size());
  for (int i : order) sorted.push_back(all[i]);
  all.swap(sorted);
}

}  // namespace

void find_candidates(const RegionTree& tree, const BinaryImage& binary, const ImageView& image,
                     const DetectorParams& params, const Camera& camera, std::vector<Candidate>& out,
                     DetectionStats& stats, const PatchFrame& patch, std::vector<Candidate>* area_rejected, int* budget,
                     std::vector<Candidate>* skipped) {
  out.clear();
  if (area_rejected) area_rejected->clear();
  if (skipped) skipped->clear();
  const double pixel_area = 1.0 / (patch.scale * patch.scale);  // of a patch pixel, in frame pixels
  stats.regions += std::int64_t(tree.regions.size());
  int smallest = 1 << 30, largest = 0;
  for (const Family& f : params.families) {
    smallest = std::min(smallest, f.cell_count());
    largest = std::max(largest, f.cell_count() + params.max_extra_children);
  }

  // Topology: white regions with n^2 .. n^2 + extra children once the noise is left out.
  std::vector<int> kids;
  std::vector<Topological> found;
  for (int r = 1; r < int(tree.regions.size()); ++r) {
    const Region& white = tree.regions[r];
    if (white.black || white.child_count < smallest) continue;
    // Noise, not blobs: children much smaller than the white region (the paper's rule) or
    // than the largest child (specks of sensor noise inside a large marker).
    const int* child = tree.children_of(r);
    int largest_child = 0;
    for (int i = 0; i < white.child_count; ++i) largest_child = std::max(largest_child, tree.regions[child[i]].area);
    const double noise = std::max(white.area * params.min_child_fraction, largest_child / params.max_child_ratio);
    const int first = int(kids.size());
    for (int i = 0; i < white.child_count; ++i)
      if (tree.regions[child[i]].area >= noise) kids.push_back(child[i]);
    const int count = int(kids.size()) - first;
    if (count < smallest || count > largest) {
      kids.resize(first);
      continue;
    }
    for (int fi = 0; fi < int(params.families.size()); ++fi) {
      const int n2 = params.families[fi].cell_count();
      if (count >= n2 && count <= n2 + params.max_extra_children) found.push_back({r, fi, first, count});
    }
  }
  stats.topology += std::int64_t(found.size());

  // The budget: the most plausible first, the rest skipped.
  std::size_t examined = found.size();
  if (budget) {
    if (found.size() > std::size_t(*budget)) {
      order_by_plausibility(tree, found);
      examined = std::size_t(*budget);
    }
    *budget -= int(examined);
    stats.skipped_by_budget += std::int64_t(found.size() - examined);
    if (skipped)
      for (std::size_t i = examined; i < found.size(); ++i) {
        Candidate c;
        c.family = params.families[found[i].family];
        c.white_region = found[i].region;
        for (int k = 0; k < std::min(found[i].kid_count, c.family.cell_count()); ++k) {
          const Region& g = tree.regions[kids[found[i].first_kid + k]];
          Blob b;
          b.region = kids[found[i].first_kid + k];
          b.area = g.area;
          b.centroid = patch.to_frame({(g.x0 + g.x1) / 2.0, (g.y0 + g.y1) / 2.0});
          c.blobs.push_back(b);
        }
        skipped->push_back(std::move(c));
      }
  }

  BlobMeasurer measurer;
  for (std::size_t i = 0; i < examined; ++i) {
    const Topological& t = found[i];
    const Family& f = params.families[t.family];
    const int n2 = f.cell_count();
    int* k = kids.data() + t.first_kid;
    // Keep the n^2 largest children.
    std::partial_sort(k, k + n2, k + t.kid_count,
                      [&](int a, int b) { return tree.regions[a].area > tree.regions[b].area; });
    Candidate c;
    c.family = f;
    c.white_region = t.region;
    c.white_area = tree.regions[t.region].area * pixel_area;
    const int reach = params.dilation * patch.scale;
    const PaperLevel paper = params.centroid_reference == CentroidReference::local_white
                                 ? paper_under(tree, t.region, k, n2, image, binary, reach)
                                 : PaperLevel(255.0);
    c.paper = paper;
    if (patch.scale == 1)
      c.paper.origin += patch.origin;
    else
      c.paper.local.release();  // the pose reads the frame, not the enlarged patch
    bool straddles = false;     // a square across a shadow's edge (kMaxPaperShift)
    for (int j = 0; j < n2; ++j) {
      cv::Point2d flat;  // the centroid against the one level, where the paper level follows the light
      Blob b = measurer.measure(tree, k[j], image, binary, reach, paper, paper.local.empty() ? nullptr : &flat);
      if (!paper.local.empty()) {
        const double unit = std::sqrt(double(b.area)) / 3;
        straddles = straddles || cv::norm(b.centroid - flat) > kMaxPaperShift * unit;
      }
      b.centroid = patch.to_frame(b.centroid);
      b.mass *= pixel_area;
      c.blobs.push_back(b);
    }
    // Area constraint on the blobs' ink (the zeroth moments, robust at a few pixels),
    // perspective taken out; a square whose ink depends on the paper model has none to go by.
    if (straddles || !(perspective_free_ink_ratio(c.blobs) <= params.max_ink_ratio)) {
      if (area_rejected) area_rejected->push_back(std::move(c));
      continue;
    }
    ++stats.area;
    std::vector<cv::Point2d> observed;
    for (const Blob& b : c.blobs) observed.push_back(b.centroid);
    const std::vector<cv::Point2d> ideal = camera.undistort(observed);
    for (int j = 0; j < n2; ++j) c.blobs[j].point = ideal[j];
    out.push_back(std::move(c));
  }
}

}  // namespace lftag::detail
