// SPDX-License-Identifier: LGPL-2.1-or-later
// A marker family n x n (n = 2..8): geometry in units and the id codec of SPEC section 1.
//
// Units: x right, y down, origin at the outer top-left corner of the black border.
// The n^2 black squares inside the marker are addressed by their grid index
// g = r * n + c (row r, column c). Cells 0 and n-1 are the two baseline squares;
// every other cell is a data cell whose 3 u square shifts by 1 u right and/or down
// to carry two bits of the id.
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/tag_id.hpp"

namespace lftag {

// An axis-aligned square or rectangle in marker units: top-left corner and size.
struct UnitRect {
  double x = 0, y = 0, width = 0, height = 0;
};

class Family {
 public:
  static constexpr int kMinN = 2;
  static constexpr int kMaxN = 8;

  // Throws std::invalid_argument unless 2 <= n <= 8.
  explicit Family(int n);
  // Parses "3x3" (also "3X3", and with spaces around it); throws std::invalid_argument
  // naming the accepted families.
  static Family parse(std::string_view name);
  // Parses a comma-separated list such as "3x3,4x4" or "3x3, 4X4"; duplicates are removed.
  static std::vector<Family> parse_list(std::string_view names);
  static std::vector<Family> all();

  int n() const { return n_; }
  std::string name() const;
  int side() const { return 6 * (n_ + 1); }  // S, the outer edge in units
  int cell_count() const { return n_ * n_; }
  int data_cell_count() const { return n_ * n_ - 2; }

  // Ids run from 0 to 4^(n^2-2) - 1.
  TagId max_id() const;
  std::string dictionary_size() const;  // decimal, exact
  bool contains(TagId id) const { return id <= max_id(); }
  // Throws std::out_of_range with a message naming the family and its largest id.
  void require(TagId id) const;

  bool is_baseline(int g) const { return g == 0 || g == n_ - 1; }
  int data_index(int g) const;       // the data cell number k of grid cell g, -1 for baselines
  int grid_index(int data_k) const;  // inverse of data_index

  // Baseline centre, or the middle of a data cell's four possible centres.
  cv::Point2d nominal_center(int g) const;
  // Centre of cell g when its data cell carries `digit` (ignored for baselines).
  cv::Point2d center(int g, int digit) const;
  UnitRect square(int g, int digit) const;

  // The n^2 centres / black squares of marker `id`, in grid order.
  std::vector<cv::Point2d> centers(TagId id) const;
  std::vector<UnitRect> black_squares(TagId id) const;
  // The marker as an S x S grid of unit cells: 0 black, 255 white. Every edge of the
  // design lies on the unit grid, so this bitmap *is* the vector geometry.
  cv::Mat1b unit_bitmap(TagId id) const;

  // Key points K0..K3 (SPEC 1): both baselines, then the bottom-left and bottom-right cells.
  std::array<int, 4> keypoint_cells() const { return {0, n_ - 1, n_ * (n_ - 1), n_ * n_ - 1}; }
  std::array<cv::Point2d, 4> keypoints(TagId id) const;

  // Outer corners of the black border, clockwise from the top-left: (0,0) (S,0) (S,S) (0,S).
  std::array<cv::Point2d, 4> outer_corners() const;
  // The inner (black-to-white) edge of the border: x, y in {2, S-2}, same order.
  std::array<cv::Point2d, 4> inner_corners() const;

  // A point in units expressed in the metric marker frame (SPEC 2): origin at the
  // marker centre, x right, y down, z into the marker; `tag_size` is the outer edge in metres.
  cv::Point3d to_marker_frame(cv::Point2d unit_point, double tag_size) const;

  friend bool operator==(const Family& a, const Family& b) { return a.n_ == b.n_; }
  friend bool operator!=(const Family& a, const Family& b) { return a.n_ != b.n_; }
  friend bool operator<(const Family& a, const Family& b) { return a.n_ < b.n_; }

 private:
  int n_;
};

}  // namespace lftag
