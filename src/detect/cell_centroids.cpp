// SPDX-License-Identifier: LGPL-2.1-or-later
// Cell centroids for the final pose: once the marker is decoded, each square's ink
// centroid is taken again from the grey image, over a window that the design gives it.
//
// The blob centroids that decoding used weigh a square's binary region and the pixels
// one pixel round it. Under defocus and JPEG a square's ink spreads further than that,
// and its region, cut by a threshold whose window holds the border's ink on one side and
// the marker's paler interior on the other, is not centred on it: the outer squares'
// centroids move inwards, the marker looks smaller and the pose puts it too far (0.42 %
// of the distance for a 60 px 3x3 under a defocus of 1.4 px and JPEG). The square grown
// by half a unit each way holds nearly all of its spread ink and little of its
// neighbours' (the gaps are at least two units). Its ink is weighed against the paper
// level of the ring half a unit further out, the middle of the narrowest gaps, measured
// where the square is, so that uneven light does not pull the centroid and a sharp
// square's anti-aliased edge counts whole: in the same conditions the bias is 0.02 %.
// A shadow's edge near a square is a step in the paper level that no one level fits: the
// shadowed paper in its window would count as ink. Where the candidate's paper level
// follows the light (paper_under, a shadow across the marker), each pixel's ink is taken
// against the paper under it instead (in the field experiment's shadows this took the
// median translation error on markers AprilTag also found from 0.42 / 0.30 % to 0.18 /
// 0.06 % for 3x3, tuning / validation).
#include <algorithm>
#include <array>
#include <cstdint>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {
namespace {

// Below this many pixels per unit the window's half unit is under 0.6 px, and which
// pixels it holds weighs more than the ink in them: the blobs' centroids are then better
// (measured on 22 to 40 px markers, with and without defocus).
constexpr double kMinPixelsPerUnit = 1.25;

// A unit rectangle grown by some units each way, in image pixels as observed (a convex
// quadrilateral), and the rows it covers.
struct Quad {
  std::array<cv::Point2d, 4> corners;
  int top = 0, bottom = -1;
  bool inside = false;            // wholly inside the image, and finite
  std::array<double, 4> slope{};  // of edge i (corner i to i + 1): x per row, 0 when level

  // The pixels x0..x1 (inclusive) of row y inside the quadrilateral (x1 < x0: none).
  std::pair<int, int> span(int y) const {
    double lo = 1e300, hi = -1e300;
    for (int i = 0; i < 4; ++i) {
      const cv::Point2d a = corners[i], b = corners[(i + 1) % 4];
      if ((a.y - y) * (b.y - y) > 0 || a.y == b.y) continue;  // the edge does not cross the row
      const double x = a.x + slope[i] * (y - a.y);
      lo = std::min(lo, x), hi = std::max(hi, x);
    }
    if (lo > hi) return {1, 0};
    return {int(std::ceil(lo)), int(std::floor(hi))};
  }
};

// The corners of unit rectangle `r` grown by `grow` units each way, under `homography`
// (units -> undistorted pixels), appended to `corners`.
void add_grown(const UnitRect& r, double grow, const cv::Matx33d& homography, std::vector<cv::Point2d>& corners) {
  for (const cv::Point2d u :
       {cv::Point2d(r.x - grow, r.y - grow), cv::Point2d(r.x + r.width + grow, r.y - grow),
        cv::Point2d(r.x + r.width + grow, r.y + r.height + grow), cv::Point2d(r.x - grow, r.y + r.height + grow)})
    corners.push_back(apply(homography, u));
}

// The quadrilateral of four corners as observed (distorted already).
Quad observed_quad(const cv::Point2d* corners, const ImageView& image) {
  Quad out;
  out.inside = true;
  double top = 1e300, bottom = -1e300;
  for (int i = 0; i < 4; ++i) {
    const cv::Point2d p = out.corners[i] = corners[i];
    out.inside &= p.x >= 0 && p.y >= 0 && p.x <= image.width - 1 && p.y <= image.height - 1;
    top = std::min(top, p.y), bottom = std::max(bottom, p.y);
  }
  for (int i = 0; i < 4; ++i) {
    const cv::Point2d a = corners[i], b = corners[(i + 1) % 4];
    if (a.y != b.y) out.slope[i] = (b.x - a.x) / (b.y - a.y);
  }
  if (out.inside) out.top = int(std::ceil(top)), out.bottom = int(std::floor(bottom));
  return out;
}

}  // namespace

