// SPDX-License-Identifier: LGPL-2.1-or-later
// Exact area coverage for axis-aligned cell grids: the coverage of a pixel by a cell is
// the product of their overlaps along x and along y, so resampling is two small matrix
// products, W_y * cells * W_x^T.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "lftag/render.hpp"

namespace lftag {
namespace {

// Overlap of pixel i ([i - 0.5, i + 0.5]) with cell j ([origin + j s, origin + (j + 1) s]).
cv::Mat1f overlap_weights(int pixels, int cells, double pixels_per_cell, double origin) {
  cv::Mat1f w(pixels, cells, 0.0f);
  for (int j = 0; j < cells; ++j) {
    const double c0 = origin + j * pixels_per_cell, c1 = c0 + pixels_per_cell;
    const int first = std::max(0, int(std::floor(c0 + 0.5)));
    const int last = std::min(pixels - 1, int(std::ceil(c1 - 0.5)));
    for (int i = first; i <= last; ++i) w(i, j) = float(std::max(0.0, std::min(c1, i + 0.5) - std::max(c0, i - 0.5)));
  }
  return w;
}

}  // namespace

cv::Mat1f resample_cells(const cv::Mat1f& cells, cv::Size image_size, double pixels_per_cell, cv::Point2d origin,
                         float outside) {
  if (cells.empty()) throw std::invalid_argument("resample_cells: no cells");
  if (image_size.width <= 0 || image_size.height <= 0)
    throw std::invalid_argument("resample_cells: the image size must be positive");
  if (!(pixels_per_cell > 0)) throw std::invalid_argument("resample_cells: the scale must be positive");
  const cv::Mat1f wx = overlap_weights(image_size.width, cells.cols, pixels_per_cell, origin.x);
  const cv::Mat1f wy = overlap_weights(image_size.height, cells.rows, pixels_per_cell, origin.y);
  cv::Mat1f image = wy * cells * wx.t();
  // Where the grid covers only part of a pixel, the rest shows `outside`.
  cv::Mat1f cover_x, cover_y;
  cv::reduce(wx, cover_x, 1, cv::REDUCE_SUM);
  cv::reduce(wy, cover_y, 1, cv::REDUCE_SUM);
  const cv::Mat1f coverage = cover_y * cover_x.t();
  image += outside * (1.0f - coverage);
  return image;
}

cv::Mat1b rasterize_marker(const Family& family, TagId id, double pixels_per_unit, double margin_units) {
  if (!(pixels_per_unit > 0)) throw std::invalid_argument("pixels per unit must be positive");
  if (!(margin_units >= 0)) throw std::invalid_argument("the margin must not be negative");
  cv::Mat1f cells;
  family.unit_bitmap(id).convertTo(cells, CV_32F, 1.0 / 255);
  const double side_px = std::ceil((family.side() + 2 * margin_units) * pixels_per_unit - 1e-9);
  if (!(side_px <= 1 << 16)) throw std::invalid_argument("the marker image would pass 65536 pixels a side");
  const int side = int(side_px);
  const double origin = margin_units * pixels_per_unit - 0.5;
  const cv::Mat1f image =
      resample_cells(cells, cv::Size(side, side), pixels_per_unit, cv::Point2d(origin, origin), 1.0f);
  cv::Mat1b out;
  image.convertTo(out, CV_8U, 255.0);
  return out;
}

}  // namespace lftag
