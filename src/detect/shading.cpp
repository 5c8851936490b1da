// SPDX-License-Identifier: LGPL-2.1-or-later
// The paper's light under a marker: a shadow across a marker darkens its paper and its ink
// alike, so the marker is read against the paper around each pixel rather than one level.
// The paper's level is the grey image closed (a dilation, then an erosion) by a square
// wider than the marker's darkest features, which fills them with the paper around them
// and keeps the edge of a shadow across the paper where it lies. Light comes from beyond
// the marker: a dim place of that level enclosed by brighter paper is the marker's own
// ink, widened by a blur past the square (a motion blur joins a baseline to the border's
// corner), and is filled with the paper around it.
#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {

// `level` with its basins filled: every place raised to the highest level at which a path
// of places no darker leads to the edge of the image (a grey-level reconstruction by
// erosion, by raster and anti-raster scans until nothing changes).
cv::Mat1b filled_basins(const cv::Mat1b& level) {
  if (level.empty()) return {};
  const int w = level.cols, h = level.rows;
  cv::Mat1b out(level.size(), 255);
  level.row(0).copyTo(out.row(0));
  level.row(h - 1).copyTo(out.row(h - 1));
  level.col(0).copyTo(out.col(0));
  level.col(w - 1).copyTo(out.col(w - 1));
  if (w <= 2 || h <= 2) return out;
  // One scan: each place lowered to its already scanned neighbours' least, never below
  // its own level.
  const auto scan = [&](int step) {
    bool changed = false;
    const int y0 = step > 0 ? 1 : h - 2, y1 = step > 0 ? h - 1 : 0;
    const int x0 = step > 0 ? 1 : w - 2, x1 = step > 0 ? w - 1 : 0;
    for (int y = y0; y != y1; y += step) {
      const std::uint8_t* scanned = out.ptr<std::uint8_t>(y - step);
      const std::uint8_t* own = level.ptr<std::uint8_t>(y);
      std::uint8_t* row = out.ptr<std::uint8_t>(y);
      for (int x = x0; x != x1; x += step) {
        const std::uint8_t before =
            std::min(std::min(scanned[x - 1], scanned[x]), std::min(scanned[x + 1], row[x - step]));
        const std::uint8_t v = std::max(own[x], std::min(row[x], before));
        if (v != row[x]) row[x] = v, changed = true;
      }
    }
    return changed;
  };
  for (bool changed = true; changed;) {
    const bool forward = scan(1), backward = scan(-1);
    changed = forward || backward;
  }
  return out;
}

cv::Mat1b paper_level(const cv::Mat& grey, int feature) {
  cv::Mat1b closed;
  cv::morphologyEx(grey, closed, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_RECT, cv::Size(feature, feature)));
  return closed;
}

std::optional<EvenLight> even_light(const ImageView& image, const std::array<cv::Point2d, 4>& outline,
                                    const Family& family) {
  const int side = family.side();
  const double per_unit = std::sqrt(std::abs(quad_area(outline))) / side;
  // Paper shows between the squares from gaps of 3.3 px on (kMinLocalPaperArea).
  if (!(per_unit >= 1.67)) return std::nullopt;
  // The darkest features: the baselines, 4 units; the border, 2.
  const int feature = int(std::ceil(5 * per_unit)) + 2;
  cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(outline.begin(), outline.end()));
  const int grow = std::max(feature, int(std::ceil(0.3 * std::max(box.width, box.height))));
  box = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) &
        cv::Rect(0, 0, image.width, image.height);
  if (box.width < feature || box.height < feature) return std::nullopt;
  const cv::Mat grey = image.mat()(box);
  cv::Mat1b paper = paper_level(grey, feature);
  // The paper's light on the white ring, all round its middle.
  std::array<cv::Point2f, 4> from, to;
  const std::array<cv::Point2d, 4> units = family.outer_corners();
  for (int i = 0; i < 4; ++i)
    from[std::size_t(i)] = cv::Point2f(units[std::size_t(i)]),
    to[std::size_t(i)] = cv::Point2f(outline[std::size_t(i)] - cv::Point2d(box.tl()));
  const cv::Matx33d h(cv::getPerspectiveTransform(from.data(), to.data()));
  std::vector<cv::Point2d> ring, at;
  for (int i = 0; i < side; ++i) {
    const double t = 3 + (side - 6) * (i + 0.5) / side;
    ring.insert(ring.end(), {{t, 3}, {side - 3.0, t}, {side - t, side - 3.0}, {3, side - t}});
  }
  cv::perspectiveTransform(ring, at, h);
  // Even when the ring's dimmest tenth is within kMinPaperSpread of its brightest (then
  // the marker is read as it is); `bright` is that brightest tenth.
  int bright = 0;
  const auto even = [&](const cv::Mat1b& level) {
    std::vector<int> light;
    for (const cv::Point2d& p : at) {
      const cv::Point q(cvRound(p.x), cvRound(p.y));
      if (q.x >= 0 && q.y >= 0 && q.x < level.cols && q.y < level.rows) light.push_back(level(q));
    }
    if (light.size() < 8) return true;
    std::sort(light.begin(), light.end());
    const int dim = light[light.size() / 10];
    bright = light[light.size() * 9 / 10];
    return dim >= kMinPaperSpread * bright || bright <= 0;
  };
  if (!light_varies(paper, even)) return std::nullopt;
  // Each pixel over the paper under it, brought to the lit paper's level.
  EvenLight out;
  out.origin = box.tl();
  cv::Mat1f ratio;
  grey.convertTo(ratio, CV_32F);
  cv::Mat1f level;
  paper.convertTo(level, CV_32F);
  cv::max(level, 1.0, level);
  ratio = ratio / level * double(bright);
  ratio.convertTo(out.pixels, CV_8U);
  out.paper = paper;
  return out;
}

}  // namespace lftag::detail
