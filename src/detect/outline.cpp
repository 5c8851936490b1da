// SPDX-License-Identifier: LGPL-2.1-or-later
// The outline reading: markers whose squares no binary image separates (far, blurred) are
// read from their grey levels once their outline is known.
//
// Whatever the id, a marker has a fixed structure: the black border, the white ring inside
// it, the white lines between the cells and, in every cell, a dark core (the 2 x 2 units
// that each of the square's four positions covers). Only the one-unit strips beside each
// core change with the data. A template of that structure (the strips left grey, blurred
// to the frame's resolution) is aligned to the frame by ECC (the enhanced correlation
// coefficient over a homography, alignment.cpp), starting from the coarse outline of a
// second look's binary patch or a border proposal. The
// corners whose four strips are all dark are the baselines, which fixes the turn; then
// each data cell's square position is the one whose blurred model fits the cell's grey
// levels best. Every check is measured against the marker's own levels and units, so it
// means the same at every size and under every blur.
#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "../core/recycled_maps.hpp"
#include "stages.hpp"

namespace lftag::detail {
namespace {

constexpr double kTemplateScale = 3;  // template pixels per unit
constexpr double kRing = 1;           // units of the white margin the template assumes outside
// Defocus blurs sought beyond the template's own, Gaussian sigmas in units.
constexpr std::array<double, 3> kDefocusUnits = {0.7, 1.1, 1.5};
// From this ratio of a defocus's longest axis in the template to its geometric mean
// (1 / sqrt(cos tilt): tilts of about 37 degrees), the defocus is sought uneven.
constexpr double kMinDefocusStretch = 1.12;
// And up to this one (tilts of about 86 degrees, beyond every marker read in the angle
// sweep, 84.5 at most): a warp stretched further is no marker's.
constexpr double kMaxDefocusStretch = 4;

// The fixed structure along one axis of the marker: 0 black, 1 white, 0.5 a data strip.
double axis_class(double u, int side) {
  if (u < 0 || u >= side) return 1;      // the margin
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

// A template's correlation with an image under a warp, from a sparse set of its pixels:
// the start of an alignment is chosen among many warps, and warping the whole template for
// each costs more than the alignment.
class SparseTemplate {
 public:
  // Every `stride`-th pixel of `templ` both ways; with `smear` (template pixels), the
  // template smeared evenly along it, sampled there.
  SparseTemplate(const cv::Mat1f& templ, int stride, cv::Point2d smear = {}) {
    const int taps = smear == cv::Point2d() ? 1 : int(std::ceil(cv::norm(smear))) + 1;
    // The taps' offsets from a sample, and how far they reach (whole pixels).
    std::vector<cv::Point2d> offsets;
    int reach_x = 0, reach_y = 0;
    for (int i = 0; i < taps && taps > 1; ++i) {
      const double f = double(i) / (taps - 1) - 0.5;
      offsets.emplace_back(f * smear.x, f * smear.y);
      reach_x = std::max(reach_x, int(std::ceil(std::abs(f * smear.x))));
      reach_y = std::max(reach_y, int(std::ceil(std::abs(f * smear.y))));
    }
    double sum = 0;
    for (int y = stride / 2; y < templ.rows; y += stride)
      for (int x = stride / 2; x < templ.cols; x += stride) {
        double value = templ(y, x);
        if (taps > 1) {
          value = 0;
          // Well inside the template bilinear_at's clamps change nothing: the same sums
          // without them.
          if (x - reach_x >= 0 && x + reach_x + 2 < templ.cols && y - reach_y >= 0 && y + reach_y + 2 < templ.rows)
            for (const cv::Point2d& t : offsets) value += bilinear_inside(templ, float(x + t.x), float(y + t.y));
          else
            for (const cv::Point2d& t : offsets) value += bilinear_at(templ, float(x + t.x), float(y + t.y));
          value /= taps;
        }
        points_.push_back({float(x), float(y), float(value)});
        sum += value;
      }
    centre(sum / double(points_.size()));
  }

  // The template smeared evenly along `direction` (unit vector) over each of `lengths`
  // (template pixels, rising), sampled at every `stride`-th pixel: the samples along the
  // longest smear are taken once, a pixel apart, and shared by the shorter ones.
  static std::vector<SparseTemplate> smeared(const cv::Mat1f& templ, int stride, cv::Point2d direction,
                                             const std::vector<double>& lengths) {
    const int reach = int(lengths.back() / 2);
    std::vector<SparseTemplate> out;
    for (std::size_t k = 0; k < lengths.size(); ++k) out.push_back(SparseTemplate());
    std::vector<float> along(2 * reach + 1);
    for (int y = stride / 2; y < templ.rows; y += stride)
      for (int x = stride / 2; x < templ.cols; x += stride) {
        for (int i = -reach; i <= reach; ++i)
          along[i + reach] = bilinear_at(templ, float(x + i * direction.x), float(y + i * direction.y));
        for (std::size_t k = 0; k < lengths.size(); ++k) {
          const int half = int(lengths[k] / 2);
          float sum = 0;
          for (int i = -half; i <= half; ++i) sum += along[i + reach];
          out[k].points_.push_back({float(x), float(y), sum / float(2 * half + 1)});
        }
      }
    for (SparseTemplate& t : out) {
      double sum = 0;
      for (const Point& p : t.points_) sum += p.value;
      t.centre(sum / double(t.points_.size()));
    }
    return out;
  }

  // `warp`: template -> image pixels (3x3, CV_32F). Image pixels outside repeat the edge.
  double correlation(const cv::Mat1f& image, const cv::Matx33f& w) const {
    if (!inside(image, w)) return correlation_of(w, [&](float x, float y) { return bilinear_at(image, x, y); });
    // Every sample well inside: the same sums without the clamps at the image's edges.
    return correlation_of(w, [&](float x, float y) { return bilinear_inside(image, x, y); });
  }

 private:
  // bilinear_at where its clamps change nothing: 0 <= x, y and x + 1, y + 1 within the image.
  static float bilinear_inside(const cv::Mat1f& image, float x, float y) {
    const int x0 = int(x), y0 = int(y);
    const float fx = x - x0, fy = y - y0;
    const float* a = image[y0] + x0;
    const float* b = image[y0 + 1] + x0;
    return (1 - fy) * ((1 - fx) * a[0] + fx * a[1]) + fy * ((1 - fx) * b[0] + fx * b[1]);
  }

  static float bilinear_at(const cv::Mat1f& image, float x, float y) {
    x = std::clamp(x, 0.0f, float(image.cols - 1)), y = std::clamp(y, 0.0f, float(image.rows - 1));
    const int x0 = std::min(int(x), std::max(image.cols - 2, 0)), y0 = std::min(int(y), std::max(image.rows - 2, 0));
    const int x1 = std::min(x0 + 1, image.cols - 1), y1 = std::min(y0 + 1, image.rows - 1);
    const float fx = x - x0, fy = y - y0;
    return (1 - fy) * ((1 - fx) * image(y0, x0) + fx * image(y0, x1)) +
           fy * ((1 - fx) * image(y1, x0) + fx * image(y1, x1));
  }

  SparseTemplate() = default;

  // The correlation of the points' values with the image's grey levels at the points
  // under `w`, sampled by `sample(x, y)`.
  template <typename Sample>
  double correlation_of(const cv::Matx33f& w, Sample sample) const {
    double s = 0, ss = 0, st = 0;
    for (const Point& p : points_) {
      const float z = w(2, 0) * p.x + w(2, 1) * p.y + w(2, 2);
      if (!(std::abs(z) > 1e-12f)) return 0;
      const double g =
          sample((w(0, 0) * p.x + w(0, 1) * p.y + w(0, 2)) / z, (w(1, 0) * p.x + w(1, 1) * p.y + w(1, 2)) / z);
      s += g, ss += g * g, st += g * p.value;
    }
    const double n = double(points_.size()), variance = ss - s * s / n;
    return variance > 0 && norm_ > 0 ? st / std::sqrt(variance * norm_) : 0;
  }

  // Whether `w` takes the box of the points well inside the image, where no bilinear
  // sample needs clamping: a homography positive over a box maps it to the quadrilateral
  // of its corners.
  bool inside(const cv::Mat1f& image, const cv::Matx33f& w) const {
    if (points_.empty()) return false;
    const Point& first = points_.front();
    const Point& last = points_.back();
    for (const float x : {first.x, last.x})
      for (const float y : {first.y, last.y}) {
        const float z = w(2, 0) * x + w(2, 1) * y + w(2, 2);
        if (!(z > 1e-6f)) return false;
        const float u = (w(0, 0) * x + w(0, 1) * y + w(0, 2)) / z, v = (w(1, 0) * x + w(1, 1) * y + w(1, 2)) / z;
        if (!(u >= 0.01f && v >= 0.01f && u <= image.cols - 2.01f && v <= image.rows - 2.01f)) return false;
      }
    return true;
  }

  // Zero mean, and the norm the correlation divides by.
  void centre(double mean) {
    for (Point& p : points_) p.value -= float(mean), norm_ += double(p.value) * p.value;
  }

  struct Point {
    float x, y, value;
  };
  std::vector<Point> points_;
  double norm_ = 0;
};

// A template blurred by a Gaussian of `sigma` template pixels. With `paper_beyond`, as the
// frame blurs the marker: beyond its white ring the paper stays white. Without, the ring
// is mirrored there and brings the border back outside it, as the checks of the sharper
// readings were measured with. Under a defocus that matters: the alignment shrank a
// marker by 0.7 px of 22 to match at a blur of 1.4 units, 3 % of its distance. (White
// paper for every reading moved the range sweep's limits both ways, one 3x3 at 26.1 m
// under the margin bound and a fifth of them further out: left for a recalibration.)
cv::Mat1f blurred_template(const cv::Mat1f& sharp, double sigma, bool paper_beyond = false) {
  cv::Mat1f out;
  cv::GaussianBlur(sharp, out, cv::Size(), sigma, sigma, paper_beyond ? cv::BORDER_REPLICATE : cv::BORDER_REFLECT_101);
  return out;
}

// The larger eigenvalue of a symmetric 2 x 2 matrix.
double larger_eigenvalue(const cv::Matx22d& m) {
  return (m(0, 0) + m(1, 1)) / 2 + std::hypot((m(0, 0) - m(1, 1)) / 2, m(0, 1));
}

// A template blurred by a Gaussian of `covariance` (template pixels squared), the paper
// beyond its white ring staying white: a defocus blurs the frame evenly, which on a tilted
// marker is a blur of its template longer across the tilt's axis than along it.
cv::Mat1f blurred_template(const cv::Mat1f& sharp, const cv::Matx22d& covariance) {
  const cv::Matx22d inverse = covariance.inv();
  const double widest = std::sqrt(larger_eigenvalue(covariance));
  // A kernel wider than the template adds nothing (and a near-singular warp would ask for
  // one of billions of taps).
  const int half = int(std::clamp(std::ceil(3 * widest), 1.0, double(std::max(sharp.rows, sharp.cols))));
  cv::Mat1f kernel(2 * half + 1, 2 * half + 1);
  for (int y = -half; y <= half; ++y)
    for (int x = -half; x <= half; ++x)
      kernel(y + half, x + half) =
          float(std::exp(-0.5 * (inverse(0, 0) * x * x + 2 * inverse(0, 1) * x * y + inverse(1, 1) * y * y)));
  kernel /= cv::sum(kernel)[0];
  cv::Mat1f out;
  cv::filter2D(sharp, out, -1, kernel, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
  return out;
}

// One value per family size, each made on its first use, once for the process, and read
// only after that: every detector and thread shares these templates, so nothing may write
// into their pixels (they are handed out as const).
template <class T>
class PerFamilySize {
 public:
  template <class Make>
  const T& get(const Family& family, Make make) {
    std::call_once(made_[family.n()], [&] { values_[family.n()] = make(); });
    return values_[family.n()];
  }

 private:
  std::array<std::once_flag, Family::kMaxN + 1> made_;
  std::array<T, Family::kMaxN + 1> values_;
};

// The sharp structure of `family`.
const cv::Mat1f& sharp_structure(const Family& family) {
  static PerFamilySize<cv::Mat1f> sharp;
  return sharp.get(family, [&] { return structure_template(family); });
}

// The blur, in template pixels, of a structure seen at `per_unit` pixels per unit.
double template_blur(double per_unit) { return 0.4 / std::min(per_unit, kTemplateScale) * kTemplateScale; }

// The structure blurred as seen at `per_unit` pixels per unit, and its sparse samples.
struct BlurredStructure {
  cv::Mat1f image;
  SparseTemplate sparse;
};

// Drawn into `drawn`, or taken from the shared table (see below).
const BlurredStructure& blurred_structure(const Family& family, double per_unit,
                                          std::optional<BlurredStructure>& drawn) {
  const double sigma = template_blur(per_unit);
  const auto draw = [&] {
    cv::Mat1f image = sharp_structure(family).clone();
    if (sigma > 0.3) image = blurred_template(image, sigma);
    return BlurredStructure{image, SparseTemplate(image, 3)};
  };
  // Every crop of kTemplateScale pixels per unit or more is read with the same blur, the
  // one of the template's own resolution: drawn once (most outline reads of a frame
  // crowded with other markers are of that kind; drawing it each time cost 2 % of such a
  // frame's instructions).
  if (per_unit >= kTemplateScale) {
    static PerFamilySize<std::optional<BlurredStructure>> resolved;
    return *resolved.get(family, draw);
  }
  return drawn.emplace(draw());
}

// Where a reading takes its white and black: the middle of the white ring (its four
// sides, each one unit wide) and each cell's 2 x 2 unit core, where its square always is.
// `mean(x, y, w, h)` averages a unit rectangle.
template <class Mean>
double ring_level(const Mean& mean, double side) {
  return (mean(2.5, 2.5, side - 5, 1) + mean(2.5, side - 3.5, side - 5, 1) + mean(2.5, 3.5, 1, side - 7) +
          mean(side - 3.5, 3.5, 1, side - 7)) /
         4;
}
template <class Mean>
double core_level(const Mean& mean, int r, int c) {
  return mean(5 + 6 * c, 5 + 6 * r, 2, 2);
}

// The contrast that a template of the structure shows where the reading measures it (1
// when sharp, less when blurred).
double structure_contrast(const cv::Mat1f& templ) {
  const auto mean = [&](double x, double y, double w, double h) {  // units, to the nearest template pixel
    const auto px = [](double u) { return int(std::lround(u * kTemplateScale)); };
    return cv::mean(templ(cv::Rect(px(x + kRing), px(y + kRing), px(w), px(h))))[0];
  };
  const double side = std::round(templ.cols / kTemplateScale - 2 * kRing);
  const int n = int(side) / 6 - 1;
  double black = 0;
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) black += core_level(mean, r, c);
  return ring_level(mean, side) - black / (n * n);
}

// Units -> template pixels (pixel centres at whole numbers).
cv::Matx33d unit_to_template() {
  const double o = kRing * kTemplateScale - 0.5;
  return {kTemplateScale, 0, o, 0, kTemplateScale, o, 0, 0, 1};
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
          core_level([&](double u, double v, double w, double hh) { return mean_level(image, h, u, v, w, hh); }, r, c)};
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
      s.grey[i * kCellGrid + j] =
          grey_at(image, apply(h, {6.0 * c + grid_coordinate(j), 6.0 * r + grid_coordinate(i)}));
  return s;
}

struct CellFit {
  int digit = 0;
  double rss = 0;  // residual sum of squares
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
  std::array<double, 4> rss;
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
    const double ink = var > 0 ? -sgc / var : 0;      // paper minus ink level
    rss[std::size_t(digit)] = ink > 0 ? sgg - sgc * sgc / var : sgg;
  }
  CellFit fit;
  fit.digit = int(std::min_element(rss.begin(), rss.end()) - rss.begin());
  fit.rss = rss[std::size_t(fit.digit)];
  return fit;
}

// The id read from the data cells under homography h (true turn): the start of the
// pixel model's reading, which decides.
TagId read_cells(const ImageView& image, const cv::Matx33d& h, const Family& family, double pixels_per_unit) {
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
  int k = 0;
  for (int g = 0; g < family.cell_count(); ++g)
    if (!family.is_baseline(g)) id = id.with_digit(family.data_index(g), best_fits[std::size_t(k++)].digit);
  return id;
}

// The direction of a marker's edges, modulo 90 degrees (radians, in [0, pi/2)): the mean
// of the gradients' orientations, taken four times over so that the four directions of a
// square's edges add up.
double edge_direction(const cv::Mat1f& image) {
  cv::Mat1f gx, gy;
  cv::Sobel(image, gx, CV_32F, 1, 0);
  cv::Sobel(image, gy, CV_32F, 0, 1);
  // With g = gx + i gy, g^4 / |g|^2 is |g|^2 e^{4ia}: no trigonometry per pixel.
  double c = 0, s = 0;
  for (int y = 1; y + 1 < image.rows; ++y)
    for (int x = 1; x + 1 < image.cols; ++x) {
      const double a = gx(y, x), b = gy(y, x), m = a * a + b * b;
      if (m <= 0) continue;
      const double re2 = a * a - b * b, im2 = 2 * a * b;  // g^2
      c += (re2 * re2 - im2 * im2) / m, s += 2 * re2 * im2 / m;
    }
  const double d = std::atan2(s, c) / 4;
  return d < 0 ? d + CV_PI / 2 : d;
}

// A linear motion blur (a point smeared evenly along the segment `along`, centred on it) as
// a convolution kernel of some image's pixels.
cv::Mat1f smear_kernel(cv::Point2d along) {
  const double length = cv::norm(along);
  const int half = int(std::ceil(length / 2)) + 1;
  cv::Mat1f k(2 * half + 1, 2 * half + 1, 0.f);
  const int steps = std::max(2, int(std::ceil(length * 4)));
  for (int i = 0; i <= steps; ++i) {  // bilinear splats of points along the segment
    const cv::Point2d p = cv::Point2d(half, half) + along * (double(i) / steps - 0.5);
    const int x = int(std::floor(p.x)), y = int(std::floor(p.y));
    const float fx = float(p.x - x), fy = float(p.y - y);
    k(y, x) += (1 - fx) * (1 - fy), k(y, x + 1) += fx * (1 - fy);
    k(y + 1, x) += (1 - fx) * fy, k(y + 1, x + 1) += fx * fy;
  }
  return k / cv::sum(k)[0];
}

// `image` convolved with a smear kernel (zero outside): a kernel along a line is mostly
// zeros, and adding shifted copies for its few taps costs less than filter2D's transform.
cv::Mat1f smeared_by(const cv::Mat1f& image, const cv::Mat1f& kernel) {
  cv::Mat1f out = recycled_map(image.size(), 0.f);
  const int ay = kernel.rows / 2, ax = kernel.cols / 2;
  for (int ky = 0; ky < kernel.rows; ++ky)
    for (int kx = 0; kx < kernel.cols; ++kx) {
      const float w = kernel(ky, kx);
      if (w == 0) continue;
      // out(y, x) += w * image(y + ky - ay, x + kx - ax)
      const int dy = ky - ay, dx = kx - ax;
      const cv::Rect to = cv::Rect(-dx, -dy, image.cols, image.rows) & cv::Rect(0, 0, image.cols, image.rows);
      if (to.empty()) continue;
      // By rows, as cv::scaleAdd would, without its per-call and per-row set-up (a pixel
      // model's reading smears about 140 small maps by some 30 taps each at every length
      // it tries: half of a motion-blurred read's time went to that set-up).
      for (int y = 0; y < to.height; ++y) {
        float* o = out.ptr<float>(to.y + y) + to.x;
        const float* in = image.ptr<float>(to.y + y + dy) + to.x + dx;
        for (int x = 0; x < to.width; ++x) o[x] += w * in[x];
      }
    }
  return out;
}

// std::floor of a value well within int's range, without the library call that std::floor
// is on a baseline x86-64 build (most of a pixel model's construction went to it).
int floor_int(double v) {
  const int t = int(v);
  return v < t ? t - 1 : t;
}

// Whether unit point `u` lies in `s` (left and top edges included).
bool marker_holds(const UnitRect& s, cv::Point2d u) {
  return u.x >= s.x && u.x < s.x + s.width && u.y >= s.y && u.y < s.y + s.height;
}

// Bounds, in units, of every point of a frame pixel (a little wider, for rounding).
struct UnitBounds {
  double x0, y0, x1, y1;
  bool within(const UnitRect& s) const { return x0 >= s.x && x1 < s.x + s.width && y0 >= s.y && y1 < s.y + s.height; }
  bool apart(const UnitRect& s) const { return x1 < s.x || x0 >= s.x + s.width || y1 < s.y || y0 >= s.y + s.height; }
};

// The bounds of the pixel centred at `centre` under `to_units`; none when the pixel
// crosses the horizon, where its points do not lie between its corners' images.
std::optional<UnitBounds> unit_bounds(const cv::Matx33d& to_units, cv::Point2d centre) {
  constexpr double kRounding = 1e-7;  // units; points computed apart differ by ~1e-13
  UnitBounds b{HUGE_VAL, HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  double first_w = 0;
  for (const cv::Point2d corner :
       {cv::Point2d(-0.5, -0.5), cv::Point2d(0.5, -0.5), cv::Point2d(0.5, 0.5), cv::Point2d(-0.5, 0.5)}) {
    const cv::Vec3d q = to_units * cv::Vec3d(centre.x + corner.x, centre.y + corner.y, 1);
    if (first_w == 0) first_w = q[2];
    if (!(q[2] * first_w > 0)) return std::nullopt;
    const double ux = q[0] / q[2], uy = q[1] / q[2];
    b.x0 = std::min(b.x0, ux), b.x1 = std::max(b.x1, ux), b.y0 = std::min(b.y0, uy), b.y1 = std::max(b.y1, uy);
  }
  b.x0 -= kRounding, b.y0 -= kRounding, b.x1 += kRounding, b.y1 += kRounding;
  return b;
}

// A marker's pixels and their predicted ink: each pixel's share of the marker's black
// (the area of the pixel that the black covers under the homography, then blurred by the
// optics), split into what is fixed (border, baselines) and what each data cell's square
// adds at each of its four positions. A frame pixel integrates light over its area, so at
// half a pixel per unit a square's one-unit shift still changes the few pixels it touches
// in a predictable way; sampling interpolated grey levels instead blurs that away.
class PixelModel {
 public:
  // `smear`: the motion blur found while aligning (frame pixels; none when zero).
  PixelModel(const ImageView& image, const cv::Matx33d& h, const Family& family, double pixels_per_unit,
             cv::Point2d smear)
      : family_(family) {
    const int side = family.side();
    if (cv::norm(smear) > 0.5) smear_ = smear;
    const cv::Matx33d to_units = h.inv();
    const int pad = blur_reach(pixels_per_unit, smear_);
    box_ = pixels_read(image, h, family, pixels_per_unit, smear);
    if (box_.area() == 0 || box_.area() > kMaxPixels) return;
    grey_ = recycled_map(box_.size());
    use_.create(box_.size());
    fixed_ = recycled_map(box_.size(), 0.f);
    for (int g = 0; g < family.cell_count(); ++g) {
      if (family.is_baseline(g)) continue;
      cells_.push_back(g);
      // Every position of the cell's square, and the blur around it.
      const double x = 4 + 6 * (g % family.n()), y = 4 + 6 * (g / family.n());
      std::vector<cv::Point2f> reach;
      for (const cv::Point2d& u :
           {cv::Point2d(x, y), cv::Point2d(x + 4, y), cv::Point2d(x + 4, y + 4), cv::Point2d(x, y + 4)})
        reach.emplace_back(cv::Point2f(apply(h, u)));
      cv::Rect r = cv::boundingRect(reach);
      r = cv::Rect(r.x - box_.x - pad, r.y - box_.y - pad, r.width + 2 * pad, r.height + 2 * pad) &
          cv::Rect(cv::Point(), box_.size());
      if (r.empty()) {  // the cell lies wholly outside the frame: nothing of it to read
        grey_.release();
        return;
      }
      std::array<Coverage, 4>& squares = squares_.emplace_back();
      for (Coverage& c : squares) c.rect = r, c.share = recycled_map(r.size(), 0.f);
    }
    // Area shares by supersampling each pixel (about four samples per unit).
    const int k = std::clamp(int(std::ceil(4 / pixels_per_unit)), 2, 8);
    const float weight = 1.0f / float(k * k);
    const int n = family.n();
    std::vector<int> slot(family.cell_count(), -1);
    for (int i = 0; i < int(cells_.size()); ++i) slot[cells_[i]] = i;
    std::vector<std::array<UnitRect, 4>> square_at(family.cell_count());  // per cell and position
    for (int g = 0; g < family.cell_count(); ++g)
      for (int d = 0; d < 4; ++d) square_at[g][d] = family.square(g, family.is_baseline(g) ? 0 : d);
    // `times` samples of pixel (x, y) that lie in one place: cell g (-1: the border, -2:
    // none), under the squares of the positions `covered`.
    const auto add = [&](int y, int x, int g, const std::array<bool, 4>& covered, int times) {
      for (int t = 0; t < times; ++t) {  // one at a time, as single samples add up
        if (g == -1) fixed_(y, x) += weight;
        if (g < 0) continue;
        if (family.is_baseline(g)) {
          if (covered[0]) fixed_(y, x) += weight;
          continue;
        }
        for (int d = 0; d < 4; ++d)
          if (covered[d]) {
            Coverage& cov = squares_[slot[g]][d];
            cov.share(y - cov.rect.y, x - cov.rect.x) += weight;
          }
      }
    };
    std::vector<cv::Point2d> sample_offsets;  // from the pixel's centre
    for (int a = 0; a < k; ++a)
      for (int c = 0; c < k; ++c) sample_offsets.emplace_back((c + 0.5) / k - 0.5, (a + 0.5) / k - 0.5);
    const UnitRect marker{0, 0, double(side), double(side)}, inside_border{2, 2, side - 4.0, side - 4.0};
    // Column and row, maybe beyond the grid. (Multiplying by a sixth can put a point a
    // rounding error past a cell's edge in the next cell: those edges lie in white, and the
    // squares' own edges decide whether a point is covered.)
    const auto cell_of = [](double ux, double uy) {
      return cv::Point(floor_int((ux - 4) * (1.0 / 6)), floor_int((uy - 4) * (1.0 / 6)));
    };
    const auto grid_index = [&](cv::Point cell) {  // -2: between the grid and the border
      return cell.x < 0 || cell.y < 0 || cell.x >= n || cell.y >= n ? -2 : cell.y * n + cell.x;
    };
    for (int y = 0; y < box_.height; ++y)
      for (int x = 0; x < box_.width; ++x) {
        const cv::Point2d centre(box_.x + x, box_.y + y);
        grey_(y, x) = float(image.data[(box_.y + y) * image.stride + box_.x + x]);
        const cv::Point2d cu = apply(to_units, centre);
        // Fitted: the marker and the inner half of its margin (what lies beyond may be
        // background).
        use_(y, x) = cu.x >= -0.5 && cu.x < side + 0.5 && cu.y >= -0.5 && cu.y < side + 0.5;
        if (!use_(y, x) && !(cu.x >= -2 && cu.x < side + 2 && cu.y >= -2 && cu.y < side + 2)) continue;
        // A pixel whose corners lie in one region of the layout (the margin, the border,
        // the white between squares, the part of a cell that the same positions cover)
        // has all its samples there: they lie between its corners, the homography being
        // projective where all four are on one side of the horizon.
        if (const std::optional<UnitBounds> b = unit_bounds(to_units, centre)) {
          if (b->apart(marker)) continue;
          std::array<bool, 4> covered{};
          if (b->within(marker) && b->apart(inside_border)) {
            add(y, x, -1, covered, k * k);
            continue;
          }
          if (b->within(inside_border) && cell_of(b->x0, b->y0) == cell_of(b->x1, b->y1)) {
            const int g = grid_index(cell_of(b->x0, b->y0));
            bool decided = true;
            for (int d = 0; d < 4 && decided && g >= 0; ++d) {
              covered[d] = b->within(square_at[g][d]);
              decided = covered[d] || b->apart(square_at[g][d]);
            }
            if (decided) {
              add(y, x, g, covered, k * k);
              continue;
            }
          }
        }
        for (const cv::Point2d& offset : sample_offsets) {
          const cv::Point2d u = apply(to_units, centre + offset);
          if (!marker_holds(marker, u)) continue;
          std::array<bool, 4> covered{};
          if (!marker_holds(inside_border, u)) {
            add(y, x, -1, covered, 1);
            continue;
          }
          const int g = grid_index(cell_of(u.x, u.y));
          if (g >= 0) {
            // Position 0's square; the others lie one unit right (digits 2, 3) and/or down (1, 3).
            const UnitRect& s = square_at[g][0];
            const bool at_x[2] = {u.x >= s.x && u.x < s.x + 3, u.x >= s.x + 1 && u.x < s.x + 4};
            const bool at_y[2] = {u.y >= s.y && u.y < s.y + 3, u.y >= s.y + 1 && u.y < s.y + 4};
            for (int d = 0; d < 4; ++d)
              covered[d] = family.is_baseline(g) ? marker_holds(s, u) : at_x[d >> 1] && at_y[d & 1];
          }
          add(y, x, g, covered, 1);
        }
      }
  }

  bool valid() const { return !grey_.empty(); }

  // The frame pixels a model of the marker under `h` reads: the marker and its one-unit
  // white margin, with room for the widest blur.
  static cv::Rect pixels_read(const ImageView& image, const cv::Matx33d& h, const Family& family,
                              double pixels_per_unit, cv::Point2d smear) {
    const int side = family.side();
    std::vector<cv::Point2f> margin;
    for (const cv::Point2d& u :
         {cv::Point2d(-1, -1), cv::Point2d(side + 1, -1), cv::Point2d(side + 1, side + 1), cv::Point2d(-1, side + 1)})
      margin.emplace_back(cv::Point2f(apply(h, u)));
    const int pad = blur_reach(pixels_per_unit, cv::norm(smear) > 0.5 ? smear : cv::Point2d());
    const cv::Rect box = cv::boundingRect(margin);
    return cv::Rect(box.x - pad, box.y - pad, box.width + 2 * pad, box.height + 2 * pad) &
           cv::Rect(0, 0, image.width, image.height);
  }

  // The least motion blur a reading can report (Reading::smear) for a smear found while
  // aligning, frame pixels: every length it tries is a scale of that one.
  static double least_smear(cv::Point2d smear) {
    return cv::norm(smear) > 0.5 ? cv::norm(smear) * kSmearScales.front() : 0;
  }

  struct Reading {
    TagId id;
    double margin = 0;
    double smear = 0;                // length of the motion blur that fits best, frame pixels
    double noise_margin = 0;         // OutlineReading::noise_margin
    double evidence = 0;             // OutlineReading::evidence
    double ink = 0;                  // OutlineReading::model_ink
    double listed_noise_margin = 0;  // OutlineReading::listed_noise_margin
    double listed_evidence = 0;      // OutlineReading::listed_evidence
  };

  // The id whose predicted pixels fit the grey levels best (least squares with the
  // marker's own paper and ink levels, at the optical blur, and the length of the motion
  // blur found while aligning, that fit best), found cell by cell from `start`; and the
  // least margin over the data cells: how much worse the runner-up position of its square
  // fits, per pixel of a cell over the contrast squared.
  Reading read(TagId start, double pixels_per_unit, double contrast, const std::vector<TagId>* listed = nullptr) const {
    // The blurs are chosen on the whole marker of an id, one map smeared and blurred (the
    // model is linear), and the cells fitted once at that blur; a fit that moves squares is
    // the marker of another id, whose blur is chosen again. (Fitting the cells at every
    // blur cost 15 fits of every square's map under motion blur, most of a frame's time.)
    Choice choice = best_blur(start, pixels_per_unit);
    Fit fit = fit_with(choice, pixels_per_unit, start, listed);
    if (fit.id != start)
      if (const Choice again = best_blur(fit.id, pixels_per_unit); again != choice)
        choice = again, fit = fit_with(choice, pixels_per_unit, fit.id, listed);
    return {fit.id,
            fit.least_gain / (pixels_per_unit * pixels_per_unit * 25 * contrast * contrast),
            cv::norm(smear_) * choice.scale,
            fit.noise_margin,
            fit.evidence,
            contrast > 0 ? fit.ink / contrast : 0,
            fit.listed_noise_margin,
            fit.listed_evidence};
  }

 private:
  inline static const std::vector<double> kSmearScales = {0.85, 0.92, 1.0, 1.08, 1.16};  // of the smear found
  static constexpr double kMaxBlur = 2.2;                                                // units
  static constexpr int kMaxPixels = 1 << 20;  // a marker this large needs no outline reading

  struct Coverage {
    cv::Rect rect;  // within the box
    cv::Mat1f share;
  };
  struct Sums {
    double n = 0, g = 0, gg = 0, c = 0, cc = 0, gc = 0;
    double rss(double* ink = nullptr) const {
      const double vg = gg - g * g / n, vc = cc - c * c / n, cov = gc - g * c / n;
      if (ink) *ink = vc > 0 ? -cov / vc : 0;
      return vc > 0 && cov < 0 ? vg - cov * cov / vc : vg;  // ink darkens
    }
  };
  struct Fit {
    TagId id;
    double rss = 0, ink = 0, least_gain = 0;
    double noise_margin = 0;         // Reading::noise_margin
    double evidence = 0;             // Reading::evidence
    double listed_noise_margin = 0;  // Reading::listed_noise_margin
    double listed_evidence = 0;      // Reading::listed_evidence
  };

  // A motion blur's length, as a scale of the one found while aligning (0: none), and an
  // optical blur (units).
  struct Choice {
    double scale = 0, blur = 0;
    bool operator!=(const Choice& o) const { return scale != o.scale || blur != o.blur; }
  };

  // How far the widest optical blur and the longest smear tried reach, pixels.
  static int blur_reach(double pixels_per_unit, cv::Point2d smear) {
    return int(std::ceil(3 * kMaxBlur * pixels_per_unit + cv::norm(smear) * kSmearScales.back() / 2)) + 1;
  }

  // `m` blurred by a Gaussian of `sigma` pixels (nothing beyond the box).
  static cv::Mat1f blurred_by(const cv::Mat1f& m, double sigma) {
    if (!(sigma > 0.2)) return m;
    cv::Mat1f out = recycled_map(m.size());
    cv::GaussianBlur(m, out, cv::Size(), sigma, sigma, cv::BORDER_CONSTANT);
    return out;
  }

  // The smear and optical blur under which the marker of `id` fits the grey levels best.
  Choice best_blur(TagId id, double pixels_per_unit) const {
    cv::Mat1f marker = recycled_copy(fixed_);
    for (std::size_t i = 0; i < cells_.size(); ++i) {
      const Coverage& square = squares_[i][id.digit(family_.data_index(cells_[i]))];
      marker(square.rect) += square.share;
    }
    const bool smeared = smear_ != cv::Point2d();
    // With a motion blur, which dominates, only the lesser optical blurs are tried.
    const std::vector<double> blurs =
        smeared ? std::vector<double>{0.0, 0.3, 0.6} : std::vector<double>{0.0, 0.3, 0.6, 1.0, 1.5, kMaxBlur};
    Choice best;
    double best_rss = std::numeric_limits<double>::infinity();
    for (const double scale : smeared ? kSmearScales : std::vector<double>{0}) {
      const cv::Mat1f moved = scale == 0 ? marker : smeared_by(marker, smear_kernel(smear_ * scale));
      for (const double blur : blurs)
        if (const double rss = sums_of(blurred_by(moved, blur * pixels_per_unit)).rss(); rss < best_rss)
          best_rss = rss, best = {scale, blur};
    }
    return best;
  }

  // The cells fitted from `start` under `choice`, with their margins.
  Fit fit_with(const Choice& choice, double pixels_per_unit, TagId start,
               const std::vector<TagId>* listed = nullptr) const {
    const cv::Mat1f kernel = choice.scale == 0 ? cv::Mat1f() : smear_kernel(smear_ * choice.scale);
    const auto smear = [&](const cv::Mat1f& m) { return choice.scale == 0 ? m : smeared_by(m, kernel); };
    std::vector<std::array<cv::Mat1f, 4>> squares(cells_.size());
    for (std::size_t i = 0; i < cells_.size(); ++i)
      for (int d = 0; d < 4; ++d) squares[i][d] = smear(squares_[i][d].share);
    return fit_at(choice.blur * pixels_per_unit, smear(fixed_), squares, start, listed);
  }

  // The variance of sum(delta * noise) over a rectangle of pixels, in units of the noise's
  // own variance, for noise correlated by rho_x^|dx| rho_y^|dy| between pixels:
  // delta' K delta, with K applied as two exponential filters each way (exact, linear).
  static double correlated_power(cv::Mat1d delta, double rho_x, double rho_y) {
    const cv::Mat1d original = delta.clone();
    const auto filter = [](double* v, int n, std::ptrdiff_t step, double rho) {
      if (rho <= 0 || n < 2) return;
      std::vector<double> forward(static_cast<std::size_t>(n)), backward(static_cast<std::size_t>(n));
      for (int k = 0; k < n; ++k) forward[std::size_t(k)] = v[k * step] + (k ? rho * forward[std::size_t(k - 1)] : 0);
      for (int k = n - 1; k >= 0; --k)
        backward[std::size_t(k)] = v[k * step] + (k < n - 1 ? rho * backward[std::size_t(k + 1)] : 0);
      for (int k = 0; k < n; ++k) v[k * step] = forward[std::size_t(k)] + backward[std::size_t(k)] - v[k * step];
    };
    for (int y = 0; y < delta.rows; ++y) filter(delta.ptr<double>(y), delta.cols, 1, rho_x);
    for (int x = 0; x < delta.cols; ++x) filter(delta.ptr<double>(0) + x, delta.rows, delta.cols, rho_y);
    return original.dot(delta);
  }

  // The fit from `start` with the coverage (`fixed`, `smeared_squares`: smeared already)
  // blurred by a Gaussian of `sigma` pixels; its id, residual and ink only, unless
  // `margins` (the least gain, the noise margin and the evidence too).
  // The sums of the fitted pixels' grey levels against the predicted coverage `total`.
  Sums sums_of(const cv::Mat1f& total) const {
    Sums sums;
    for (int y = 0; y < total.rows; ++y)
      for (int x = 0; x < total.cols; ++x)
        if (use_(y, x)) {
          const double g = grey_(y, x), c = total(y, x);
          sums.n += 1, sums.g += g, sums.gg += g * g, sums.c += c, sums.cc += c * c, sums.gc += g * c;
        }
    return sums;
  }

  Fit fit_at(double sigma, const cv::Mat1f& fixed, const std::vector<std::array<cv::Mat1f, 4>>& smeared_squares,
             TagId start, const std::vector<TagId>* listed = nullptr) const {
    // A copy only of what the sums below change (`total`); the squares' maps are read only.
    cv::Mat1f total = recycled_copy(blurred_by(fixed, sigma));
    std::vector<std::array<cv::Mat1f, 4>> squares(cells_.size());
    std::vector<int> digit(cells_.size());
    // Where within its rectangle a cell's square can change anything at this blur: its maps
    // are zero beyond the blur's reach, and a move changes no sum there.
    std::vector<cv::Rect> reach(cells_.size());
    for (std::size_t i = 0; i < cells_.size(); ++i) {
      for (int d = 0; d < 4; ++d) squares[i][d] = blurred_by(smeared_squares[i][d], sigma);
      digit[i] = start.digit(family_.data_index(cells_[i]));
      total(squares_[i][0].rect) += squares[i][digit[i]];
      reach[i] =
          cv::boundingRect((squares[i][0] != 0) | (squares[i][1] != 0) | (squares[i][2] != 0) | (squares[i][3] != 0));
    }
    Sums sums = sums_of(total);
    // The sums with cell i's square moved from its current position to d.
    const auto moved = [&](std::size_t i, int d) { return moved_in(total, sums, squares, digit, i, d, reach[i]); };
    for (int pass = 0; pass < 4; ++pass) {
      bool changed = false;
      for (std::size_t i = 0; i < cells_.size(); ++i) {
        int best = digit[i];
        double best_rss = sums.rss();
        for (int d = 0; d < 4; ++d)
          if (d != digit[i])
            if (const double r = moved(i, d).rss(); r < best_rss - 1e-9) best_rss = r, best = d;
        if (best == digit[i]) continue;
        sums = moved(i, best);
        total(squares_[i][0].rect) += squares[i][best] - squares[i][digit[i]];
        digit[i] = best;
        changed = true;
      }
      if (!changed) break;
    }
    Fit fit;
    fit.rss = sums.rss(&fit.ink);
    for (std::size_t i = 0; i < cells_.size(); ++i) fit.id = fit.id.with_digit(family_.data_index(cells_[i]), digit[i]);
    fit.least_gain = std::numeric_limits<double>::infinity();
    std::vector<std::array<double, 4>> gain(cells_.size());  // of moving cell i's square to d
    for (std::size_t i = 0; i < cells_.size(); ++i)
      for (int d = 0; d < 4; ++d)
        if (d != digit[i]) fit.least_gain = std::min(fit.least_gain, gain[i][d] = moved(i, d).rss() - fit.rss);

    // The noise margin. With grey = prediction + noise, moving a square changes the
    // prediction by p = ink * delta (delta: the change of its coverage), and the fit worsens
    // by |p|^2 on average, give or take 2 sqrt(p' C p) (C: the noise's covariance): the
    // runner-up stands gain / (2 sqrt(p' C p)) standard deviations away. C is measured on
    // the residuals: their variance (at least the 1/12 of 8-bit rounding) and their
    // correlation between neighbours each way, for blur, a codec's blocks and the model's
    // misfit leave them smooth, and smooth noise moves a square's pixels together.
    const double vc = sums.cc - sums.c * sums.c / sums.n, cov = sums.gc - sums.g * sums.c / sums.n;
    const double slope = vc > 0 && cov < 0 ? cov / vc : 0, mg = sums.g / sums.n, mc = sums.c / sums.n;
    const auto residual = [&](int y, int x) { return grey_(y, x) - mg - slope * (total(y, x) - mc); };
    double rr = 0, across = 0, down = 0;
    int pairs_across = 0, pairs_down = 0;
    for (int y = 0; y < total.rows; ++y)
      for (int x = 0; x < total.cols; ++x) {
        if (!use_(y, x)) continue;
        const double r = residual(y, x);
        rr += r * r;
        if (x + 1 < total.cols && use_(y, x + 1)) across += r * residual(y, x + 1), ++pairs_across;
        if (y + 1 < total.rows && use_(y + 1, x)) down += r * residual(y + 1, x), ++pairs_down;
      }
    const double variance = std::max(rr / sums.n, 1.0 / 12);
    const auto correlation = [&](double sum, int pairs) {
      return rr > 0 && pairs > 0 ? std::clamp(sum / pairs / (rr / sums.n), 0.0, 0.95) : 0.0;
    };
    const double rho_x = correlation(across, pairs_across), rho_y = correlation(down, pairs_down);
    // The evidence: each move's worsening of the fit over the worsening the model predicts
    // for it, |p|^2 (the image's own misfit and noise take some of it away).
    fit.noise_margin = fit.evidence = std::numeric_limits<double>::infinity();
    // Of moving cell i's square to d: the spread and the predicted worsening.
    std::vector<std::array<double, 4>> spread_of(cells_.size(), {0, 0, 0, 0}), predicted_of = spread_of;
    for (std::size_t i = 0; i < cells_.size(); ++i) {
      const cv::Rect& r = squares_[i][0].rect;
      const cv::Rect& e = reach[i];
      for (int d = 0; d < 4; ++d) {
        if (d == digit[i]) continue;
        if (e.empty()) {  // a square wholly outside the frame: moving it changes nothing
          fit.noise_margin = fit.evidence = 0;
          continue;
        }
        cv::Mat1d delta(e.size(), 0.0);
        for (int y = 0; y < e.height; ++y)
          for (int x = 0; x < e.width; ++x)
            if (use_(r.y + e.y + y, r.x + e.x + x))
              delta(y, x) = squares[i][d](e.y + y, e.x + x) - squares[i][digit[i]](e.y + y, e.x + x);
        const double predicted = fit.ink * fit.ink * delta.dot(delta);  // before correlated_power filters delta
        const double spread = fit.ink * fit.ink * variance * correlated_power(delta, rho_x, rho_y);
        spread_of[i][d] = spread, predicted_of[i][d] = predicted;
        fit.noise_margin = std::min(fit.noise_margin, spread > 0 ? gain[i][d] / (2 * std::sqrt(spread)) : 0.0);
        fit.evidence = std::min(fit.evidence, predicted > 0 ? gain[i][d] / predicted : 0.0);
      }
    }
    if (!std::isfinite(fit.noise_margin)) fit.noise_margin = 0;
    if (!std::isfinite(fit.evidence)) fit.evidence = 0;
    if (listed)
      std::tie(fit.listed_noise_margin, fit.listed_evidence) = listed_margins(
          *listed, fit, digit, squares, total, sums, gain, spread_of, predicted_of, variance, rho_x, rho_y);
    return fit;
  }

  // The noise margin and the evidence of the fit's id against the other ids in `listed`,
  // all the ids that may be in view (DetectorParams::ids_complete), the least over them:
  // each with all its differing squares moved at once. The others are ranked by adding
  // their squares' single moves, on either measure, and the kExactRivals nearest on each
  // refitted exactly. Zeros when the id is not listed; infinite when it is alone.
  std::pair<double, double> listed_margins(const std::vector<TagId>& listed, const Fit& fit,
                                           const std::vector<int>& digit,
                                           const std::vector<std::array<cv::Mat1f, 4>>& squares, const cv::Mat1f& total,
                                           const Sums& sums, const std::vector<std::array<double, 4>>& gain,
                                           const std::vector<std::array<double, 4>>& spread_of,
                                           const std::vector<std::array<double, 4>>& predicted_of, double variance,
                                           double rho_x, double rho_y) const {
    constexpr std::size_t kExactRivals = 4;
    if (std::find(listed.begin(), listed.end(), fit.id) == listed.end()) return {0.0, 0.0};
    const auto digit_of = [&](TagId id, std::size_t i) { return id.digit(family_.data_index(cells_[i])); };
    struct Rival {
      double noise_margin, evidence;
      TagId id;
    };
    std::vector<Rival> rivals;
    for (const TagId& other : listed) {
      if (other == fit.id) continue;
      double worse = 0, spread = 0, predicted = 0;
      for (std::size_t i = 0; i < cells_.size(); ++i)
        if (const int d = digit_of(other, i); d != digit[i])
          worse += gain[i][d], spread += spread_of[i][d], predicted += predicted_of[i][d];
      rivals.push_back(
          {spread > 0 ? worse / (2 * std::sqrt(spread)) : 0.0, predicted > 0 ? worse / predicted : 0.0, other});
    }
    const double inf = std::numeric_limits<double>::infinity();
    if (rivals.empty()) return {inf, inf};
    std::vector<TagId> nearest;
    const std::size_t exact = std::min(kExactRivals, rivals.size());
    for (const auto by : {&Rival::noise_margin, &Rival::evidence}) {
      std::partial_sort(rivals.begin(), rivals.begin() + std::ptrdiff_t(exact), rivals.end(),
                        [by](const Rival& a, const Rival& b) { return a.*by < b.*by; });
      for (std::size_t k = 0; k < exact; ++k)
        if (std::find(nearest.begin(), nearest.end(), rivals[k].id) == nearest.end()) nearest.push_back(rivals[k].id);
    }
    double least_margin = inf, least_evidence = inf;
    for (const TagId& other : nearest) {
      cv::Mat1f moved_total = total.clone();
      Sums s = sums;
      std::vector<int> now = digit;
      cv::Mat1d delta(total.size(), 0.0);
      for (std::size_t i = 0; i < cells_.size(); ++i) {
        const int d = digit_of(other, i);
        if (d == now[i]) continue;
        s = moved_in(moved_total, s, squares, now, i, d, cv::Rect(cv::Point(), squares_[i][0].rect.size()));
        const cv::Rect& r = squares_[i][0].rect;
        const cv::Mat1f change = squares[i][d] - squares[i][now[i]];
        moved_total(r) += change;
        for (int y = 0; y < r.height; ++y)
          for (int x = 0; x < r.width; ++x)
            if (use_(r.y + y, r.x + x)) delta(r.y + y, r.x + x) += change(y, x);
        now[i] = d;
      }
      const double worse = s.rss() - fit.rss, predicted = fit.ink * fit.ink * delta.dot(delta);
      const double spread = fit.ink * fit.ink * variance * correlated_power(delta, rho_x, rho_y);
      least_margin = std::min(least_margin, spread > 0 ? worse / (2 * std::sqrt(spread)) : 0.0);
      least_evidence = std::min(least_evidence, predicted > 0 ? worse / predicted : 0.0);
    }
    return {least_margin, least_evidence};
  }

  // The sums with cell i's square moved from position now[i] to d, over `total`: only
  // `reach` (within the square's rectangle) can change.
  Sums moved_in(const cv::Mat1f& total, const Sums& sums, const std::vector<std::array<cv::Mat1f, 4>>& squares,
                const std::vector<int>& now, std::size_t i, int d, const cv::Rect& reach) const {
    Sums s = sums;
    const cv::Rect& r = squares_[i][0].rect;
    for (int y = reach.y; y < reach.y + reach.height; ++y)
      for (int x = reach.x; x < reach.x + reach.width; ++x) {
        if (!use_(r.y + y, r.x + x)) continue;
        const double delta = squares[i][d](y, x) - squares[i][now[i]](y, x);
        if (delta == 0) continue;
        const double c = total(r.y + y, r.x + x), g = grey_(r.y + y, r.x + x);
        s.c += delta, s.cc += 2 * c * delta + delta * delta, s.gc += g * delta;
      }
    return s;
  }

  Family family_;
  cv::Point2d smear_;  // frame pixels
  cv::Rect box_;
  cv::Mat1f grey_, fixed_;
  cv::Mat1b use_;
  std::vector<int> cells_;                        // grid indices of the data cells
  std::vector<std::array<Coverage, 4>> squares_;  // per data cell, per position
};

// The quadrilaterals the marker's outline may be, given a coarse one: itself; itself with
// one corner replaced by the parallelogram of the other three (a spur of a broken border
// pulls one corner out); and the square of its area turned to the image's edges, taken for
// the outline and for the hull of the data squares (units 4.5 to S - 4.5), for when the
// border merged with the background and only the data is left.
std::vector<std::array<cv::Point2d, 4>> plausible_outlines(const std::array<cv::Point2d, 4>& outline, int side,
                                                           double edge_angle) {
  std::vector<std::array<cv::Point2d, 4>> out = {outline};
  for (int i = 0; i < 4; ++i) {
    std::array<cv::Point2d, 4> q = outline;
    q[i] = q[(i + 1) % 4] + q[(i + 3) % 4] - q[(i + 2) % 4];
    out.push_back(q);
  }
  const cv::Point2d centre = (outline[0] + outline[1] + outline[2] + outline[3]) / 4;
  const double half = std::sqrt(std::abs(quad_area(outline))) / 2;
  const cv::Point2d u(std::cos(edge_angle), std::sin(edge_angle)), v(-u.y, u.x);
  for (const double grow : {1.0, side / (side - 9.0)})
    out.push_back({centre + (-u - v) * half * grow, centre + (u - v) * half * grow, centre + (u + v) * half * grow,
                   centre + (v - u) * half * grow});  // clockwise with y down
  return out;
}

double pixels_per_unit_of(const std::array<cv::Point2d, 4>& outline, int side) {
  return std::sqrt(std::abs(quad_area(outline))) / side;
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
  std::vector<std::pair<double, std::vector<cv::Point>>> hulls, rings;  // area, hull
  std::vector<cv::Point> points;
  // The convex hull of piece j, with its area, when it is closed around a hole that holds
  // two or more pieces, or one piece and is a tenth of its hull or more: a marker's border
  // around its squares, some of which may have joined it. Empty otherwise (the hull is
  // taken only once a hole holds a piece: most pieces with holes in photos hold none).
  const auto closed_hull = [&](int j) -> std::pair<double, std::vector<cv::Point>> {
    std::vector<cv::Point> hull;
    double area = 0;
    for (int hole = hierarchy[j][2]; hole >= 0; hole = hierarchy[hole][0]) {
      int held = 0;
      for (int k = hierarchy[hole][2]; k >= 0 && held < 2; k = hierarchy[k][0]) ++held;
      if (held == 0) continue;
      if (hull.empty()) cv::convexHull(contours[j], hull), area = cv::contourArea(hull);
      if (held >= 2 || cv::contourArea(contours[hole]) >= 0.1 * area) return {area, std::move(hull)};
    }
    return {};
  };
  for (int i = 0; i < int(contours.size()); ++i) {
    // Outer boundaries of black pieces are at even depths; visit each parent's group once.
    if (depth(i) % 2 != 0 || hierarchy[i][1] >= 0) continue;
    std::vector<int> pieces;
    std::vector<cv::Rect> boxes;
    points.clear();
    for (int j = i; j >= 0; j = hierarchy[j][0]) {
      const cv::Rect r = cv::boundingRect(contours[j]);
      if ((r & inner) != r) continue;
      pieces.push_back(j), boxes.push_back(r);
      points.insert(points.end(), contours[j].begin(), contours[j].end());
    }
    if (points.size() < 4) continue;
    // A border closed around squares is also tried alone: a margin's edge beside it (the
    // ground seen through the local threshold, open where the sheet meets the patch's
    // bright surroundings) would otherwise be its group and hide it.
    if (pieces.size() > 1)
      for (const int j : pieces)
        if (auto ring = closed_hull(j); !ring.second.empty()) rings.push_back(std::move(ring));
    // The group grown from its largest piece by the pieces within a tenth of the group's
    // size: a speck of the margin or of the ground further off would pull a corner of the
    // hull out. Only specks are left out (at most a tenth of the group by the area of
    // their boxes): under motion blur a marker's own pieces lie further apart, and they
    // are much of it.
    const int largest = int(std::max_element(boxes.begin(), boxes.end(),
                                             [](const cv::Rect& a, const cv::Rect& b) { return a.area() < b.area(); }) -
                            boxes.begin());
    cv::Rect all = boxes[largest];
    for (const cv::Rect& r : boxes) all |= r;
    const int gap = std::max(4, std::max(all.width, all.height) / 10);
    std::vector<bool> taken(pieces.size(), false);
    taken[largest] = true;
    for (bool grew = true; grew;) {
      grew = false;
      for (std::size_t a = 0; a < pieces.size(); ++a) {
        if (taken[a]) continue;
        const cv::Rect near(boxes[a].x - gap, boxes[a].y - gap, boxes[a].width + 2 * gap, boxes[a].height + 2 * gap);
        for (std::size_t b = 0; b < pieces.size() && !taken[a]; ++b)
          if (taken[b] && (near & boxes[b]).area() > 0) taken[a] = grew = true;
      }
    }
    double ink = 0, left_out = 0;
    for (std::size_t a = 0; a < pieces.size(); ++a) (taken[a] ? ink : left_out) += boxes[a].area();
    if (left_out > 0 && left_out <= 0.1 * (ink + left_out)) {
      points.clear();
      for (std::size_t a = 0; a < pieces.size(); ++a)
        if (taken[a]) points.insert(points.end(), contours[pieces[a]].begin(), contours[pieces[a]].end());
    }
    std::vector<cv::Point> hull;
    cv::convexHull(points, hull);
    hulls.emplace_back(cv::contourArea(hull), std::move(hull));
  }
  // The groups largest first, then the borders tried alone.
  const auto larger = [](const auto& a, const auto& b) { return a.first > b.first; };
  std::sort(hulls.begin(), hulls.end(), larger);
  std::sort(rings.begin(), rings.end(), larger);
  hulls.insert(hulls.end(), std::make_move_iterator(rings.begin()), std::make_move_iterator(rings.end()));
  std::vector<std::array<cv::Point2d, 4>> out;
  for (const auto& [area, hull] : hulls) {
    if (out.size() == 3) break;
    if (area < 16) continue;
    std::vector<cv::Point> quad;
    const double perimeter = cv::arcLength(hull, true);
    for (double f = 0.02; f <= 0.2 && quad.size() != 4; f += 0.02) cv::approxPolyDP(hull, quad, f * perimeter, true);
    if (quad.size() != 4 || !cv::isContourConvex(quad)) {
      // Rounded corners can take the approximation from five vertices to three: the
      // hull's largest quadrilateral instead.
      const std::optional<std::array<int, 4>> largest =
          largest_quad(std::vector<cv::Point2d>(hull.begin(), hull.end()));
      if (!largest) continue;
      quad.clear();
      for (const int i : *largest) quad.push_back(hull[i]);
    }
    std::array<cv::Point2d, 4> corners;
    for (int i = 0; i < 4; ++i) corners[i] = frame.to_frame(cv::Point2d(quad[i]));
    // Clockwise on screen (y down): positive shoelace sum.
    if (quad_area(corners) < 0) std::reverse(corners.begin(), corners.end());
    out.push_back(corners);
  }
  return out;
}

bool ReadPlaces::seen(int n, const std::array<cv::Point2d, 4>& corners, double pixels_per_unit) const {
  for (const Place& p : places) {
    if (p.n != n) continue;
    // A unit of the smaller scale: alignments of one marker from different starts agree
    // to a fraction of one (the field experiment's quick plan, tuning and validation
    // frames of 3x3 and 6x6 under motion, H.264 at 1080p, bent and shadow: 9 repeated
    // reads, 0.54 to 1.71 px per unit, within 0.12 units of the first; no other pair of
    // a frame's readings within 4 units).
    const double reach = std::min(p.pixels_per_unit, pixels_per_unit);
    for (int turn = 0; turn < 4; ++turn) {
      bool near = true;
      for (int i = 0; i < 4 && near; ++i) near = cv::norm(p.corners[(i + turn) % 4] - corners[i]) <= reach;
      if (near) return true;
    }
  }
  return false;
}

void ReadPlaces::add(int n, const cv::Matx33d& homography, const Family& family, double pixels_per_unit) {
  Place p{n, {}, pixels_per_unit};
  for (int i = 0; i < 4; ++i) p.corners[i] = apply(homography, family.outer_corners()[i]);
  places.push_back(p);
}

std::optional<OutlineReading> read_outline(const ImageView& image, const std::array<cv::Point2d, 4>& coarse,
                                           const Family& family, double min_pixels_per_unit, const Deadline& deadline,
                                           ReadPlaces* read_places, std::optional<TagId> expected,
                                           const std::vector<TagId>* complete_ids) {
  const int side = family.side();
  // The frame around the coarse outline, with room for the alignment to move and for an
  // outline of the data squares only.
  std::vector<cv::Point2f> corners(coarse.begin(), coarse.end());
  cv::Rect box = cv::boundingRect(corners);
  const int grow = std::max(3, int(std::ceil(0.3 * std::max(box.width, box.height))));
  box = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) &
        cv::Rect(0, 0, image.width, image.height);
  if (box.width < 8 || box.height < 8) return std::nullopt;
  // Pixels per unit: small markers are enlarged to about two (bicubic, as the patches are,
  // where the alignment's own bilinear sampling breaks a diagonal border into dots), large
  // ones reduced to the template's three (the alignment's cost grows with the pixels, its
  // precision does not), and the template is blurred to the resolution of the crop.
  const double per_unit = pixels_per_unit_of(coarse, side);
  if (!(per_unit >= 0.2)) return std::nullopt;  // half the readable resolution, or degenerate
  // A large crop is reduced before anything else reads it: by interpolation for the search
  // of the start, which most outlines in photos do not pass, by the area average, which
  // costs several times more, for the alignment.
  const cv::Size reduced_size(std::max(8, int(std::lround(box.width * kTemplateScale / per_unit))),
                              std::max(8, int(std::lround(box.height * kTemplateScale / per_unit))));
  const auto reduced = [&](int interpolation) {
    cv::Mat1b pixels;
    cv::resize(image.mat()(box), pixels, reduced_size, 0, 0, interpolation);
    cv::Mat1f out;
    pixels.convertTo(out, CV_32F, 1.0 / 255);
    return out;
  };
  cv::Mat1f crop;
  if (per_unit > kTemplateScale)
    crop = reduced(cv::INTER_LINEAR);
  else
    image.mat()(box).convertTo(crop, CV_32F, 1.0 / 255);
  const double edge_angle = edge_direction(crop);
  if (per_unit < 1) {
    const int enlarge = std::clamp(int(std::ceil(2 / per_unit)), 1, 4);
    cv::resize(crop, crop, cv::Size(), enlarge, enlarge, cv::INTER_CUBIC);
  }
  // Crop pixels -> frame pixels.
  const double zx = double(crop.cols) / box.width, zy = double(crop.rows) / box.height;
  const cv::Matx33d to_frame(1 / zx, 0, 0.5 / zx - 0.5 + box.x, 0, 1 / zy, 0.5 / zy - 0.5 + box.y, 0, 0, 1);

  // The template: the structure blurred to the crop's resolution (read only from here on).
  double sigma = template_blur(per_unit);
  std::optional<BlurredStructure> drawn;
  const BlurredStructure& structure = blurred_structure(family, per_unit, drawn);
  cv::Mat1f defocused;                        // a defocused template that replaces it, see try_defocus
  const cv::Mat1f* templ = &structure.image;  // const: its pixels may be the shared table's
  const SparseTemplate& sparse = structure.sparse;
  const cv::Matx33d to_template = unit_to_template();
  const cv::Matx33d from_frame = to_frame.inv();
  const std::vector<std::array<cv::Point2d, 4>> outlines = plausible_outlines(coarse, side, edge_angle);
  // The alignment starts from the plausible outline where the structure correlates best.
  // Most outlines in photos are no marker: that correlation (about 0.6 to 0.9 for markers,
  // under 0.3 for nearly every other outline) spares them the alignment.
  const std::array<cv::Point2d, 4> unit_corners = family.outer_corners();
  const auto warp_of = [&](const std::array<cv::Point2d, 4>& outline) {
    std::vector<cv::Point2f> from, to;
    for (int i = 0; i < 4; ++i) {
      const cv::Point2d t = apply(to_template, unit_corners[i]), c = apply(from_frame, outline[i]);
      from.emplace_back(float(t.x), float(t.y));
      to.emplace_back(float(c.x), float(c.y));
    }
    cv::Mat w = cv::getPerspectiveTransform(from, to);
    w.convertTo(w, CV_32F);
    return w;
  };
  std::array<cv::Point2d, 4> start;
  double start_correlation = -1;
  for (const auto& outline : outlines)
    if (const double r = sparse.correlation(crop, warp_of(outline)); r > start_correlation)
      start_correlation = r, start = outline;
  // Where the structure shows at all, the start is moved, turned and scaled while that
  // makes it correlate better (halving the steps): the alignment's reach is about a unit,
  // which an outline of broken pieces can miss.
  if (start_correlation >= kMinStartCorrelation / 2) {
    double step_scale = 0.12, step_angle = 0.08, step_shift = 1.0 * per_unit;  // shift: one unit, in pixels
    for (int round = 0; round < 3; ++round, step_scale /= 2, step_angle /= 2, step_shift /= 2) {
      bool moved = true;
      for (int guard = 0; moved && guard < 4; ++guard) {
        moved = false;
        const cv::Point2d centre = (start[0] + start[1] + start[2] + start[3]) / 4;
        for (int move = 0; move < 8; ++move) {
          const double sign = move % 2 ? -1 : 1;
          double scale = 1, angle = 0;
          cv::Point2d shift;
          switch (move / 2) {
            case 0: scale = 1 + sign * step_scale; break;
            case 1: angle = sign * step_angle; break;
            case 2: shift.x = sign * step_shift; break;
            default: shift.y = sign * step_shift; break;
          }
          const cv::Matx22d r(std::cos(angle) * scale, -std::sin(angle) * scale, std::sin(angle) * scale,
                              std::cos(angle) * scale);
          std::array<cv::Point2d, 4> q;
          for (int i = 0; i < 4; ++i) {
            const cv::Vec2d d = r * cv::Vec2d(start[i].x - centre.x, start[i].y - centre.y);
            q[i] = centre + shift + cv::Point2d(d[0], d[1]);
          }
          if (const double c = sparse.correlation(crop, warp_of(q)); c > start_correlation + 1e-4) {
            start_correlation = c, start = q, moved = true;
            break;
          }
        }
      }
    }
  }
  if (start_correlation < kMinStartCorrelation) return std::nullopt;
  // The alignment, the costly part, moves a start by much less than a fifth of its scale:
  // in the range and blur sweeps every accepted reading started at 0.43 px per unit or
  // more, while most outlines of photos that get this far start under 0.3.
  const double start_per_unit = pixels_per_unit_of(start, side);
  if (start_per_unit < 0.8 * min_pixels_per_unit) {
    OutlineReading out;
    out.correlation = start_correlation, out.pixels_per_unit = start_per_unit;
    return out;
  }
  // From two pixels per unit a marker's structure shows plainly at its start, once a
  // motion blur is allowed for: in the range, blur and video sweeps every reading accepted
  // there had started at 0.68 or more, while the outlines of other families' markers and
  // of AprilTags start at 0.64 or less. Those are spared the alignment, which is most of
  // the cost of a frame that holds them. From 1.5 px per unit it shows less plainly: there
  // every reading accepted in the range, blur, pose and video sweeps had started at 0.648
  // or more, while a sharp 6x6 read as a 7x7 started at 0.41 to 0.43 and took three
  // alignments, none converging (up to 28 ms).
  const double min_start = start_per_unit >= kResolvedPixelsPerUnit ? kMinResolvedStartCorrelation
                           : start_per_unit >= kSharpPixelsPerUnit  ? kMinSharpStartCorrelation
                                                                    : 0.0;
  if (start_correlation < min_start) {
    // The structure smeared in eight directions over the lengths sought after the
    // alignment, blurred as at two to three pixels per unit (the bounds above were
    // measured with them): drawn once.
    static PerFamilySize<std::vector<SparseTemplate>> smeared_structures;
    const std::vector<SparseTemplate>& smeared = smeared_structures.get(family, [&] {
      std::vector<SparseTemplate> drawn;
      const cv::Mat1f blurred = blurred_template(sharp_structure(family), 0.5);
      std::vector<double> lengths;  // template pixels
      for (double units = 1.5; units <= kLongestSmearSought; units += 1.5) lengths.push_back(units * kTemplateScale);
      for (int a = 0; a < 8; ++a)
        for (SparseTemplate& t :
             SparseTemplate::smeared(blurred, 3, {std::cos(a * CV_PI / 8), std::sin(a * CV_PI / 8)}, lengths))
          drawn.push_back(std::move(t));
      return drawn;
    });
    const cv::Mat warp = warp_of(start);
    double best = start_correlation;
    for (std::size_t i = 0; i < smeared.size() && best < min_start && !deadline.passed(); ++i)
      best = std::max(best, smeared[i].correlation(crop, warp));
    if (best < min_start && !deadline.passed()) {
      OutlineReading out;
      out.correlation = best, out.pixels_per_unit = start_per_unit;
      return out;
    }
  }
  // Past the deadline no alignment (the costly part) starts, nor any reading of cells.
  const auto cut = [&](OutlineReading out) {
    out.past_deadline = true;
    return out;
  };
  if (deadline.passed()) {
    OutlineReading out;
    out.correlation = start_correlation, out.pixels_per_unit = start_per_unit;
    return cut(out);
  }
  if (per_unit > kTemplateScale) crop = reduced(cv::INTER_AREA);
  cv::Mat warp = warp_of(start);
  // Each alignment: at most 25 steps, until the correlation changes by less than 1e-4.
  const EccAlignment alignment(crop);
  const auto align = [&](const cv::Mat1f& t, cv::Mat& warp_to_crop) {
    cv::Matx33f w = warp_to_crop;
    const std::optional<double> c = alignment.align(t, w, 25, 1e-4);
    if (c) cv::Mat(w).copyTo(warp_to_crop);
    return c;
  };
  double correlation = 0;  // of the alignment that stands
  // Motion blur smears the structure along one direction, which the template does not: a
  // structure that aligned but correlates too little is tried smeared in several
  // directions and lengths, and aligned again with the one that correlates best.
  cv::Point2d smear, smear_crop;  // frame pixels, crop pixels
  // The linear part of `warp_to_crop` (template pixels -> crop pixels) at the template's centre.
  const auto jacobian_at_centre = [&](const cv::Mat& warp_to_crop) {
    const cv::Matx33f wf = warp_to_crop;
    const float cx = templ->cols / 2.0f, cy = templ->rows / 2.0f;
    const float z = wf(2, 0) * cx + wf(2, 1) * cy + wf(2, 2);
    const float mx = (wf(0, 0) * cx + wf(0, 1) * cy + wf(0, 2)) / z,
                my = (wf(1, 0) * cx + wf(1, 1) * cy + wf(1, 2)) / z;
    return cv::Matx22d((wf(0, 0) - mx * wf(2, 0)) / z, (wf(0, 1) - mx * wf(2, 1)) / z, (wf(1, 0) - my * wf(2, 0)) / z,
                       (wf(1, 1) - my * wf(2, 1)) / z);
  };
  // A smear of the crop in the pixels of a template that `warp_to_crop` maps onto it (its
  // linear part at the template's centre); none (zero) from a warp far from a marker's.
  const auto template_smear = [&](const cv::Mat& warp_to_crop, cv::Point2d along) {
    const cv::Vec2d t = jacobian_at_centre(warp_to_crop).inv() * cv::Vec2d(along.x, along.y);
    const cv::Point2d out(t[0], t[1]);
    return cv::norm(out) <= 2 * kLongestSmearSought * kTemplateScale ? out : cv::Point2d();
  };
  const auto template_kernel = [&](const cv::Mat& warp_to_crop, cv::Point2d along) {
    const cv::Point2d t = template_smear(warp_to_crop, along);
    return t == cv::Point2d() ? cv::Mat1f() : smear_kernel(t);
  };
  const auto smeared = [](const cv::Mat1f& t, const cv::Mat1f& kernel) {
    if (kernel.empty()) return t.clone();
    cv::Mat1f out;
    cv::filter2D(t, out, -1, kernel, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
    return out;
  };
  // Defocus blurs a small marker by more than its pixels do, which the template does not
  // either: a structure that correlates too little, or shows too little contrast, is tried
  // blurred by more, and aligned again with the blur that correlates best when that beats
  // `to_beat` (and the smears, below). `contrast_scale` then brings the contrast measured
  // below to the one the template's own blur would show, for the contrast check; the
  // margins stay measured against the contrast seen, as every other reading's are.
  double contrast_scale = 1;
  double defocus = 0;  // units, beyond the template's own blur (0: none found)
  // A defocus blurs the frame evenly: under `warp_to_crop`, a blur of `units` is in
  // template pixels one of the shape (J^T J)^-1 |det J| (determinant one; the identity on
  // a marker seen face on), J the warp's linear part, beside the template's own. None when
  // it stretches less than kMinDefocusStretch, where a round blur does as well, or more
  // than kMaxDefocusStretch.
  const auto uneven_defocus = [&](const cv::Mat& warp_to_crop, double units) -> std::optional<cv::Matx22d> {
    const cv::Matx22d jacobian = jacobian_at_centre(warp_to_crop);
    const cv::Matx22d shape = (jacobian.t() * jacobian).inv() * std::abs(cv::determinant(jacobian));
    const double stretch = std::sqrt(larger_eigenvalue(shape));
    if (!std::isfinite(stretch) || stretch < kMinDefocusStretch || stretch > kMaxDefocusStretch) return std::nullopt;
    return cv::Matx22d::eye() * (template_blur(per_unit) * template_blur(per_unit)) +
           shape * std::pow(units * kTemplateScale, 2);
  };
  bool uneven = false;  // the defocus found is uneven in the template
  const auto try_defocus = [&](double to_beat) {
    double best = to_beat, best_sigma = 0, best_units = 0;
    cv::Mat1f best_template;
    bool best_uneven = false;
    for (const double units : kDefocusUnits) {
      const double blur = std::hypot(sigma, units * kTemplateScale);
      const std::optional<cv::Matx22d> covariance = uneven_defocus(warp, units);
      const cv::Mat1f blurred = covariance ? blurred_template(sharp_structure(family), *covariance)
                                           : blurred_template(sharp_structure(family), blur, true);
      if (const double c = SparseTemplate(blurred, 3).correlation(crop, warp); c > best)
        best = c, best_sigma = blur, best_units = units, best_template = blurred, best_uneven = bool(covariance);
    }
    if (best_template.empty() || deadline.passed()) return false;
    cv::Mat again = warp.clone();
    const std::optional<double> c = align(best_template, again);
    if (!c || *c <= correlation) return true;  // the sharper alignment stands, and no smear beats it
    contrast_scale = structure_contrast(*templ) / structure_contrast(best_template);
    defocused = best_template;
    correlation = *c, warp = again, templ = &defocused, sigma = best_sigma, defocus = best_units;
    uneven = best_uneven;
    return true;
  };
  // The motion blur under which the structure correlates best with the crop under
  // `warp_to_crop`, and that correlation; none (zero) when none beats `to_beat`. Directions
  // every 22.5 degrees and lengths every 1.5 units, then half steps around the best (the
  // image's own least-gradient direction snaps to the marker's axes when the blur runs
  // diagonally, so it is searched).
  const double crop_per_unit = per_unit * zx;
  const auto seek_smear = [&](const cv::Mat& warp_to_crop, double to_beat) {
    double best = to_beat;
    cv::Point2d best_along;
    const auto try_smear = [&](double angle, double units) {
      const cv::Point2d along = cv::Point2d(std::cos(angle), std::sin(angle)) * units * crop_per_unit;
      const cv::Point2d in_template = template_smear(warp_to_crop, along);
      if (in_template == cv::Point2d()) return;
      if (const double c = SparseTemplate(*templ, 3, in_template).correlation(crop, warp_to_crop); c > best)
        best = c, best_along = along;
    };
    // The grid's lengths of one direction share their samples (SparseTemplate::smeared):
    // a smear's image in the template is linear in its length.
    for (int a = 0; a < 8; ++a) {
      const cv::Point2d unit_along = cv::Point2d(std::cos(a * CV_PI / 8), std::sin(a * CV_PI / 8)) * crop_per_unit;
      const cv::Point2d per_unit_in_template = template_smear(warp_to_crop, unit_along);
      const double stretch = cv::norm(per_unit_in_template);
      if (stretch == 0) continue;
      std::vector<double> units, lengths;  // units of the marker, template pixels
      for (double u = 1.5; u <= kLongestSmearSought; u += 1.5)
        if (template_smear(warp_to_crop, unit_along * u) != cv::Point2d())
          units.push_back(u), lengths.push_back(u * stretch);
      if (lengths.empty()) continue;
      const std::vector<SparseTemplate> grid =
          SparseTemplate::smeared(*templ, 3, per_unit_in_template / stretch, lengths);
      for (std::size_t k = 0; k < grid.size(); ++k)
        if (const double c = grid[k].correlation(crop, warp_to_crop); c > best)
          best = c, best_along = unit_along * units[k];
    }
    if (best_along != cv::Point2d()) {
      const double angle = std::atan2(best_along.y, best_along.x), units = cv::norm(best_along) / crop_per_unit;
      for (const double da : {-CV_PI / 16, 0.0, CV_PI / 16})
        for (const double du : {-0.75, 0.0, 0.75})
          if (da != 0 || du != 0) try_smear(angle + da, units + du);
    }
    return std::make_pair(best, best_along);
  };
  // The structure smeared `along` (crop pixels), aligned from `warp_to_crop`: it stands
  // when it correlates better than `to_beat`.
  const auto align_smeared = [&](const cv::Mat& warp_to_crop, cv::Point2d along, double to_beat) {
    cv::Mat again = warp_to_crop.clone();
    const cv::Mat1f smeared_structure = smeared(*templ, template_kernel(warp_to_crop, along));
    const std::optional<double> c = align(smeared_structure, again);
    if (!c || *c <= to_beat) return false;
    correlation = *c, warp = again, smear_crop = along;
    smear = {along.x / zx, along.y / zy};
    // A smear mixes the cores with the white round them as a defocus does: the contrast
    // check asks for the ink the unsmeared template would show.
    contrast_scale *= structure_contrast(*templ) / structure_contrast(smeared_structure);
    return true;
  };
  // Motion blur can also keep the sharp structure from aligning at all, or leave it
  // aligned under kMinSmearedCorrelation, where no smear is sought after the alignment: the
  // smears are then sought where the start puts the structure, and the best one is aligned
  // when it correlates there as well as an aligned structure must for a smear to be sought.
  std::optional<double> aligned_at = align(*templ, warp);
  if (aligned_at) correlation = *aligned_at;
  if ((!aligned_at || correlation < kMinSmearedCorrelation) && start_per_unit >= kMinSmearedStartPixelsPerUnit &&
      !deadline.passed()) {
    const cv::Mat at_start = warp_of(start);
    const auto [smeared_start, along] = seek_smear(at_start, start_correlation);
    if (along != cv::Point2d() && smeared_start >= kMinSmearedCorrelation &&
        align_smeared(at_start, along, aligned_at ? correlation : -1)) {
      aligned_at = correlation;
      // A defocus seen obliquely is longer across the tilt, much as a smear: where one
      // aligns better, it is the blur found.
      if (try_defocus(correlation) && defocus > 0) smear = smear_crop = cv::Point2d();
    }
  }
  if (!aligned_at) return std::nullopt;  // did not converge: not a marker's structure
  // An alignment that collapsed, shrinking the structure to under half its start's scale
  // (a true marker's moves it by much less, see above) and under the readable resolution
  // (onto a speck, or to nothing), is refused now, as the resolution check would refuse it
  // after the smear search, the defocus and the reading: aligning again from a collapse
  // does not undo it.
  {
    cv::Matx33d shrunk;
    cv::Mat(warp).convertTo(cv::Mat(3, 3, CV_64F, shrunk.val), CV_64F);
    const double aligned_per_unit = smallest_scale(to_frame * shrunk * to_template, {side / 2.0, side / 2.0});
    if (!(aligned_per_unit >= min_pixels_per_unit || aligned_per_unit >= start_per_unit / 2)) {
      OutlineReading out;
      out.correlation = correlation, out.pixels_per_unit = std::isfinite(aligned_per_unit) ? aligned_per_unit : 0;
      return out;
    }
  }
  if (correlation < kMinCorrelation && correlation >= kMinSmearedCorrelation && smear_crop == cv::Point2d()) {
    const auto [best, best_along] = seek_smear(warp, sparse.correlation(crop, warp));
    // (When the smeared alignment fails, the unsmeared one stands.)
    if (!try_defocus(best) && best_along != cv::Point2d() && !deadline.passed())
      align_smeared(warp, best_along, correlation);
  }
  cv::Matx33d w, aligned;  // units (some turn) -> frame pixels
  // Its black and white under the alignment: the cores, and the middle of the white ring.
  double black = 0, white = 0;
  std::vector<std::vector<CellLevels>> levels(family.n(), std::vector<CellLevels>(family.n()));
  const auto measure = [&] {
    cv::Mat(warp).convertTo(cv::Mat(3, 3, CV_64F, w.val), CV_64F);
    aligned = to_frame * w * to_template;
    if (!std::isfinite(aligned(2, 2)) || std::abs(aligned(2, 2)) < 1e-12) return false;
    black = 0;
    for (int r = 0; r < family.n(); ++r)
      for (int c = 0; c < family.n(); ++c) black += (levels[r][c] = cell_levels(image, aligned, r, c)).core;
    black /= family.cell_count();
    white = ring_level([&](double x, double y, double w, double h) { return mean_level(image, aligned, x, y, w, h); },
                       side);
    return true;
  };
  if (!measure()) return std::nullopt;
  // A structure that aligned well but shows little contrast may be a defocused marker too.
  if (correlation >= kMinCorrelation && white > black && white - black < kMinContrast && defocus == 0 &&
      smear_crop == cv::Point2d()) {
    try_defocus(sparse.correlation(crop, warp));
    if (defocus > 0 && !measure()) return std::nullopt;
  }

  OutlineReading out;
  out.correlation = correlation;
  out.pixels_per_unit = smallest_scale(aligned, {side / 2.0, side / 2.0});
  out.contrast = (white - black) * contrast_scale;
  out.defocus = defocus;
  // A ring as dark as the cores (a defocus of more than those sought mixes them): the
  // reading fails the contrast check, and the trace says so.
  if (out.contrast <= 0) return out;
  const auto level = [&](double g) { return (g - black) / (white - black); };
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
  // What the reading below cannot change decides first: it is the expensive part (each of
  // its pixel models fits 6 to 15 blurs, and a reading makes two to four). The resolution
  // is the alignment's: at 1080p most of a frame's time went to readings under
  // min_pixels_per_unit, all refused after the reading.
  out.smear = PixelModel::least_smear(smear) / out.pixels_per_unit;
  if (out.pixels_per_unit < min_pixels_per_unit || out.correlation < kMinCorrelation || out.contrast < kMinContrast ||
      out.baseline_gap < kMinBaselineGap)
    return out;  // margin and marker correlation 0: not acceptable
  if (read_places) {
    std::array<cv::Point2d, 4> corners;
    for (int i = 0; i < 4; ++i) corners[i] = apply(aligned, family.outer_corners()[i]);
    if (read_places->seen(family.n(), corners, out.pixels_per_unit)) {
      out.repeated = true;
      return out;
    }
  }
  // Aligned corner `best` (clockwise from the aligned top-left) is the true top-left.
  const cv::Matx33d h = aligned * turn(best, side);
  out.homography = h;
  // The id: each data cell read from grey levels sampled under h (fast, but blurred by the
  // sampling), then every cell's square moved to where the marker's predicted pixels fit
  // the frame's best (PixelModel).
  // A marker of more than kTemplateScale pixels per unit is modelled on its pixels reduced
  // to that (the area average, as a coarser camera would see it): the model's cost grows
  // with its pixels and with its blurs' reach, and a square's one-unit shift shows plainly
  // at three pixels.
  const auto read_id = [&](const cv::Matx33d& under) -> std::optional<PixelModel::Reading> {
    const TagId sampled = read_cells(image, under, family, out.pixels_per_unit);
    if (out.pixels_per_unit <= kTemplateScale) {
      const PixelModel model(image, under, family, out.pixels_per_unit, smear);
      if (!model.valid()) return std::nullopt;
      return model.read(sampled, out.pixels_per_unit, white - black, complete_ids);
    }
    const cv::Rect region = PixelModel::pixels_read(image, under, family, out.pixels_per_unit, smear);
    if (region.empty()) return std::nullopt;
    const double scale = kTemplateScale / out.pixels_per_unit;
    cv::Mat1b reduced;
    cv::resize(image.mat()(region), reduced,
               cv::Size(std::max(1, int(std::lround(region.width * scale))),
                        std::max(1, int(std::lround(region.height * scale)))),
               0, 0, cv::INTER_AREA);
    const double sx = double(reduced.cols) / region.width, sy = double(reduced.rows) / region.height;
    // Frame pixels -> reduced pixels (pixel centres map to pixel centres).
    const cv::Matx33d to_reduced(sx, 0, (0.5 - region.x) * sx - 0.5, 0, sy, (0.5 - region.y) * sy - 0.5, 0, 0, 1);
    const double reduced_per_unit = out.pixels_per_unit * std::sqrt(sx * sy);
    const PixelModel model(ImageView(reduced), to_reduced * under, family, reduced_per_unit,
                           cv::Point2d(smear.x * sx, smear.y * sy));
    if (!model.valid()) return std::nullopt;
    PixelModel::Reading r = model.read(sampled, reduced_per_unit, white - black, complete_ids);
    r.smear *= out.pixels_per_unit / reduced_per_unit;  // frame pixels
    return r;
  };
  if (deadline.passed()) return cut(out);
  out.read = true;
  const auto take = [&](const PixelModel::Reading& r) {
    out.id = r.id;
    out.margin = r.margin;
    out.noise_margin = r.noise_margin;
    out.evidence = r.evidence;
    out.listed_noise_margin = r.listed_noise_margin, out.listed_evidence = r.listed_evidence;
    out.model_ink = r.ink;
    out.smear = r.smear / out.pixels_per_unit;
  };
  // The marker to align first: the id expected, or the one the cells' sampled grey levels
  // give under the structure's alignment. Only the pixel model's readings under the whole
  // marker's alignment below decide: a model of the pixels is most of a reading's cost,
  // and one under the structure's alignment, less exact, could only make margins smaller.
  out.id = expected ? *expected : read_cells(image, h, family, out.pixels_per_unit);
  out.margin = out.noise_margin = out.model_ink = std::numeric_limits<double>::infinity();
  out.smear = 0;

  // The final homography: the whole marker of the id read, every square in place, aligned
  // again from there; it must fit as well as the structure did, and the cells read under
  // it must give the same id. A reading at the edge of resolution can change its mind once
  // the squares are in place: then the marker of the new reading is aligned in turn.
  cv::Matx33d current = h;
  for (int attempt = 0; attempt < 3; ++attempt) {
    if (deadline.passed()) {
      out.marker_correlation = 0;
      return cut(out);
    }
    cv::Mat1f whole = marker_template(family, out.id);
    const cv::Matx33d start = from_frame * current * to_template.inv();
    cv::Mat refined(3, 3, CV_32F);
    for (int i = 0; i < 9; ++i) refined.at<float>(i / 3, i % 3) = float(start.val[i] / start.val[8]);
    // (The marker's true turn: an uneven blur is shaped under its own warp.)
    if (const auto covariance = uneven ? uneven_defocus(refined, defocus) : std::nullopt)
      whole = blurred_template(whole, *covariance);
    else if (sigma > 0.3)
      whole = blurred_template(whole, sigma, defocus > 0);
    if (smear_crop != cv::Point2d()) whole = smeared(whole, template_kernel(refined, smear_crop));
    const std::optional<double> marker_correlation = align(whole, refined);
    if (!marker_correlation) {
      out.marker_correlation = 0;  // fails the checks
      return out;
    }
    out.marker_correlation = *marker_correlation;
    cv::Mat(refined).convertTo(cv::Mat(3, 3, CV_64F, w.val), CV_64F);
    const cv::Matx33d final_h = to_frame * w * to_template;
    if (!std::isfinite(final_h(2, 2)) || std::abs(final_h(2, 2)) < 1e-12) {
      out.marker_correlation = 0;
      return out;
    }
    out.homography = current = final_h;
    const auto again = read_id(final_h);
    if (!again) return std::nullopt;
    if (again->id == out.id) {
      out.margin = std::min(out.margin, again->margin);
      out.noise_margin = std::min(out.noise_margin, again->noise_margin);
      out.model_ink = std::min(out.model_ink, again->ink);
      out.evidence = again->evidence;  // the final alignment's: the first reading's is a start
      out.listed_noise_margin = again->listed_noise_margin, out.listed_evidence = again->listed_evidence;
      out.smear = std::max(out.smear, again->smear / out.pixels_per_unit);
      return out;
    }
    take(*again);
  }
  out.margin = out.noise_margin = out.evidence = out.model_ink = 0;  // the reading never settled
  return out;
}

Stage outline_stage(const OutlineReading& r, const DetectorParams& params) {
  // Measured on the range and blur renders and on marker-free photos (docs/BENCHMARKS.md),
  // with the pixel model's reading: true readings align at 0.78 to 0.99 and have margins
  // around 0.15 (5 % under 0.01); wrong readings above the resolution bound had margins up
  // to 0.022 (below it, up to 0.09), and under motion blur none passed once the blur's
  // length is fitted.
  // Too small to read first (read_outline decides it first for a start far under the
  // bound), then in the order read_outline decides them.
  if (r.past_deadline) return Stage::deadline;
  if (r.repeated) return Stage::duplicate;
  if (r.pixels_per_unit < params.min_pixels_per_unit) return Stage::resolution;
  if (r.correlation < kMinCorrelation) return Stage::structure;
  if (r.contrast < kMinContrast) return Stage::contrast;
  if (r.baseline_gap < kMinBaselineGap) return Stage::baselines;
  if (!(r.model_ink > kMinModelInk)) return Stage::margin;
  if ((r.margin < kMinMargin || r.evidence < kMinEvidence) &&
      !(params.ids_complete && r.listed_noise_margin >= kMinListedNoiseMargin && r.listed_evidence >= kMinEvidence))
    return Stage::margin;
  if (r.marker_correlation < kMinMarkerCorrelation) return Stage::marker;
  return Stage::detected;
}

}  // namespace lftag::detail