std::vector<cv::Point2d> cell_centroids(const ImageView& image, const Camera& camera, const Family& family, TagId id,
                                        const cv::Matx33d& homography, const PaperLevel& paper_level,
                                        std::vector<CellInk>* inks, double grow, double ring_units, int stride) {
  const double side = family.side();
  if (!(smallest_scale(homography, {side / 2, side / 2}) >= kMinPixelsPerUnit)) return {};
  std::vector<cv::Point2d> out;
  if (inks) inks->clear();
  // Each square's window and the outer edge of its ring, distorted in one call (a call
  // per quadrilateral was a third of a tracked frame's time under lens distortion).
  std::vector<cv::Point2d> corners;
  corners.reserve(8 * std::size_t(family.cell_count()));
  for (int g = 0; g < family.cell_count(); ++g) {
    const UnitRect s = family.square(g, family.is_baseline(g) ? 0 : id.digit(family.data_index(g)));
    add_grown(s, grow, homography, corners);
    add_grown(s, grow + ring_units, homography, corners);
  }
  distort(camera, corners);
  std::vector<std::pair<int, int>> spans;  // the window's, on the rows the ring's count visits
  for (int g = 0; g < family.cell_count(); ++g) {
    const Quad window = observed_quad(&corners[8 * std::size_t(g)], image);
    const Quad paper = observed_quad(&corners[8 * std::size_t(g) + 4], image);
    // A window cut by the frame's edge would lose ink on one side.
    if (!window.inside || !paper.inside) return {};

    // The paper level: the median grey of the ring between the two.
    std::array<int, 256> ring{};
    int ring_size = 0;
    spans.assign(std::size_t(std::max(0, window.bottom - window.top + 1)), {1, 0});
    for (int y = paper.top; y <= paper.bottom; y += stride) {
      const auto [a, b] = paper.span(y);
      const auto [wa, wb] = window.span(y);
      if (y >= window.top && y <= window.bottom) spans[std::size_t(y - window.top)] = {wa, wb};
      const std::uint8_t* row = image.data + y * image.stride;
      const auto count = [&](int from, int to) {
        for (int x = from; x <= to; x += stride) ++ring[row[x]], ++ring_size;
      };
      if (wa > wb) {  // the window misses the row
        count(a, b);
      } else {
        count(a, std::min(b, wa - 1));
        count(std::max(a, wb + 1), b);
      }
    }
    if (ring_size == 0) return {};
    int white = 0, below = ring[0];
    while (2 * below <= ring_size) below += ring[++white];

    // (The window lies within its ring's rows unless the lens folds them.)
    const bool cached = window.top >= paper.top && window.bottom <= paper.bottom;
    double m = 0, mx = 0, my = 0;
    const int first = window.top + ((paper.top - window.top) % stride + stride) % stride;  // a row the ring's visits
    for (int y = first; y <= window.bottom; y += stride) {
      const auto [a, b] = cached ? spans[std::size_t(y - window.top)] : window.span(y);
      const std::uint8_t* row = image.data + y * image.stride;
      if (!paper_level.local.empty()) {  // a shadow: each pixel against the paper under it
        double row_m = 0, row_mx = 0;
        for (int x = a; x <= b; x += stride) {
          const double ink = paper_level.ink(x, y, row[x]);
          row_m += ink, row_mx += ink * x;
        }
        m += row_m, mx += row_mx, my += row_m * y;
        continue;
      }
      std::int64_t row_m = 0, row_mx = 0;
      for (int x = a; x <= b; x += stride) {
        const int ink = std::max(0, white - row[x]);
        row_m += ink, row_mx += std::int64_t(ink) * x;
      }
      m += double(row_m), mx += double(row_mx), my += double(row_m) * y;
    }
    if (m <= 0) return {};
    out.emplace_back(mx / m, my / m);
    if (inks) inks->push_back({m, double(white)});
  }
  return out;
}

}  // namespace lftag::detail
