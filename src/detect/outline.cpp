// SPDX-License-Identifier: LGPL-2.1-or-later
// The outline reading: markers whose squares no binary image separates (far, blurred) are
// read from their grey levels once their outline is known.
//
// Whatever the id, a marker has a fixed structure: the black border, the white ring inside
// it, the white lines between the cells and, in every cell, a dark core (the 2 x 2 units
// that each of the square's four positions covers). Only the one-unit strips beside each
// core change with the data. A template of that structure (the strips left grey, blurred
// to the frame's resolution) is aligned to the frame by ECC (OpenCV's findTransformECC, a
// homography), starting from the coarse outline of a second look's binary patch. The
// corners whose four strips are all dark are the baselines, which fixes the turn; then
// each data cell's square position is the one whose blurred model fits the cell's grey
// levels best. Every check is measured against the marker's own levels and units, so it
// means the same at every size and under every blur.
#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "stages.hpp"

namespace lftag::detail {
namespace {

constexpr double kTemplateScale = 3;  // template pixels per unit
constexpr double kRing = 1;           // units of the white margin the template assumes outside

// The fixed structure along one axis of the marker: 0 black, 1 white, 0.5 a data strip.
double axis_class(double u, int side) {
  if (u < 0 || u >= side) return 1;  // the margin
  if (u < 2 || u >= side - 2) return 0;  // the border
  if (u < 4) return 1;                   // the white ring
  const double v = std::fmod(u - 4, 6);  // within a cell's 6-unit pitch
  if (v >= 4) return 1;                  // the lines between cells, and the ring
  if (v >= 1 && v < 3) return 0;         // the core
  return 0.5;
}

double structure(double x, double y, int side) {
  const double cx = axis_class(x, side), cy = axis_class(y, side);
  if (x < 0 || y < 0 || x >= side || y >= side) return 1;
  if (cx == 0 && (x < 2 || x >= side - 2)) return 0;  // border columns
  if (cy == 0 && (y < 2 || y >= side - 2)) return 0;  // border rows
  if (cx == 1 || cy == 1) return 1;
  if (cx == 0 && cy == 0) return 0;
  return 0.5;
}

cv::Mat1f structure_template(const Family& family) {
  const int side = family.side();
  const int size = int(std::lround((side + 2 * kRing) * kTemplateScale));
  cv::Mat1f t(size, size);
  constexpr int kSub = 3;  // supersampling per template pixel and axis
  for (int i = 0; i < size; ++i)
    for (int j = 0; j < size; ++j) {
      double sum = 0;
      for (int a = 0; a < kSub; ++a)
        for (int b = 0; b < kSub; ++b)
          sum += structure((j + (b + 0.5) / kSub) / kTemplateScale - kRing,
                           (i + (a + 0.5) / kSub) / kTemplateScale - kRing, side);
      t(i, j) = float(sum / (kSub * kSub));
    }
  return t;
}

// The marker `id` itself, drawn as the structure is (white outside).
cv::Mat1f marker_template(const Family& family, TagId id) {
  const int ring = int(kRing);
  cv::Mat1b units(family.side() + 2 * ring, family.side() + 2 * ring, std::uint8_t(255));
  family.unit_bitmap(id).copyTo(units(cv::Rect(ring, ring, family.side(), family.side())));
  cv::Mat1f t;
  units.convertTo(t, CV_32F, 1.0 / 255);
  // Whole template pixels per unit, so unit edges fall on pixel edges.
  cv::resize(t, t, cv::Size(), kTemplateScale, kTemplateScale, cv::INTER_NEAREST);
  return t;
}

// The correlation of `templ` with the image warped by `warp` (template -> image pixels).
double correlation_at(const cv::Mat1f& image, const cv::Mat& warp, const cv::Mat1f& templ) {
  cv::Mat1f seen;
  cv::warpPerspective(image, seen, warp, templ.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_REPLICATE);
  cv::Scalar mean_seen, sd_seen, mean_templ, sd_templ;
  cv::meanStdDev(seen, mean_seen, sd_seen);
  cv::meanStdDev(templ, mean_templ, sd_templ);
  if (sd_seen[0] <= 0 || sd_templ[0] <= 0) return 0;
  return cv::mean((seen - mean_seen[0]).mul(templ - mean_templ[0]))[0] / (sd_seen[0] * sd_templ[0]);
}

// Units -> template pixels (pixel centres at whole numbers).
cv::Matx33d unit_to_template() {
  const double o = kRing * kTemplateScale - 0.5;
  return {kTemplateScale, 0, o, 0, kTemplateScale, o, 0, 0, 1};
}

cv::Point2d apply(const cv::Matx33d& h, cv::Point2d p) {
  const cv::Vec3d q = h * cv::Vec3d(p.x, p.y, 1);
  return {q[0] / q[2], q[1] / q[2]};
}

// Mean grey level over the unit rectangle [x, x + w) x [y, y + h) under h.
double mean_level(const ImageView& image, const cv::Matx33d& h, double x, double y, double w, double hh) {
  constexpr double kStep = 0.25;
  double sum = 0;
  int count = 0;
  for (double v = y + kStep / 2; v < y + hh; v += kStep)
    for (double u = x + kStep / 2; u < x + w; u += kStep) sum += grey_at(image, apply(h, {u, v})), ++count;
  return count ? sum / count : 0;
}

// The marker turned by 90 degrees k times clockwise about its centre: true units ->
// aligned units.
cv::Matx33d turn(int k, int side) {
  cv::Matx33d r = cv::Matx33d::eye();
  for (int i = 0; i < k; ++i) r = cv::Matx33d(0, -1, side, 1, 0, 0, 0, 0, 1) * r;
  return r;
}

struct CellLevels {
  double low_x, high_x, low_y, high_y, core;
};

CellLevels cell_levels(const ImageView& image, const cv::Matx33d& h, int r, int c) {
  const double x = 4 + 6 * c, y = 4 + 6 * r;
  return {mean_level(image, h, x, y + 1, 1, 2), mean_level(image, h, x + 3, y + 1, 1, 2),
          mean_level(image, h, x + 1, y, 2, 1), mean_level(image, h, x + 1, y + 3, 2, 1),
          mean_level(image, h, x + 1, y + 1, 2, 2)};
}

// A data cell's grey levels on a regular grid of unit points over every position its
// square can take, with half of the gaps around.
constexpr int kCellGrid = 20;  // per axis, 0.25 u apart over [3.5, 8.5) of the cell
constexpr int kCellSamples = kCellGrid * kCellGrid;
struct CellSamples {
  std::array<double, kCellSamples> grey;
};

double grid_coordinate(int i) { return 3.5 + (i + 0.5) * 0.25; }

CellSamples sample_cell(const ImageView& image, const cv::Matx33d& h, int r, int c) {
  CellSamples s;
  for (int i = 0; i < kCellGrid; ++i)
    for (int j = 0; j < kCellGrid; ++j)
      s.grey[i * kCellGrid + j] = grey_at(image, apply(h, {6.0 * c + grid_coordinate(j), 6.0 * r + grid_coordinate(i)}));
  return s;
}

struct CellFit {
  int digit = 0;
  double rss = 0, runner_up_rss = 0;  // residual sums of squares of the best and second digits
  double ink = 0;                     // the best model's paper minus ink level
};

// Fits grey = paper - ink * coverage for each of the four square positions, the
// coverage being the 3 u square blurred by a Gaussian of `sigma` units.
CellFit fit_cell(const CellSamples& cell, double sigma) {
  // Coverage along one axis of a square starting at unit `start`, at each grid coordinate.
  const auto profile = [&](double start) {
    std::array<double, kCellGrid> p;
    for (int i = 0; i < kCellGrid; ++i) {
      const double t = grid_coordinate(i) - start;
      p[i] = 0.5 * (std::erf(t / (sigma * std::sqrt(2.0))) - std::erf((t - 3) / (sigma * std::sqrt(2.0))));
    }
    return p;
  };
  const std::array<std::array<double, kCellGrid>, 2> at = {profile(4), profile(5)};
  double mean = 0;
  for (double g : cell.grey) mean += g;
  mean /= kCellSamples;
  double sgg = 0;
  for (double g : cell.grey) sgg += (g - mean) * (g - mean);
  std::array<double, 4> rss, ink;
  for (int digit = 0; digit < 4; ++digit) {
    const auto& px = at[digit >> 1];
    const auto& py = at[digit & 1];
    double sc = 0, scc = 0, sgc = 0;
    for (int i = 0; i < kCellGrid; ++i)
      for (int j = 0; j < kCellGrid; ++j) {
        const double cov = px[j] * py[i], g = cell.grey[i * kCellGrid + j] - mean;
        sc += cov, scc += cov * cov, sgc += g * cov;
      }
    const double var = scc - sc * sc / kCellSamples;  // sgc is centred already through g
    ink[digit] = var > 0 ? -sgc / var : 0;
    rss[digit] = ink[digit] > 0 ? sgg - sgc * sgc / var : sgg;
  }
  CellFit fit;
  fit.digit = int(std::min_element(rss.begin(), rss.end()) - rss.begin());
  fit.rss = rss[fit.digit];
  fit.runner_up_rss = std::numeric_limits<double>::infinity();
  for (int d = 0; d < 4; ++d)
    if (d != fit.digit) fit.runner_up_rss = std::min(fit.runner_up_rss, rss[d]);
  fit.ink = ink[fit.digit];
  return fit;
}

// The id read from the data cells under homography h (true turn), and the least margin
// of its cells (see OutlineReading::margin).
std::pair<TagId, double> read_cells(const ImageView& image, const cv::Matx33d& h, const Family& family,
                                    double pixels_per_unit, double contrast) {
  const int n = family.n();
  // Each data cell's digit: the square position whose blurred model fits the cell's grey
  // levels best (least squares, with the cell's own paper and ink levels), at the blur that
  // fits the whole marker best.
  std::vector<CellSamples> cells;
  for (int g = 0; g < family.cell_count(); ++g)
    if (!family.is_baseline(g)) cells.push_back(sample_cell(image, h, g / n, g % n));
  std::vector<CellFit> fits, best_fits;
  double best_rss = std::numeric_limits<double>::infinity();
  for (const double blur : {0.3, 0.6, 1.0, 1.5, 2.2}) {
    const double sigma = std::max(blur, 0.4 / std::max(pixels_per_unit, 1e-3));
    fits.clear();
    double rss = 0;
    for (const CellSamples& cell : cells) rss += fits.emplace_back(fit_cell(cell, sigma)).rss;
    if (rss < best_rss) best_rss = rss, best_fits = fits;
  }
  TagId id;
  double margin = 1e9;
  int k = 0;
  for (int g = 0; g < family.cell_count(); ++g) {
    if (family.is_baseline(g)) continue;
    const CellFit& fit = best_fits[k++];
    // How much worse the runner-up fits, per sample, in units of the marker's contrast.
    const double m = (fit.runner_up_rss - fit.rss) / (kCellSamples * contrast * contrast);
    margin = std::min(margin, fit.ink > 0.4 * contrast ? m : 0.0);
    id = id.with_digit(family.data_index(g), fit.digit);
  }
  return {id, margin};
}

}  // namespace

std::vector<std::array<cv::Point2d, 4>> coarse_outlines(const BinaryImage& binary, const PatchFrame& frame) {
  // The black pieces of each white region (a far marker's border breaks up on the
  // diagonals) that do not reach the patch's edge; a background darker than the margin
  // can leave a ring of its own around the marker's margin, so more than one group is kept.
  cv::Mat1b black = binary.to_mat();
  std::vector<std::vector<cv::Point>> contours;
  std::vector<cv::Vec4i> hierarchy;  // next, previous, first child, parent
  cv::findContours(black, contours, hierarchy, cv::RETR_TREE, cv::CHAIN_APPROX_SIMPLE);
  const cv::Rect inner(1, 1, black.cols - 2, black.rows - 2);
  const auto depth = [&](int i) {
    int d = 0;
    for (; hierarchy[i][3] >= 0; i = hierarchy[i][3]) ++d;
    return d;
  };
  std::vector<std::pair<double, std::vector<cv::Point>>> hulls;  // area, hull
  std::vector<cv::Point> points;
  for (int i = 0; i < int(contours.size()); ++i) {
    // Outer boundaries of black pieces are at even depths; visit each parent's group once.
    if (depth(i) % 2 != 0 || hierarchy[i][1] >= 0) continue;
    points.clear();
    for (int j = i; j >= 0; j = hierarchy[j][0]) {
      const cv::Rect r = cv::boundingRect(contours[j]);
      if ((r & inner) != r) continue;
      points.insert(points.end(), contours[j].begin(), contours[j].end());
    }
    if (points.size() < 4) continue;
    std::vector<cv::Point> hull;
    cv::convexHull(points, hull);
    hulls.emplace_back(cv::contourArea(hull), std::move(hull));
  }
  std::sort(hulls.begin(), hulls.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<std::array<cv::Point2d, 4>> out;
  for (const auto& [area, hull] : hulls) {
    if (out.size() == 3 || area < 16) break;
    std::vector<cv::Point> quad;
    const double perimeter = cv::arcLength(hull, true);
    for (double f = 0.02; f <= 0.2 && quad.size() != 4; f += 0.02) cv::approxPolyDP(hull, quad, f * perimeter, true);
    if (quad.size() != 4 || !cv::isContourConvex(quad)) continue;
    std::array<cv::Point2d, 4> corners;
    for (int i = 0; i < 4; ++i) corners[i] = frame.to_frame(cv::Point2d(quad[i]));
    // Clockwise on screen (y down): positive shoelace sum.
    double twice_area = 0;
    for (int i = 0; i < 4; ++i)
      twice_area += corners[i].x * corners[(i + 1) % 4].y - corners[(i + 1) % 4].x * corners[i].y;
    if (twice_area < 0) std::reverse(corners.begin(), corners.end());
    out.push_back(corners);
  }
  return out;
}

std::optional<OutlineReading> read_outline(const ImageView& image, const std::array<cv::Point2d, 4>& outline,
                                           const Family& family) {
  const int side = family.side();
  // The frame around the outline, with room for the alignment to move.
  std::vector<cv::Point2f> corners(outline.begin(), outline.end());
  cv::Rect box = cv::boundingRect(corners);
  const int grow = std::max(3, int(std::ceil(3.0 * std::max(box.width, box.height) / side)));
  box = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) &
        cv::Rect(0, 0, image.width, image.height);
  if (box.width < 8 || box.height < 8) return std::nullopt;
  // Pixels per unit: small markers are enlarged to about two (bicubic, as the patches are,
  // where the alignment's own bilinear sampling breaks a diagonal border into dots), and
  // the template is blurred to the resolution of the frame's pixels.
  double twice_area = 0;
  for (int i = 0; i < 4; ++i)
    twice_area += outline[i].x * outline[(i + 1) % 4].y - outline[(i + 1) % 4].x * outline[i].y;
  const double per_unit = std::sqrt(std::abs(twice_area) / 2) / side;
  if (!(per_unit >= 0.2)) return std::nullopt;  // half the readable resolution, or degenerate
  const int enlarge = std::clamp(int(std::ceil(2 / per_unit)), 1, 4);
  cv::Mat1f crop;
  image.mat()(box).convertTo(crop, CV_32F, 1.0 / 255);
  if (enlarge > 1) cv::resize(crop, crop, cv::Size(), enlarge, enlarge, cv::INTER_CUBIC);
  // Enlarged crop pixels -> frame pixels.
  const cv::Matx33d to_frame(1.0 / enlarge, 0, 0.5 / enlarge - 0.5 + box.x, 0, 1.0 / enlarge,
                             0.5 / enlarge - 0.5 + box.y, 0, 0, 1);

  // The sharp template of each family is drawn once per thread.
  thread_local std::array<cv::Mat1f, Family::kMaxN + 1> sharp;
  if (sharp[family.n()].empty()) sharp[family.n()] = structure_template(family);
  cv::Mat1f templ = sharp[family.n()].clone();
  const double sigma = 0.4 / per_unit * kTemplateScale;  // template pixels
  if (sigma > 0.3) cv::GaussianBlur(templ, templ, cv::Size(), sigma);
  const cv::Matx33d to_template = unit_to_template();
  const cv::Matx33d from_frame = to_frame.inv();
  std::vector<cv::Point2f> from, to;
  const std::array<cv::Point2d, 4> unit_corners = family.outer_corners();
  for (int i = 0; i < 4; ++i) {
    const cv::Point2d t = apply(to_template, unit_corners[i]), c = apply(from_frame, outline[i]);
    from.emplace_back(float(t.x), float(t.y));
    to.emplace_back(float(c.x), float(c.y));
  }
  cv::Mat warp = cv::getPerspectiveTransform(from, to);
  warp.convertTo(warp, CV_32F);
  // Most outlines in photos are no marker: the structure's correlation where the outline
  // puts it (about 0.6 to 0.9 for markers, under 0.3 for nearly every other outline)
  // spares them the alignment.
  if (correlation_at(crop, warp, templ) < kMinStartCorrelation) return std::nullopt;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 25, 1e-4);
  double correlation = 0;
  try {
    correlation = cv::findTransformECC(templ, crop, warp, cv::MOTION_HOMOGRAPHY, criteria, cv::noArray(), 3);
  } catch (const cv::Exception&) {
    return std::nullopt;  // did not converge: not a marker's structure
  }
  cv::Matx33d w;
  cv::Mat(warp).convertTo(cv::Mat(3, 3, CV_64F, w.val), CV_64F);
  const cv::Matx33d aligned = to_frame * w * to_template;  // units (some turn) -> frame pixels
  if (!std::isfinite(aligned(2, 2)) || std::abs(aligned(2, 2)) < 1e-12) return std::nullopt;

