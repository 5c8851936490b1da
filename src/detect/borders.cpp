// SPDX-License-Identifier: LGPL-2.1-or-later
// Border proposals: where a marker's black border may lie, found as square markers are
// found, from the outer edge of the border against the paper around it. That edge is the
// strongest and lowest-frequency feature a printed marker has: it survives squares that
// touch each other or the border, a shadow across the inside, blur and compression, all
// of which break the topology the candidates stage needs. Each black region of a marker's
// size in the frame's binary image is a proposal when its convex hull is a quadrilateral
// and the grey levels along it show a dark band with paper outside and the white ring
// inside, and within that the cells' cores darker than the lines between them; the
// detector then looks at it as a second look would and reads it from its outline.
#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {
namespace {

// Mean and variance of samples, accumulated.
struct Moments {
  double sum = 0, sum2 = 0;
  int count = 0;
  void add(double v) { sum += v, sum2 += v * v, ++count; }
  double mean() const { return count ? sum / count : 0; }
  double variance() const { return count > 1 ? std::max(0.0, (sum2 - sum * sum / count) / (count - 1)) : 0; }
};

// A quadrilateral's points by their place in it: (u, v) in units of a marker of side
// `side` whose outer corners the quadrilateral's are (clockwise from the top left), by
// bilinear interpolation (and extrapolation, outside). Sampling bands along its sides,
// this is as good as the homography and costs no solve.
struct QuadPlace {
  std::array<cv::Point2d, 4> c;
  double side;
  cv::Point2d operator()(double u, double v) const {
    u /= side, v /= side;
    return c[0] * ((1 - u) * (1 - v)) + c[1] * (u * (1 - v)) + c[2] * (u * v) + c[3] * ((1 - u) * v);
  }
};

// The grey levels of a band along the four sides of the marker, from `from` to `to` units
// inwards of its outer edge (negative: outside), at `along` places on the middle four
// fifths of each side and `across` depths: per side, and all together.
struct Band {
  std::array<Moments, 4> side;
  Moments all;
};
Band band(const ImageView& image, const QuadPlace& at, double from, double to, int along, int across) {
  Band out;
  const double s = at.side;
  for (int i = 0; i < along; ++i) {
    const double t = s * (0.1 + 0.8 * (i + 0.5) / along);
    for (int j = 0; j < across; ++j) {
      const double d = from + (to - from) * (j + 0.5) / across;
      // Clockwise from the top: top, right, bottom, left.
      const std::array<cv::Point2d, 4> p = {at(t, d), at(s - d, t), at(s - t, s - d), at(d, s - t)};
      for (int k = 0; k < 4; ++k) {
        const double g = grey_at(image, p[std::size_t(k)]);
        out.side[std::size_t(k)].add(g);
        out.all.add(g);
      }
    }
  }
  return out;
}

// The marker's fixed structure inside its border, whatever its id: the white ring and
// the lines between the cells (mean grey level, midway between cores) and the cells'
// cores (the 2 x 2 units every position of a square covers).
std::pair<double, double> structure_levels(const ImageView& image, const QuadPlace& at, int n) {
  double white = 0, core = 0;
  int whites = 0, cores = 0;
  for (int r = 0; r < n; ++r) {
    const double across = 6 + 6 * r;
    for (int c = 0; c <= n; ++c) {  // the ring (c = 0, n) and the lines between cells
      const double between = 3 + 6 * c;
      white += grey_at(image, at(between, across)) + grey_at(image, at(across, between));
      whites += 2;
    }
    for (int c = 0; c < n; ++c)
      for (const double d : {-0.5, 0.5}) {
        core += grey_at(image, at(6 + 6 * c + d, across + d)) + grey_at(image, at(6 + 6 * c - d, across + d));
        cores += 2;
      }
  }
  return {white / whites, core / cores};
}

// The evidence of the bands along the sides, `along` places a side.
BorderEvidence evidence_at(const ImageView& image, const QuadPlace& at, int along) {
  // The margin a unit outside, the border's middle unit, the white ring's.
  const Band margin = band(image, at, -1.5, -0.5, along, 2), border = band(image, at, 0.5, 1.5, along, 2),
             ring = band(image, at, 2.5, 3.5, along, 2);
  BorderEvidence e;
  e.contrast = margin.all.mean() - border.all.mean();
  e.noise = std::sqrt((margin.all.variance() + border.all.variance()) / 2);
  e.ring = e.contrast > 0 ? (ring.all.mean() - border.all.mean()) / e.contrast : 0;
  for (int s = 0; s < 4; ++s) e.darker_sides += border.side[std::size_t(s)].mean() < margin.side[std::size_t(s)].mean();
  return e;
}

// A region's extreme pixels in eight directions: least and most x, y, x + y and x - y.
// They include every corner of a quadrilateral region, at any turn (each corner is the
// extreme of the directions within its 90 degrees), and cost one pass over the frame's
// runs for all regions together, where the hull of each region's runs cost a pass over
// its box.
struct Extremes {
  std::array<int, 8> value{std::numeric_limits<int>::max(), std::numeric_limits<int>::min(),
                           std::numeric_limits<int>::max(), std::numeric_limits<int>::min(),
                           std::numeric_limits<int>::max(), std::numeric_limits<int>::min(),
                           std::numeric_limits<int>::max(), std::numeric_limits<int>::min()};
  std::array<cv::Point, 8> at;
  // The run of pixels `first` .. `last` of one row.
  void add(cv::Point first, cv::Point last) {
    const auto low = [&](int k, int v, cv::Point p) {
      if (v < value[std::size_t(k)]) value[std::size_t(k)] = v, at[std::size_t(k)] = p;
    };
    const auto high = [&](int k, int v, cv::Point p) {
      if (v > value[std::size_t(k)]) value[std::size_t(k)] = v, at[std::size_t(k)] = p;
    };
    low(0, first.x, first), high(1, last.x, last), low(2, first.y, first), high(3, last.y, last);
    low(4, first.x + first.y, first), high(5, last.x + last.y, last);
    low(6, first.x - first.y, first), high(7, last.x - last.y, last);
  }
};

// The quadrilateral a region is, from its extreme pixels (centres): the largest
// quadrilateral of their convex hull, moved out by half a pixel to the pixels' outer
// edges; none when it covers under kMinQuadFill of the hull's area. Clockwise on screen.
std::optional<std::array<cv::Point2d, 4>> extremes_quad(const Extremes& e) {
  std::vector<cv::Point> points(e.at.begin(), e.at.end()), hull;
  cv::convexHull(points, hull);
  if (hull.size() < 4) return std::nullopt;
  const double hull_area = cv::contourArea(hull);
  if (!(hull_area > 0)) return std::nullopt;
  const std::vector<cv::Point2d> polygon(hull.begin(), hull.end());
  const std::optional<std::array<int, 4>> corners = largest_quad(polygon);
  if (!corners) return std::nullopt;
  std::array<cv::Point2d, 4> q;
  for (int i = 0; i < 4; ++i) q[std::size_t(i)] = polygon[std::size_t((*corners)[std::size_t(i)])];
  if (quad_area(q) < 0) std::reverse(q.begin(), q.end());
  if (std::abs(quad_area(q)) < kMinQuadFill * hull_area) return std::nullopt;
  const cv::Point2d centre = (q[0] + q[1] + q[2] + q[3]) / 4;
  for (cv::Point2d& p : q) {
    const cv::Point2d out = p - centre;
    p += out * (std::sqrt(0.5) / std::max(1.0, cv::norm(out)));
  }
  return q;
}

}  // namespace

