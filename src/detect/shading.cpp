// SPDX-License-Identifier: LGPL-2.1-or-later
// The paper's light under a marker: a shadow across a marker darkens its paper and its ink
// alike, so the marker is read against the paper around each pixel rather than one level.
// The paper's level is the grey image closed (a dilation, then an erosion) by a square
// wider than the marker's darkest features, which fills them with the paper around them
// and keeps the edge of a shadow across the paper where it lies.
#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {

cv::Mat1b paper_level(const cv::Mat& grey, int feature) {
  cv::Mat1b out;
  cv::morphologyEx(grey, out, cv::MORPH_CLOSE, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(feature, feature)));
  return out;
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
  const cv::Mat1b paper = paper_level(grey, feature);
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
  std::vector<int> light;
  for (const cv::Point2d& p : at) {
    const cv::Point q(cvRound(p.x), cvRound(p.y));
    if (q.x >= 0 && q.y >= 0 && q.x < paper.cols && q.y < paper.rows) light.push_back(paper(q));
  }
  if (light.size() < 8) return std::nullopt;
  std::sort(light.begin(), light.end());
  const int dim = light[light.size() / 10], bright = light[light.size() * 9 / 10];
  if (dim >= kMinPaperSpread * bright || bright <= 0) return std::nullopt;  // evenly lit: read it as it is
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
  return out;
}

}  // namespace lftag::detail