  OutlineReading out;
  out.correlation = correlation;
  out.pixels_per_unit = smallest_scale(aligned, {side / 2.0, side / 2.0});
  // Its black and white: the cores, and the middle of the white ring.
  double black = 0, white = 0;
  std::vector<std::vector<CellLevels>> levels(family.n(), std::vector<CellLevels>(family.n()));
  for (int r = 0; r < family.n(); ++r)
    for (int c = 0; c < family.n(); ++c) black += (levels[r][c] = cell_levels(image, aligned, r, c)).core;
  black /= family.cell_count();
  white = (mean_level(image, aligned, 2.5, 2.5, side - 5, 1) + mean_level(image, aligned, 2.5, side - 3.5, side - 5, 1) +
           mean_level(image, aligned, 2.5, 3.5, 1, side - 7) + mean_level(image, aligned, side - 3.5, 3.5, 1, side - 7)) /
          4;
  out.contrast = white - black;
  if (out.contrast <= 0) return std::nullopt;
  const auto level = [&](double g) { return (g - black) / out.contrast; };
  // A baseline square covers both strips of both axes: its brightest strip is dark.
  const auto baseline_likeness = [&](const CellLevels& l) {
    return 1 - level(std::max({l.low_x, l.high_x, l.low_y, l.high_y}));
  };
  const int n = family.n();
  const std::array<double, 4> corner = {baseline_likeness(levels[0][0]), baseline_likeness(levels[0][n - 1]),
                                        baseline_likeness(levels[n - 1][n - 1]),
                                        baseline_likeness(levels[n - 1][0])};  // clockwise
  // The turn whose top corners are most like baselines, and by how much they are.
  int best = -1;
  double best_gap = -1;
  for (int k = 0; k < 4; ++k) {
    const double pair = std::min(corner[k], corner[(k + 1) % 4]);
    const double others = std::max(corner[(k + 2) % 4], corner[(k + 3) % 4]);
    if (pair - others > best_gap) best_gap = pair - others, best = k;
  }
  out.baseline_gap = best_gap;
  // Aligned corner `best` (clockwise from the aligned top-left) is the true top-left.
  const cv::Matx33d h = aligned * turn(best, side);
  out.homography = h;
  // Each data cell's digit: the square position whose blurred model fits the cell's grey
  // levels best (least squares, with the cell's own paper and ink levels), at the blur that
  // fits the whole marker best.
  const auto [id, margin] = read_cells(image, h, family, out.pixels_per_unit, out.contrast);
  out.margin = margin;
  out.id = id;