std::optional<BorderEvidence> border_evidence(const ImageView& image, const std::array<cv::Point2d, 4>& corners,
                                              const Family& family) {
  if (!(std::abs(quad_area(corners)) > 0)) return std::nullopt;
  const QuadPlace at{corners, double(family.side())};
  // A few samples first: most black regions of a photo that get here are solid blobs,
  // with no white ring inside their edge.
  const BorderEvidence glance = evidence_at(image, at, 1);
  if (glance.darker_sides < 4 || glance.ring < kMinRingShare) return glance;
  BorderEvidence e = evidence_at(image, at, 8);
  if (e.contrast > 0) {
    const auto [white, core] = structure_levels(image, at, family.n());
    e.structure = (white - core) / e.contrast;
  }
  return e;
}

double BorderEvidence::clarity() const { return contrast / std::max(1.0, noise); }

bool BorderEvidence::plausible() const {
  return darker_sides == 4 && contrast >= kMinBorderSeparation * noise && ring >= kMinRingShare &&
         structure >= kMinStructure;
}

std::vector<BorderProposal> propose_borders(const RegionTree& tree, const ImageView& image, const SecondLook& look,
                                            const std::vector<Family>& families, const std::vector<cv::Rect>& taken,
                                            std::vector<BorderProposal>* refused) {
  std::vector<BorderProposal> out;
  // The regions of a border's size and fill, away from what was found.
  std::vector<int> slot(tree.regions.size(), -1), chosen;
  for (int r = 1; r < int(tree.regions.size()); ++r) {
    const Region& g = tree.regions[std::size_t(r)];
    if (!g.black) continue;
    const int w = g.x1 - g.x0 + 1, h = g.y1 - g.y0 + 1;
    if (std::max(w, h) < std::max(look.min_size, kMinBorderSize) || std::max(w, h) > look.max_size ||
        std::max(w, h) > 4 * std::min(w, h))
      continue;
    const double fill = double(g.area) / (double(w) * h);
    if (fill < kMinBorderFill || fill > kMaxBorderFill) continue;
    const cv::Rect box(g.x0, g.y0, w, h);
    if (std::any_of(taken.begin(), taken.end(), [&](const cv::Rect& t) { return (t & box).area() > 0; })) continue;
    slot[std::size_t(r)] = int(chosen.size());
    chosen.push_back(r);
  }
  if (chosen.empty()) return out;
  std::vector<Extremes> extremes(chosen.size());
  for_all_runs(tree, image.height, [&](int y, int x0, int x1, int region) {
    if (const int k = slot[std::size_t(region)]; k >= 0) extremes[std::size_t(k)].add({x0, y}, {x1 - 1, y});
  });
  for (std::size_t i = 0; i < chosen.size(); ++i) {
    const std::optional<std::array<cv::Point2d, 4>> quad = extremes_quad(extremes[i]);
    if (!quad) continue;
    const int r = chosen[i];
    BorderProposal p;
    p.corners = *quad;
    p.region = r;
    // The evidence kept: the clearest of the families the border passes for, or of all.
    std::optional<BorderEvidence> passing;
    for (const Family& f : families) {
      const std::optional<BorderEvidence> e = border_evidence(image, *quad, f);
      if (!e) continue;
      if (e->plausible()) {
        p.families.set(std::size_t(f.n()));
        if (!passing || e->clarity() > passing->clarity()) passing = e;
      }
      if (!p.evidence || e->clarity() > p.evidence->clarity()) p.evidence = e;
    }
    if (passing) p.evidence = passing;
    if (p.families.any())
      out.push_back(p);
    else if (refused && p.evidence)
      refused->push_back(p);
  }
  // The clearest borders first: what the frame's bound of outline reads leaves unread
  // is the least marker-like.
  std::stable_sort(out.begin(), out.end(), [](const BorderProposal& a, const BorderProposal& b) {
    return a.evidence->clarity() > b.evidence->clarity();
  });
  return out;
}

}  // namespace lftag::detail
