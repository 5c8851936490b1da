// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/family.hpp"

#include <algorithm>
#include <stdexcept>

namespace lftag {

Family::Family(int n) : n_(n) {
  if (n < kMinN || n > kMaxN)
    throw std::invalid_argument("unknown family " + std::to_string(n) + "x" + std::to_string(n) +
                                ": families are 2x2 to 8x8");
}

Family Family::parse(std::string_view name) {
  // The obvious spellings too: " 4x4" (after a comma and a space) and "4X4".
  std::string_view text = name;
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  if (text.size() == 3 && (text[1] == 'x' || text[1] == 'X') && text[0] == text[2] && text[0] >= '2' && text[0] <= '8')
    return Family(text[0] - '0');
  throw std::invalid_argument("unknown family '" + std::string(name) +
                              "': expected one of 2x2, 3x3, 4x4, 5x5, 6x6, 7x7, 8x8");
}

std::vector<Family> Family::parse_list(std::string_view names) {
  std::vector<Family> out;
  std::size_t start = 0;
  while (start <= names.size()) {
    const std::size_t comma = std::min(names.find(',', start), names.size());
    Family f = parse(names.substr(start, comma - start));
    if (std::find(out.begin(), out.end(), f) == out.end()) out.push_back(f);
    start = comma + 1;
  }
  return out;
}

std::vector<Family> Family::all() {
  std::vector<Family> out;
  for (int n = kMinN; n <= kMaxN; ++n) out.emplace_back(n);
  return out;
}

std::string Family::name() const { return std::to_string(n_) + "x" + std::to_string(n_); }

TagId Family::max_id() const {
  const int bits = 2 * data_cell_count();  // at most 124
  if (bits > 64) return TagId(~std::uint64_t{0} >> (128 - bits), ~std::uint64_t{0});
  return TagId(bits == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << bits) - 1);  // a shift by 64 is undefined
}

std::string Family::dictionary_size() const {
  // 4^(n^2-2) = max_id + 1, which never overflows 128 bits (at most 2^124).
  const TagId m = max_id();
  const std::uint64_t lo = m.low() + 1;
  return TagId(m.high() + (lo == 0 ? 1 : 0), lo).to_decimal();
}

void Family::require(TagId id) const {
  if (!contains(id))
    throw std::out_of_range("id " + id.to_decimal() + " is out of range for family " + name() + ": ids run from 0 to " +
                            max_id().to_decimal());
}

int Family::data_index(int g) const {
  if (g < 0 || g >= cell_count()) throw std::out_of_range("cell index out of range");
  if (is_baseline(g)) return -1;
  return g < n_ ? g - 1 : g - 2;  // skip the baseline cells (0, 0) and (0, n-1)
}

int Family::grid_index(int data_k) const {
  if (data_k < 0 || data_k >= data_cell_count()) throw std::out_of_range("data cell index out of range");
  return data_k < n_ - 2 ? data_k + 1 : data_k + 2;
}

cv::Point2d Family::nominal_center(int g) const { return {6.0 + 6.0 * (g % n_), 6.0 + 6.0 * (g / n_)}; }

UnitRect Family::square(int g, int digit) const {
  const int r = g / n_, c = g % n_;
  if (is_baseline(g)) return {4.0 + 6.0 * c, 4.0, 4.0, 4.0};
  // Bit 0 moves the square down by 1 u, bit 1 moves it right by 1 u.
  return {4.0 + 6.0 * c + (digit >> 1), 4.0 + 6.0 * r + (digit & 1), 3.0, 3.0};
}

cv::Point2d Family::center(int g, int digit) const {
  const UnitRect s = square(g, digit);
  return {s.x + s.width / 2, s.y + s.height / 2};
}

std::vector<cv::Point2d> Family::centers(TagId id) const {
  require(id);
  std::vector<cv::Point2d> out;
  for (int g = 0; g < cell_count(); ++g) out.push_back(center(g, is_baseline(g) ? 0 : id.digit(data_index(g))));
  return out;
}

std::vector<UnitRect> Family::black_squares(TagId id) const {
  require(id);
  std::vector<UnitRect> out;
  for (int g = 0; g < cell_count(); ++g) out.push_back(square(g, is_baseline(g) ? 0 : id.digit(data_index(g))));
  return out;
}

cv::Mat1b Family::unit_bitmap(TagId id) const {
  const int s = side();
  cv::Mat1b bitmap(s, s, uchar(0));
  bitmap(cv::Rect(2, 2, s - 4, s - 4)).setTo(255);
  for (const UnitRect& r : black_squares(id))
    bitmap(cv::Rect(int(r.x), int(r.y), int(r.width), int(r.height))).setTo(0);
  return bitmap;
}

std::array<cv::Point2d, 4> Family::keypoints(TagId id) const {
  const std::vector<cv::Point2d> c = centers(id);
  const std::array<int, 4> cells = keypoint_cells();
  return {c[cells[0]], c[cells[1]], c[cells[2]], c[cells[3]]};
}

std::array<cv::Point2d, 4> Family::outer_corners() const {
  const double s = side();
  return {cv::Point2d(0, 0), cv::Point2d(s, 0), cv::Point2d(s, s), cv::Point2d(0, s)};
}

std::array<cv::Point2d, 4> Family::inner_corners() const {
  const double a = 2, b = side() - 2;
  return {cv::Point2d(a, a), cv::Point2d(b, a), cv::Point2d(b, b), cv::Point2d(a, b)};
}

cv::Point3d Family::to_marker_frame(cv::Point2d p, double tag_size) const {
  const double half = side() / 2.0, scale = tag_size / side();
  return {(p.x - half) * scale, (p.y - half) * scale, 0.0};
}

}  // namespace lftag