  // The final homography: the whole marker of that id, every square in place, aligned
  // again from there; it must fit as well as the structure did.
  cv::Mat1f whole = marker_template(family, id);
  if (sigma > 0.3) cv::GaussianBlur(whole, whole, cv::Size(), sigma);
  const cv::Matx33d start = from_frame * h * to_template.inv();
  cv::Mat refined(3, 3, CV_32F);
  for (int i = 0; i < 9; ++i) refined.at<float>(i / 3, i % 3) = float(start.val[i] / start.val[8]);
  try {
    out.marker_correlation = cv::findTransformECC(whole, crop, refined, cv::MOTION_HOMOGRAPHY, criteria, cv::noArray(), 3);
  } catch (const cv::Exception&) {
    return out;  // the structure's homography stands; marker_correlation 0 fails the checks
  }
  cv::Mat(refined).convertTo(cv::Mat(3, 3, CV_64F, w.val), CV_64F);
  const cv::Matx33d final_h = to_frame * w * to_template;
  if (!std::isfinite(final_h(2, 2)) || std::abs(final_h(2, 2)) < 1e-12) {
    out.marker_correlation = 0;
    return out;
  }
  out.homography = final_h;
  // Read again under the final homography: a reading at the edge of resolution can change
  // its mind, and then it is no reading.
  const auto [again, margin_again] = read_cells(image, final_h, family, out.pixels_per_unit, out.contrast);
  out.margin = std::min(out.margin, again == id ? margin_again : 0.0);
  return out;
}


bool acceptable(const OutlineReading& r, const DetectorParams& params) {
  // Measured on the range and blur renders and on marker-free photos (docs/BENCHMARKS.md):
  // true readings align at 0.78 to 0.93 and wrong ones occur only below the resolution
  // bound, where their margins reach 0.04; 0.03 keeps every wrong reading above the bound
  // out with room to spare.
  return r.pixels_per_unit >= params.min_pixels_per_unit && r.correlation >= kMinCorrelation &&
         r.marker_correlation >= kMinMarkerCorrelation &&
         r.contrast >= kMinContrast && r.margin >= kMinMargin && r.baseline_gap >= kMinBaselineGap;
}

}  // namespace lftag::detail
