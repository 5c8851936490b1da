// SPDX-License-Identifier: LGPL-2.1-or-later
// Initial poses, their evaluation and decoding (paper IV-F to IV-H). K2 and K3 each have
// four possible positions, so there are 16 hypotheses. Each is a homography from the four
// key points (exact and closed-form, and it needs no camera intrinsics), scored by the
// image gradient along the projected inner border edge; under each, every data cell takes
// the nearest observed centroid among its four possible centres. The best normalised
// residual wins.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {

double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

std::optional<cv::Matx33d> fit_homography(const std::vector<cv::Point2d>& from, const std::vector<cv::Point2d>& to) {
  const std::size_t count = from.size();
  if (count < 4 || to.size() != count) return std::nullopt;
  // Normalise both point sets (centroid at 0, mean distance sqrt 2) for conditioning.
  auto normaliser = [](const std::vector<cv::Point2d>& pts) {
    cv::Point2d c;
    for (const cv::Point2d& p : pts) c += p;
    c *= 1.0 / pts.size();
    double d = 0;
    for (const cv::Point2d& p : pts) d += cv::norm(p - c);
    const double s = d > 0 ? std::sqrt(2.0) * pts.size() / d : 1.0;
    return cv::Matx33d(s, 0, -s * c.x, 0, s, -s * c.y, 0, 0, 1);
  };
  const cv::Matx33d tf = normaliser(from), tt = normaliser(to);
  Eigen::Matrix<double, 8, 8> ata = Eigen::Matrix<double, 8, 8>::Zero();
  Eigen::Matrix<double, 8, 1> atb = Eigen::Matrix<double, 8, 1>::Zero();
  for (std::size_t i = 0; i < count; ++i) {
    const double u = tf(0, 0) * from[i].x + tf(0, 2), v = tf(1, 1) * from[i].y + tf(1, 2);
    const double x = tt(0, 0) * to[i].x + tt(0, 2), y = tt(1, 1) * to[i].y + tt(1, 2);
    Eigen::Matrix<double, 8, 1> rx, ry;
    rx << u, v, 1, 0, 0, 0, -x * u, -x * v;
    ry << 0, 0, 0, u, v, 1, -y * u, -y * v;
    ata += rx * rx.transpose() + ry * ry.transpose();
    atb += rx * x + ry * y;
  }
  const Eigen::Matrix<double, 8, 1> h = ata.ldlt().solve(atb);
  if (!h.allFinite()) return std::nullopt;
  const cv::Matx33d hn(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0);
  // In normalised coordinates a homography between two spread point sets has a determinant
  // near 1; collinear or coincident points leave it (near) singular.
  if (!(std::abs(cv::determinant(hn)) > 1e-6)) return std::nullopt;
  return tt.inv() * hn * tf;
}

void distort(const Camera& camera, std::vector<cv::Point2d>& points) {
  if (!camera.has_distortion() || points.empty()) return;
  std::vector<cv::Point3d> rays;
  rays.reserve(points.size());
  for (const cv::Point2d& p : points)
    rays.emplace_back((p.x - camera.cx) / camera.fx, (p.y - camera.cy) / camera.fy, 1.0);
  points = camera.project(rays);
}

namespace {

// The Jacobian of h at unit point u (central differences): units -> pixels.
cv::Matx22d units_to_pixels(const cv::Matx33d& h, cv::Point2d u) {
  const cv::Point2d dx = apply(h, u + cv::Point2d(0.5, 0)) - apply(h, u - cv::Point2d(0.5, 0));
  const cv::Point2d dy = apply(h, u + cv::Point2d(0, 0.5)) - apply(h, u - cv::Point2d(0, 0.5));
  return cv::Matx22d(dx.x, dy.x, dx.y, dy.y);
}

// The local inverse of h at unit point u: pixels -> units.
cv::Matx22d pixels_to_units(const cv::Matx33d& h, cv::Point2d u) { return units_to_pixels(h, u).inv(); }

// The length in units of `off` (pixels), a blob's offset from unit point u under h.
double offset_in_units(const cv::Matx33d& h, cv::Point2d u, cv::Point2d off) {
  return cv::norm(pixels_to_units(h, u) * cv::Vec2d(off.x, off.y));
}

// The homography taking the unit square's corners (0, 0), (1, 0), (1, 1), (0, 1) to q[0]
// .. q[3] (the projective map of a square onto a quadrilateral, in closed form); none when
// three of the corners are collinear.
std::optional<cv::Matx33d> square_to_quad(const std::array<cv::Point2d, 4>& q) {
  const cv::Point2d sum = q[0] - q[1] + q[2] - q[3];
  const cv::Point2d d1 = q[1] - q[2], d2 = q[3] - q[2];
  const double den = d1.cross(d2);
  if (!(std::abs(den) > 0)) return std::nullopt;
  const double g = sum.cross(d2) / den, h = d1.cross(sum) / den;
  return cv::Matx33d(q[1].x - q[0].x + g * q[1].x, q[3].x - q[0].x + h * q[3].x, q[0].x, q[1].y - q[0].y + g * q[1].y,
                     q[3].y - q[0].y + h * q[3].y, q[0].y, g, h, 1.0);
}

// The homography taking the four points `from` to `to` (h33 = 1): through the unit square.
// None when either set has three collinear points.
std::optional<cv::Matx33d> four_point_homography(const std::array<cv::Point2d, 4>& from,
                                                 const std::array<cv::Point2d, 4>& to) {
  const auto a = square_to_quad(from), b = square_to_quad(to);
  if (!a || !b) return std::nullopt;
  const double det = cv::determinant(*a);
  if (!(std::abs(det) > 0)) return std::nullopt;
  cv::Matx33d m = *b * a->inv();
  if (!(std::abs(m(2, 2)) > 0)) return std::nullopt;
  m *= 1.0 / m(2, 2);
  for (int i = 0; i < 9; ++i)
    if (!std::isfinite(m.val[i])) return std::nullopt;
  return m;
}

// The 3x3 Sobel gradient at pixel (x, y), edges replicated.
cv::Vec2d sobel(const ImageView& im, int x, int y) {
  const int xm = std::max(x - 1, 0), xp = std::min(x + 1, im.width - 1);
  const std::uint8_t* up = im.data + std::max(y - 1, 0) * im.stride;
  const std::uint8_t* mid = im.data + y * im.stride;
  const std::uint8_t* down = im.data + std::min(y + 1, im.height - 1) * im.stride;
  const int gx = (up[xp] + 2 * mid[xp] + down[xp]) - (up[xm] + 2 * mid[xm] + down[xm]);
  const int gy = (down[xm] + 2 * down[x] + down[xp]) - (up[xm] + 2 * up[x] + up[xp]);
  return {double(gx), double(gy)};
}

// `value(x, y)` at a sub-pixel point, bilinear between the four pixels around it (the
// point clamped into the image).
template <class Value>
auto bilinear(const ImageView& im, cv::Point2d p, Value value) {
  const double x = std::clamp(p.x, 0.0, im.width - 1.0), y = std::clamp(p.y, 0.0, im.height - 1.0);
  const int x0 = std::clamp(int(x), 0, std::max(0, im.width - 2));
  const int y0 = std::clamp(int(y), 0, std::max(0, im.height - 2));
  const int x1 = std::min(x0 + 1, im.width - 1), y1 = std::min(y0 + 1, im.height - 1);
  const double fx = x - x0, fy = y - y0;
  return (1 - fx) * (1 - fy) * value(x0, y0) + fx * (1 - fy) * value(x1, y0) + (1 - fx) * fy * value(x0, y1) +
         fx * fy * value(x1, y1);
}

// Sobel gradient magnitude at a sub-pixel point, bilinear between pixel gradients.
double gradient_at(const ImageView& im, cv::Point2d p) {
  const cv::Vec2d g = bilinear(im, p, [&](int x, int y) { return sobel(im, x, y); });
  return std::sqrt(g[0] * g[0] + g[1] * g[1]);  // std::hypot guards against overflow, at a cost
}

}  // namespace

double grey_at(const ImageView& im, cv::Point2d p) {
  return bilinear(im, p, [&](int x, int y) { return double(im.data[y * im.stride + x]); });
}

namespace {

std::vector<cv::Point2d> square(double a, double b) {
  return {cv::Point2d(a, a), cv::Point2d(b, a), cv::Point2d(b, b), cv::Point2d(a, b)};
}

// For 2x2, where the four blobs fix the homography and leave no residual: the grey levels
// where reading `id` under h must be black (the square centres and the middle of the
// border) and white (the middle of the white ring inside the border and the middle of the
// cross between the squares).
struct Photometry {
  std::vector<cv::Point2d> black_units, white_units, pixels;
  std::vector<double> black, white;
};
Photometry photometry(const Family& f, TagId id, const cv::Matx33d& h, const ImageView& image, const Camera& camera) {
  Photometry m;
  const double s = f.side();
  for (int g = 0; g < f.cell_count(); ++g)
    m.black_units.push_back(f.center(g, f.is_baseline(g) ? 0 : id.digit(f.data_index(g))));
  for (int i = 0; i < 8; ++i) {
    const double t = 1 + (s - 2) * (i + 0.5) / 8;  // along the border's middle line
    for (const cv::Point2d& p :
         {cv::Point2d(t, 1), cv::Point2d(s - 1, t), cv::Point2d(s - t, s - 1), cv::Point2d(1, s - t)})
      m.black_units.push_back(p);
    const double r = 3 + (s - 6) * (i + 0.5) / 8;  // along the white ring
    for (const cv::Point2d& p :
         {cv::Point2d(r, 3), cv::Point2d(s - 3, r), cv::Point2d(s - r, s - 3), cv::Point2d(3, s - r)})
      m.white_units.push_back(p);
  }
  m.white_units.emplace_back(s / 2, s / 2);
  auto grey = [&](const std::vector<cv::Point2d>& units, std::vector<double>& out) {
    m.pixels.clear();
    for (const cv::Point2d& u : units) m.pixels.push_back(apply(h, u));
    distort(camera, m.pixels);
    out.clear();
    for (const cv::Point2d& p : m.pixels) out.push_back(grey_at(image, p));
  };
  grey(m.black_units, m.black);
  grey(m.white_units, m.white);
  return m;
}

// The fraction of (should-be-white, should-be-black) sample pairs whose grey levels are in
// the wrong order.
double misordered_pairs(const Family& f, TagId id, const cv::Matx33d& h, const ImageView& image, const Camera& camera) {
  Photometry m = photometry(f, id, h, image, camera);
  // For each white sample, the black samples at least as bright (sorted: n log n, where
  // every pair was n^2).
  std::sort(m.black.begin(), m.black.end());
  std::size_t wrong = 0;
  for (double wv : m.white) wrong += std::size_t(m.black.end() - std::lower_bound(m.black.begin(), m.black.end(), wv));
  return double(wrong) / (m.white.size() * m.black.size());
}

// Whether no sample that must be white is as dark as one that must be black (the
// misordered pairs are none).
bool no_misordered_pair(const Family& f, TagId id, const cv::Matx33d& h, const ImageView& image, const Camera& camera) {
  const Photometry m = photometry(f, id, h, image, camera);
  return *std::min_element(m.white.begin(), m.white.end()) > *std::max_element(m.black.begin(), m.black.end());
}

// See Decoding::ink_spread.
double square_ink_spread(const Candidate& c, const Decoding& d) {
  const Family& f = c.family;
  std::vector<cv::Point2d> units;
  std::vector<double> area;
  for (int g = 0; g < f.cell_count(); ++g) {
    const UnitRect sq = f.square(g, f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g)));
    units.emplace_back(sq.x + sq.width / 2, sq.y + sq.height / 2);
    area.push_back(sq.width * sq.height);
  }
  const cv::Matx33d& h = d.homography;
  const double det = cv::determinant(h);
  double lo = 1e300, hi = 0;
  for (int g = 0; g < f.cell_count(); ++g) {
    // The Jacobian of a homography at (x, y) has determinant det(H) / w^3.
    const double w = h(2, 0) * units[g].x + h(2, 1) * units[g].y + h(2, 2);
    const double ink = c.blobs[d.blob_of_cell[g]].mass / (std::abs(det / (w * w * w)) * area[g]);
    lo = std::min(lo, ink), hi = std::max(hi, ink);
  }
  return lo > 0 ? hi / lo : 1e300;
}

}  // namespace

double smallest_scale(const cv::Matx33d& h, cv::Point2d u) {
  // The singular values of a 2x2 matrix in closed form: their squares sum to the squared
  // entries and their product is the determinant.
  const cv::Matx22d j = units_to_pixels(h, u);
  const double squares = j(0, 0) * j(0, 0) + j(0, 1) * j(0, 1) + j(1, 0) * j(1, 0) + j(1, 1) * j(1, 1);
  const double det = std::abs(j(0, 0) * j(1, 1) - j(0, 1) * j(1, 0));
  const double largest = std::sqrt((squares + std::sqrt(std::max(0.0, squares * squares - 4 * det * det))) / 2);
  const double smallest = largest > 0 ? det / largest : 0.0;
  return std::isfinite(smallest) ? smallest : 0.0;
}

double edge_gradient(const ImageView& image, const Camera& camera, const cv::Matx33d& h, double a, double b) {
  // About one sample per pixel of projected edge, at least 8 and at most 16 per side: the
  // score is a mean, and more samples on a large marker only cost time (64 per side made
  // this half of a frame's time with six 150 px markers in it).
  const std::vector<cv::Point2d> corners = square(a, b);
  std::vector<cv::Point2d> samples;
  for (int side = 0; side < 4; ++side) {
    const cv::Point2d u0 = corners[side], u1 = corners[(side + 1) % 4];
    const int count = std::clamp(int(cv::norm(apply(h, u1) - apply(h, u0))), 8, 16);
    for (int i = 0; i < count; ++i) samples.push_back(apply(h, u0 + (u1 - u0) * ((i + 0.5) / count)));
  }
  distort(camera, samples);
  double sum = 0;
  for (const cv::Point2d& p : samples) sum += gradient_at(image, p);
  return sum / samples.size();
}

namespace {

// The design centre of every cell for every digit, [g][digit] (a baseline's centre for
// every digit), per family: computed once.
using CellCentres = std::vector<std::array<cv::Point2d, 4>>;
const CellCentres& design_centres(const Family& f) {
  static const std::array<CellCentres, Family::kMaxN + 1> table = [] {
    std::array<CellCentres, Family::kMaxN + 1> t;
    for (int n = 2; n <= Family::kMaxN; ++n) {
      const Family family(n);
      t[n].resize(family.cell_count());
      for (int g = 0; g < family.cell_count(); ++g)
        for (int v = 0; v < 4; ++v) t[n][g][v] = family.center(g, family.is_baseline(g) ? 0 : v);
    }
    return t;
  }();
  return table[f.n()];
}

// Every design centre under homography h, [g][digit].
void project_centres(const CellCentres& design, const cv::Matx33d& h, CellCentres& out) {
  out.resize(design.size());
  for (std::size_t g = 0; g < design.size(); ++g)
    for (int v = 0; v < 4; ++v) out[g][v] = apply(h, design[g][v]);
}

// A candidate's blobs with finite centroids in the order of x, and their x: the search
// for the nearest blob stops where x alone puts the rest further than the nearest so far
// (an 8x8 marker's 64 blobs were each measured from every position of every cell, under
// each of the 16 hypotheses). Sorted once per candidate.
struct BlobsByX {
  std::vector<int> index;
  std::vector<double> x;
  explicit BlobsByX(const Candidate& c) {
    for (int j = 0; j < int(c.blobs.size()); ++j)
      if (std::isfinite(c.blobs[j].point.x) && std::isfinite(c.blobs[j].point.y)) index.push_back(j);
    std::sort(index.begin(), index.end(), [&](int a, int b) { return c.blobs[a].point.x < c.blobs[b].point.x; });
    for (const int j : index) x.push_back(c.blobs[j].point.x);
  }
};

// Under a homography whose design centres project to `projected`, each data cell takes
// the blob and position (of its four) nearest to each other. False when two cells claim
// one blob: then the homography cannot be this marker's.
bool assign_cells(const Candidate& c, const BlobsByX& by_x, const KeyPoints& k, const CellCentres& projected,
                  Decoding& d) {
  const Family& f = c.family;
  const std::array<int, 4> kc = f.keypoint_cells();
  std::vector<char> used(c.blobs.size(), 0);
  d.blob_of_cell.assign(f.cell_count(), -1);
  d.blob_of_cell[kc[0]] = k.blob[0], d.blob_of_cell[kc[1]] = k.blob[1];
  used[k.blob[0]] = used[k.blob[1]] = 1;
  const std::vector<double>& xs = by_x.x;
  for (int g = 0; g < f.cell_count(); ++g) {
    if (f.is_baseline(g)) continue;
    // The least distance wins; of equal ones, the first position, then the first blob.
    double nearest = std::numeric_limits<double>::max();
    int blob = -1, blob_position = -1;
    for (int v = 0; v < 4; ++v) {
      const cv::Point2d p = projected[g][v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
      const auto consider = [&](std::size_t i) {
        const int j = by_x.index[i];
        const cv::Point2d e = c.blobs[j].point - p;
        const double distance = e.dot(e);
        if (distance < nearest || (distance == nearest && v == blob_position && j < blob))
          nearest = distance, blob = j, blob_position = v;
      };
      const std::size_t first = std::size_t(std::lower_bound(xs.begin(), xs.end(), p.x) - xs.begin());
      for (std::size_t i = first; i < xs.size() && (xs[i] - p.x) * (xs[i] - p.x) <= nearest; ++i) consider(i);
      for (std::size_t i = first; i-- > 0 && (p.x - xs[i]) * (p.x - xs[i]) <= nearest;) consider(i);
    }
    if (blob < 0 || used[blob]) return false;  // no finite projection, or a blob claimed twice
    used[blob] = 1;
    d.blob_of_cell[g] = blob;
  }
  return true;
}

// True when h maps the whole marker to finite points in front of the camera: the
// homogeneous scale keeps one sign over the marker's corners (a plane seen from the
// front), so no projection wraps through infinity.
bool maps_marker(const Family& f, const cv::Matx33d& h) {
  double first = 0;
  for (const cv::Point2d& u : f.outer_corners()) {
    const cv::Vec3d q = h * cv::Vec3d(u.x, u.y, 1.0);
    if (!std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2]) || q[2] == 0) return false;
    if (first == 0)
      first = q[2];
    else if ((q[2] > 0) != (first > 0))
      return false;
  }
  return true;
}

// With the blobs assigned, each data cell's digit is its position nearest to its blob under
// d.homography (whose design centres project to `projected`); fills the id and returns the
// squared residual (pixels^2). With `worst`, also the worst cell (units).
double read_digits(const Candidate& c, const CellCentres& design, const CellCentres& projected, Decoding& d,
                   bool worst) {
  const Family& f = c.family;
  double residual = 0;
  d.id = TagId();
  d.worst_cell = 0;
  for (int g = 0; g < f.cell_count(); ++g) {
    if (f.is_baseline(g)) continue;
    const cv::Point2d blob = c.blobs[d.blob_of_cell[g]].point;
    double nearest = std::numeric_limits<double>::max();
    int digit = 0;
    for (int v = 0; v < 4; ++v) {
      const cv::Point2d e = blob - projected[g][v];
      if (e.dot(e) < nearest) nearest = e.dot(e), digit = v;
    }
    d.id = d.id.with_digit(f.data_index(g), digit);
    residual += nearest;
    if (!worst) continue;
    const cv::Point2d off = blob - projected[g][digit];
    d.worst_cell = std::max(d.worst_cell, offset_in_units(d.homography, design[g][digit], off));
  }
  return residual;
}

// Detection::noise_margin of a reading of 3x3 or larger: each data cell's blob's distance
// from the line halfway to its runner-up position, over the blobs' scatter about their
// decoded positions (the residual of the homography through all n^2 of them, its 8 degrees
// of freedom taken off; at least 0.02 px, what the centroids' rounding leaves on a sharp
// render), least over the cells. The scatter is measured on the marker itself, so the
// margin means the same at every size, blur and codec.
double digit_noise_margin(const Candidate& c, const CellCentres& design, const Decoding& d) {
  const Family& f = c.family;
  CellCentres projected;
  project_centres(design, d.homography, projected);
  double squares = 0, least = std::numeric_limits<double>::infinity();
  for (int g = 0; g < f.cell_count(); ++g) {
    const cv::Point2d blob = c.blobs[d.blob_of_cell[g]].point;
    const int digit = f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g));
    const cv::Point2d own = projected[g][digit];
    squares += (blob - own).dot(blob - own);
    if (f.is_baseline(g)) continue;
    for (int v = 0; v < 4; ++v) {
      if (v == digit) continue;
      // Signed distance from the perpendicular bisector of own and the other position.
      const cv::Point2d other = projected[g][v], axis = other - own;
      const double length = std::sqrt(axis.dot(axis));
      if (!(length > 0)) return 0;
      least = std::min(least, ((other - blob).dot(other - blob) - (own - blob).dot(own - blob)) / (2 * length));
    }
  }
  const int freedom = 2 * f.cell_count() - 8;
  if (freedom <= 0 || !std::isfinite(least)) return 0;
  return least / std::max(std::sqrt(squares / freedom), 0.02);
}

// A sheet bent round a cylinder moves its squares smoothly, and a band of rows (or
// columns) away from the middle can land a whole unit from where a flat marker would put
// it: read flat, that is the band shifted, another id (a 4x4 on a 0.15 to 0.4 m cylinder
// in the field experiment was read so for three frames), or no id at all. A grid free to
// bow models it: the reading's homography h plus a map b(u) of unit offsets, seen through
// h, so a square at u lies at h(u) + J_h(u) b(u), linear in b's coefficients.
// - From 4x4 the bow is free: b quadratic in u, 12 coefficients. With the homography's 8
//   parameters, 14 are fitted (b's constant and linear terms move h's affine part).
// - A 3x3 has three rows, and a free bow fits any one row's shift: its grid may only bend
//   as a sheet does. b keeps its constant and linear terms (h's affine part refitted),
//   and the squares leave the sheet's tangent plane by a depth z(u) quadratic in u (a
//   cylinder of any axis, or a dome): a square at u moves along the image of the sheet's
//   normal, by z(u). 3 parameters beyond the homography's 8; a row shifted a unit is no
//   depth the sheet can take, unless the view is so oblique that the normal's image runs
//   along the rows, and then the rival fits as well and the margin refuses the reading.
struct Bow {
  cv::Matx33d h;
  bool sheet = false;
  cv::Vec3d normal;                       // sheet: the homogeneous image of a unit step along the sheet's normal
  std::array<double, 12> coefficients{};  // free: b's x terms, then its y terms; sheet: the first 9
  double misfit = 0;                      // squared pixels, over the blobs fitted
};

// Parameters fitted in all, with the homography's.
int bow_parameters(bool sheet) { return sheet ? 11 : 14; }
// The bow's own coefficients: b's 12 terms, or a sheet's 6 affine and 3 depth terms.
constexpr int bow_coefficients(bool sheet) { return sheet ? 9 : 12; }

// A bow of shape `sheet` under h, not yet fitted. The sheet's normal needs the camera: h
// maps units to ideal pixels, so K^-1 h holds the sheet's axes (scaled alike).
Bow unfitted_bow(const Family& f, const cv::Matx33d& h, const Camera& camera) {
  Bow bow;
  bow.h = h;
  bow.sheet = f.n() < 4;
  if (bow.sheet) {
    const cv::Matx33d k = camera.matrix(), axes = k.inv() * h;
    const cv::Vec3d x(axes(0, 0), axes(1, 0), axes(2, 0)), y(axes(0, 1), axes(1, 1), axes(2, 1));
    const cv::Vec3d normal = x.cross(y);
    const double length = cv::norm(normal);
    // Scaled so that z is in units, as u is.
    bow.normal = length > 0 ? k * (normal * (cv::norm(x) / length)) : cv::Vec3d(0, 0, 0);
  }
  return bow;
}

// The pixel shift at unit point u that each of the bow's coefficients makes, per unit
// (the first 12 of a free bow, the first 9 of a sheet).
using BowColumns = std::array<cv::Vec2d, 12>;
BowColumns bow_columns(const Family& f, const Bow& bow, cv::Point2d u) {
  const double x = u.x / f.side() - 0.5, y = u.y / f.side() - 0.5;
  const std::array<double, 6> t = {1, x, y, x * x, x * y, y * y};
  const cv::Matx22d j = units_to_pixels(bow.h, u);
  const cv::Vec2d along_x(j(0, 0), j(1, 0)), along_y(j(0, 1), j(1, 1));
  const int terms = bow.sheet ? 3 : 6;
  BowColumns columns;
  for (int k = 0; k < terms; ++k) columns[k] = along_x * t[k], columns[terms + k] = along_y * t[k];
  if (bow.sheet) {
    const cv::Vec3d q = bow.h * cv::Vec3d(u.x, u.y, 1.0);
    const cv::Vec2d deeper((bow.normal[0] - q[0] / q[2] * bow.normal[2]) / q[2],
                           (bow.normal[1] - q[1] / q[2] * bow.normal[2]) / q[2]);
    for (int k = 3; k < 6; ++k) columns[3 + k] = deeper * (t[k] * f.side());
  }
  return columns;
}

// The bow under h that puts the squares at `units` (grid order) nearest their blobs.
Bow fit_bow(const Candidate& c, Bow bow, const std::vector<int>& blob_of_cell, const std::vector<cv::Point2d>& units) {
  const int cells = c.family.cell_count(), terms = bow_coefficients(bow.sheet);
  // (Eigen's QR: through cv::solve, LAPACK's setup doubled the cost of these small solves.)
  Eigen::MatrixXd columns(2 * cells, terms);
  Eigen::VectorXd offsets(2 * cells);
  for (int g = 0; g < cells; ++g) {
    const BowColumns shifts = bow_columns(c.family, bow, units[g]);
    const cv::Point2d off = c.blobs[blob_of_cell[g]].point - apply(bow.h, units[g]);
    for (int k = 0; k < terms; ++k) columns(2 * g, k) = shifts[k][0], columns(2 * g + 1, k) = shifts[k][1];
    offsets(2 * g) = off.x, offsets(2 * g + 1) = off.y;
  }
  const Eigen::VectorXd fitted = columns.colPivHouseholderQr().solve(offsets);
  for (int k = 0; k < terms; ++k) bow.coefficients[k] = fitted(k);
  bow.misfit = (columns * fitted - offsets).squaredNorm();
  return bow;
}

cv::Point2d bowed(const Family& f, const Bow& bow, cv::Point2d u) {
  const BowColumns shifts = bow_columns(f, bow, u);
  cv::Point2d p = apply(bow.h, u);
  for (int k = 0; k < bow_coefficients(bow.sheet); ++k)
    p += cv::Point2d(shifts[k][0], shifts[k][1]) * bow.coefficients[k];
  return p;
}

std::vector<cv::Point2d> units_of(const Family& f, const CellCentres& design, TagId id) {
  std::vector<cv::Point2d> units(f.cell_count());
  for (int g = 0; g < f.cell_count(); ++g) units[g] = design[g][f.is_baseline(g) ? 0 : id.digit(f.data_index(g))];
  return units;
}

// How surely the bowed grid tells reading `d` from its rivals: the least, over the readings
// that move a band of rows or columns one unit (and with `digits`, over those that move one
// square), of half the root of how much worse the rival fits, refitted, over the scatter
// about the bowed grid (at least 0.02 px): a digit's margin, measured with the bow refitted
// for each rival so that it cannot take up the square's own error. A band moves only when
// all its squares can move the same way; rows holding a baseline cannot.
double bowed_noise_margin(const Candidate& c, const CellCentres& design, const Decoding& d, const Camera& camera,
                          bool digits) {
  const Family& f = c.family;
  const Bow shape = unfitted_bow(f, d.homography, camera);
  const int n = f.n(), freedom = 2 * f.cell_count() - bow_parameters(shape.sheet);
  if (freedom <= 0) return 0;
  const std::vector<cv::Point2d> units = units_of(f, design, d.id);
  const double own = fit_bow(c, shape, d.blob_of_cell, units).misfit;
  const double spread = std::max(std::sqrt(own / freedom), 0.02);
  double least = std::numeric_limits<double>::infinity();
  const auto consider = [&](const std::vector<cv::Point2d>& rival) {
    const double worse = fit_bow(c, shape, d.blob_of_cell, rival).misfit - own;
    least = std::min(least, std::sqrt(std::max(worse, 0.0)) / (2 * spread));
  };
  // Bands of rows (along y, bit 0) and of columns (along x, bit 1): lines [first, last].
  for (const bool rows : {true, false}) {
    const int bit = rows ? 1 : 2;
    auto cell = [&](int line, int along) { return rows ? line * n + along : along * n + line; };
    auto movable = [&](int line) {  // every square of the line data, and all moved one way
      int set = 0;
      for (int a = 0; a < n; ++a) {
        const int g = cell(line, a);
        if (f.is_baseline(g)) return 0;
        set |= (d.id.digit(f.data_index(g)) & bit) ? 2 : 1;
      }
      return set == 3 ? 0 : set;  // 1: all can move +1 unit; 2: all can move -1 unit
    };
    for (int first = 0; first < n; ++first) {
      const int way = movable(first);
      if (way == 0) continue;
      std::vector<cv::Point2d> rival = units;
      for (int last = first; last < n && movable(last) == way; ++last) {
        for (int a = 0; a < n; ++a) (rows ? rival[cell(last, a)].y : rival[cell(last, a)].x) += way == 1 ? 1 : -1;
        consider(rival);
      }
    }
  }
  if (digits)
    for (int g = 0; g < f.cell_count(); ++g) {
      if (f.is_baseline(g)) continue;
      const int digit = d.id.digit(f.data_index(g));
      for (int v = 0; v < 4; ++v) {
        if (v == digit) continue;
        std::vector<cv::Point2d> rival = units;
        rival[g] = design[g][v];
        consider(rival);
      }
    }
  return least;
}

// Reading `d` again on a bowed grid: from its id, each data square takes the position
// nearest its blob under the bow fitted to the id, until the id holds. Fills the id,
// worst_cell (units) and returns the bow's misfit; none when the id never settles: it
// comes back to an id it left (a cycle), or is still moving after kMaxBowedRounds.
// A strong bend takes several rounds: the flat reading's wrong squares pull the first bow
// towards themselves, and each round frees more of them; the round after the printed id
// is reached confirms it. The bound is on cost only: in the field experiment's bent clips
// every reading that settles does so within four rounds (tuning set) or five (validation).
constexpr int kMaxBowedRounds = 8;
std::optional<double> read_bowed(const Candidate& c, const CellCentres& design, const Camera& camera, Decoding& d) {
  const Family& f = c.family;
  const Bow shape = unfitted_bow(f, d.homography, camera);
  std::vector<TagId> left;
  for (int round = 0; round < kMaxBowedRounds; ++round) {
    const Bow bow = fit_bow(c, shape, d.blob_of_cell, units_of(f, design, d.id));
    TagId id;
    double worst = 0;
    for (int g = 0; g < f.cell_count(); ++g) {
      if (f.is_baseline(g)) continue;
      const cv::Point2d blob = c.blobs[d.blob_of_cell[g]].point;
      double nearest = std::numeric_limits<double>::max();
      int digit = 0;
      cv::Point2d off;
      for (int v = 0; v < 4; ++v) {
        const cv::Point2d e = blob - bowed(f, bow, design[g][v]);
        if (e.dot(e) < nearest) nearest = e.dot(e), digit = v, off = e;
      }
      id = id.with_digit(f.data_index(g), digit);
      worst = std::max(worst, offset_in_units(d.homography, design[g][digit], off));
    }
    if (id == d.id) {
      d.worst_cell = worst;
      return bow.misfit;
    }
    if (std::find(left.begin(), left.end(), id) != left.end()) return std::nullopt;
    left.push_back(d.id);
    d.id = id;
  }
  return std::nullopt;
}

// A 3x3 read as a bent sheet. The sheet's 3 depth terms fit more than one id near a
// reading (the nearest positions under the sheet fitted to a hypothesis' id can settle on
// another id that fits, while the printed one fits better), so every id is weighed: with
// the sheet's shifts taken at each cell's centre (they change little over the unit
// between its positions), an id's misfit is the norm of a sum of one term per cell, in
// the 9 coordinates off the span of the shifts, and all 4^7 sums are formed. `fits`
// keeps the least misfit and the least of any other id, over every call.
struct SheetFits {
  TagId best, second;
  double best_misfit = std::numeric_limits<double>::infinity();
  double second_misfit = std::numeric_limits<double>::infinity();
  const Decoding* reading = nullptr;  // the best id's hypothesis: its homography and blobs

  void offer(TagId id, double misfit, const Decoding* from) {
    if (misfit < best_misfit) {
      if (id != best) second = best, second_misfit = best_misfit;
      best = id, best_misfit = misfit, reading = from;
    } else if (id != best && misfit < second_misfit) {
      second = id, second_misfit = misfit;
    }
  }
};

void weigh_sheet_ids(const Candidate& c, const CellCentres& design, const Camera& camera, const Decoding& from,
                     SheetFits& fits) {
  const Family& f = c.family;
  constexpr int cells = 9, rows = 2 * cells, coefficients = bow_coefficients(true), left = rows - coefficients,
                digits = cells - 2;
  using Offsets = Eigen::Matrix<double, left, 1>;
  const Bow sheet = unfitted_bow(f, from.homography, camera);
  using Column = Eigen::Matrix<double, rows, 1>;
  Eigen::Matrix<double, rows, coefficients> shifts;
  for (int g = 0; g < cells; ++g) {
    const cv::Point2d centre = f.is_baseline(g) ? design[g][0] : (design[g][0] + design[g][3]) * 0.5;
    const BowColumns columns = bow_columns(f, sheet, centre);
    for (int k = 0; k < coefficients; ++k) shifts(2 * g, k) = columns[k][0], shifts(2 * g + 1, k) = columns[k][1];
  }
  // An orthonormal basis of the shifts' span, then of what lies off it (Gram-Schmidt,
  // each vector cleared twice against those before it): the last `left` vectors are the
  // coordinates the misfits are measured in. (Several times cheaper than a full SVD;
  // Eigen's Householder QR trips GCC 12's -Wmaybe-uninitialized.)
  Eigen::Matrix<double, rows, rows> basis;
  int spanned = 0;
  const auto extend = [&](Column v, double least) {
    for (int pass = 0; pass < 2; ++pass)
      for (int j = 0; j < spanned; ++j) v -= basis.col(j).dot(v) * basis.col(j);
    const double norm = v.norm();
    if (spanned < rows && norm > least) basis.col(spanned++) = v / norm;
  };
  for (int k = 0; k < coefficients; ++k) extend(shifts.col(k), 1e-9 * shifts.col(k).norm());
  for (int r = 0; r < rows && spanned < rows; ++r) extend(Column::Unit(r), 1e-6);
  if (spanned != rows) return;
  const Eigen::Matrix<double, left, rows> off = basis.rightCols<left>().transpose();
  // term[i][v]: data cell i's offset at digit v, in those coordinates; the baselines' in `fixed`.
  std::array<std::array<Offsets, 4>, digits> term;
  std::array<int, digits> cell{};
  Offsets fixed = Offsets::Zero();
  int i = 0;
  for (int g = 0; g < cells; ++g) {
    const cv::Point2d blob = c.blobs[from.blob_of_cell[g]].point;
    const auto offset = [&](int v) {
      const cv::Point2d e = blob - apply(from.homography, design[g][v]);
      return Offsets(off.col(2 * g) * e.x + off.col(2 * g + 1) * e.y);
    };
    if (f.is_baseline(g)) {
      fixed += offset(0);
      continue;
    }
    cell[i] = g;
    for (int v = 0; v < 4; ++v) term[i][v] = offset(v);
    ++i;
  }
  // Every digit pattern, depth first, the nearer digits first; a branch is left when no
  // pattern in it can fit better than the second id kept (a pattern's sum lies within the
  // remaining terms' spread of their centres' sum), which leaves `fits` as weighing every
  // pattern would.
  std::array<Offsets, digits + 1> centre_sum;   // [k]: the centres of terms k and after
  std::array<double, digits + 1> spread_sum{};  // [k]: their largest distances from their centres
  centre_sum[digits] = Offsets::Zero();
  for (int k = digits - 1; k >= 0; --k) {
    const Offsets centre = (term[k][0] + term[k][1] + term[k][2] + term[k][3]) / 4;
    double spread = 0;
    for (const Offsets& t : term[k]) spread = std::max(spread, (t - centre).norm());
    centre_sum[k] = centre_sum[k + 1] + centre;
    spread_sum[k] = spread_sum[k + 1] + spread;
  }
  std::array<int, digits> digit{};
  const auto visit = [&](const auto& self, int k, const Offsets& sum) -> void {
    std::array<std::pair<double, int>, 4> order;
    for (int v = 0; v < 4; ++v) order[std::size_t(v)] = {(sum + term[k][v] + centre_sum[k + 1]).squaredNorm(), v};
    std::sort(order.begin(), order.end());
    for (const auto& [distance, v] : order) {
      digit[std::size_t(k)] = v;
      if (k + 1 == digits) {  // the last digit: `distance` is the pattern's misfit
        if (distance >= fits.second_misfit) break;
        TagId id;
        for (int j = 0; j < digits; ++j) id = id.with_digit(f.data_index(cell[j]), digit[j]);
        fits.offer(id, distance, &from);
        continue;
      }
      // (1 - 1e-9): the bound kept below the misfits it bounds whatever their rounding.
      const double reach = std::max(0.0, std::sqrt(distance) - spread_sum[k + 1]);
      if (reach * reach * (1 - 1e-9) >= fits.second_misfit) break;
      self(self, k + 1, Offsets(sum + term[k][v]));
    }
  };
  visit(visit, 0, fixed);
}

// The homography through all n^2 blobs at their decoded positions.
std::optional<cv::Matx33d> refit(const Candidate& c, const CellCentres& design, const Decoding& d) {
  std::vector<cv::Point2d> points;
  for (const int blob : d.blob_of_cell) points.push_back(c.blobs[blob].point);
  return fit_homography(units_of(c.family, design, d.id), points);
}

}  // namespace

std::optional<Decoding> decode(const Candidate& c, const KeyPoints& k, const ImageView& image, const Camera& camera,
                               const DetectorParams& params, DetectionStats& stats,
                               std::vector<std::vector<cv::Point2d>>* hypotheses) {
  const Family& f = c.family;
  const int side = f.side();
  const cv::Point2d middle(side / 2.0, side / 2.0);
  const std::array<int, 4> kc = f.keypoint_cells();
  const CellCentres& design = design_centres(f);
  // K0, K1, K3, K2: around the marker, as the unit square's corners go.
  const std::array<cv::Point2d, 4> observed = {c.blobs[k.blob[0]].point, c.blobs[k.blob[1]].point,
                                               c.blobs[k.blob[3]].point, c.blobs[k.blob[2]].point};
  const double norm = std::sqrt(std::max(1.0, c.white_area));

  // First what the blobs alone tell of each hypothesis: its homography, id, residual, worst
  // cell, resolution and the squares' ink. The reading that wins is one of these, so when
  // none of them passes the checks that need no grey level, no edge score or photometric
  // test can make the side a marker: a grid of equal dots (the ink of every square alike,
  // where the baseline's carries 16/9 of a data square's, or dots that fit no id) or a
  // wrong side of a true marker stops here, before the grey-level work that costs most.
  struct Reading {
    Decoding d;
    double residual = 0;
    bool resolved = false, placed = false, passes = false;  // resolution; and cell residual; and ink
  };
  std::vector<Reading> readings;
  CellCentres projected;
  // Hypotheses that read the same id from the same blobs refit the same homography: the
  // refit and what follows from it are taken from the first of them.
  struct Refit {
    TagId id;
    std::vector<int> cells;
    std::size_t reading;  // the first reading with them, when its refit succeeded
  };
  std::vector<Refit> refits;
  int resolved = 0, placed = 0, passing = 0;
  const BlobsByX by_x(c);
  for (int hypothesis = 0; hypothesis < 16; ++hypothesis) {
    auto start = std::chrono::steady_clock::now();
    const int d2 = hypothesis / 4, d3 = hypothesis % 4;
    const auto hm =
        four_point_homography({design[kc[0]][0], design[kc[1]][0], design[kc[3]][d3], design[kc[2]][d2]}, observed);
    stats.hypotheses_ms += elapsed_ms(start);
    if (!hm) continue;
    start = std::chrono::steady_clock::now();

    Reading r;
    Decoding& d = r.d;
    d.homography = *hm;
    if (!maps_marker(f, d.homography)) {
      stats.decode_ms += elapsed_ms(start);
      continue;
    }
    project_centres(design, d.homography, projected);
    if (!assign_cells(c, by_x, k, projected, d)) {
      stats.decode_ms += elapsed_ms(start);
      continue;
    }
    r.residual = read_digits(c, design, projected, d, f.n() == 2);
    // The four key points fix this homography; all n^2 blobs judge it. The marker's id
    // explains every centroid with one homography, a wrong hypothesis cannot.
    bool copied = false;
    if (f.n() > 2) {
      const auto same = std::find_if(refits.begin(), refits.end(),
                                     [&](const Refit& e) { return e.id == d.id && e.cells == d.blob_of_cell; });
      if (same != refits.end() && same->reading != std::size_t(-1)) {
        r = readings[same->reading];
        copied = true;
      } else {
        std::optional<cv::Matx33d> h;
        if (same == refits.end()) h = refit(c, design, d);  // else it failed before
        const bool fitted = h && maps_marker(f, *h);
        if (same == refits.end()) refits.push_back({d.id, d.blob_of_cell, fitted ? readings.size() : std::size_t(-1)});
        if (fitted) {
          d.homography = *h;
          project_centres(design, d.homography, projected);
        }
        r.residual = read_digits(c, design, projected, d, true);
      }
    }
    if (!copied) {
      d.ink_spread = square_ink_spread(c, d);
      r.resolved = smallest_scale(d.homography, middle) >= params.min_pixels_per_unit;
      r.placed = r.resolved && d.worst_cell <= params.max_cell_residual;
      r.passes = r.placed && d.ink_spread <= params.max_ink_spread;
    }
    resolved += r.resolved, placed += r.placed, passing += r.passes;
    stats.decode_ms += elapsed_ms(start);
    readings.push_back(r);
  }
  if (readings.empty()) return std::nullopt;

  const auto outline_of = [&](const Decoding& d) {
    std::vector<cv::Point2d> outline;
    for (const cv::Point2d& u : square(2, side - 2)) outline.push_back(apply(d.homography, u));
    distort(camera, outline);
    return outline;
  };
  if (hypotheses)
    for (const Reading& r : readings) hypotheses->push_back(outline_of(r.d));
  // `clean`: a 2x2 reading known to be free of misordered pairs.
  const auto score = [&](Reading& r, bool clean = false) {
    const auto start = std::chrono::steady_clock::now();
    r.d.edge_score = edge_gradient(image, camera, r.d.homography, 2, side - 2);
    stats.hypotheses_ms += elapsed_ms(start);
    // 2x2: four blobs fix the homography exactly and leave no residual, so the grey
    // levels where the marker must be black or white decide.
    r.d.error = f.n() != 2 ? r.residual / norm / r.d.edge_score
                : clean    ? 0.0
                           : misordered_pairs(f, r.d.id, r.d.homography, image, camera);
  };
  const auto rejected = [&](Verdict verdict) {
    // The reading reported (for the trace) is the one with the least residual, scored in
    // full only when the trace asks for it.
    const auto least = std::min_element(readings.begin(), readings.end(),
                                        [](const Reading& a, const Reading& b) { return a.residual < b.residual; });
    Decoding best = least->d;
    best.verdict = verdict;
    if (hypotheses) {
      Reading scored = *least;
      score(scored);
      best.edge_score = scored.d.edge_score, best.error = scored.d.error;
    }
    return best;
  };
  const auto better = [](const Decoding& a, const Decoding& b) {
    return a.error != b.error ? a.error < b.error : a.edge_score > b.edge_score;
  };

  // What every reading on a bowed grid must pass beyond its rivals: the homography
  // refitted through its squares, the resolution, even ink, its margin (`margin`, else the
  // bowed grid's margin against every square and band moved), tau3 on its bowed misfit.
  const auto bowed_checks = [&](Decoding d, double misfit, std::optional<double> margin) -> std::optional<Decoding> {
    const auto h = refit(c, design, d);
    if (!h || !maps_marker(f, *h)) return std::nullopt;
    d.homography = *h;
    if (smallest_scale(d.homography, middle) < params.min_pixels_per_unit) return std::nullopt;
    d.ink_spread = square_ink_spread(c, d);
    if (!(d.ink_spread <= params.max_ink_spread)) return std::nullopt;
    d.noise_margin = margin ? *margin : bowed_noise_margin(c, design, d, camera, true);
    if (d.noise_margin < params.min_noise_margin) return std::nullopt;
    d.edge_score = edge_gradient(image, camera, d.homography, 2, side - 2);
    if (!(d.edge_score > 0)) return std::nullopt;
    d.error = misfit / norm / d.edge_score;
    if (d.error > params.decode_threshold(f)) return std::nullopt;
    d.verdict = Verdict::accepted;
    return d;
  };
  // A reading's misfit on the flat grid, and whether a sheet's depth terms take up more of
  // it than noise would (read_on_sheet, below).
  const auto flat_misfit_of = [&](const Decoding& d) {
    const std::vector<cv::Point2d> units = units_of(f, design, d.id);
    double misfit = 0;
    for (int g = 0; g < f.cell_count(); ++g) {
      const cv::Point2d e = c.blobs[d.blob_of_cell[g]].point - apply(d.homography, units[g]);
      misfit += e.dot(e);
    }
    return misfit;
  };
  const int sheet_freedom = 2 * f.cell_count() - bow_parameters(true);
  const auto bend_shows = [&](double flat_misfit, double sheet_misfit) {
    constexpr double kF3And7At99 = 8.45;
    return (flat_misfit - sheet_misfit) / 3 > kF3And7At99 * std::max(sheet_misfit / sheet_freedom, 0.02 * 0.02);
  };
  // 3x3: the id the sheet fits best over every id and plausible hypothesis, with its margin
  // over the best other id there (half the root of how much worse it fits, over the
  // scatter about the sheet): no rival is left unweighed. Only where a bend shows: the
  // sheet's 3 depth terms take up more of the flat reading's misfit than Gaussian noise
  // would but once in a hundred times (an F test: F(3, 7) at 0.99 is 8.45, for 3 depth
  // terms and 18 - 11 degrees of freedom left; the scatter at least 0.02 px, as for the
  // noise margin). Elsewhere the flat grid's verdict stands. `bent` tells whether it did.
  const auto read_on_sheet = [&](const Decoding& flat, bool* bent = nullptr) -> std::optional<Decoding> {
    SheetFits fits;
    std::vector<const Decoding*> weighed;
    for (const Reading& r : readings) {
      if (!r.resolved || !(r.d.ink_spread <= params.max_ink_spread)) continue;
      const bool seen = std::any_of(weighed.begin(), weighed.end(), [&](const Decoding* d) {
        return d->blob_of_cell == r.d.blob_of_cell && d->homography == r.d.homography;
      });
      if (seen) continue;
      weighed.push_back(&r.d);
      weigh_sheet_ids(c, design, camera, r.d, fits);
    }
    if (!std::isfinite(fits.best_misfit) || !bend_shows(flat_misfit_of(flat), fits.best_misfit)) return std::nullopt;
    if (bent) *bent = true;
    // No other id within a factor min_decode_margin, as for a flat reading.
    if (fits.second_misfit < params.min_decode_margin * fits.best_misfit) return std::nullopt;
    Decoding d = *fits.reading;
    d.id = fits.best;
    const Bow sheet = fit_bow(c, unfitted_bow(f, d.homography, camera), d.blob_of_cell, units_of(f, design, d.id));
    d.worst_cell = 0;
    for (int g = 0; g < f.cell_count(); ++g) {
      const int digit = f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g));
      const cv::Point2d off = c.blobs[d.blob_of_cell[g]].point - bowed(f, sheet, design[g][digit]);
      d.worst_cell = std::max(d.worst_cell, offset_in_units(d.homography, design[g][digit], off));
    }
    if (d.worst_cell > params.max_cell_residual) return std::nullopt;
    const double spread = std::max(std::sqrt(fits.best_misfit / sheet_freedom), 0.02);
    const double margin = std::sqrt(std::max(fits.second_misfit - fits.best_misfit, 0.0)) / (2 * spread);
    return bowed_checks(d, sheet.misfit, margin);
  };
  // A reading refused flat for where its squares lie (cell residual, tau3, a rival id or
  // digit too close) is read again on a bowed grid; a 3x3's as a sheet (read_on_sheet).
  // From 4x4 each hypothesis of a plausible turn (resolved, its ink even) re-reads its
  // squares under its own bow, and the least misfit wins. It is held to the same bounds,
  // with the bowed grid's scatter as the noise: its cells within max_cell_residual, every
  // other hypothesis' id and every reading that moves one square or a band of them at
  // least min_noise_margin worse (each rival's bow refitted), tau3 on its bowed misfit,
  // its ink even. A flat marker fits its bow with no curve, and is read so only when its
  // own scatter allows it.
  const auto read_on_bowed_grid = [&](const Decoding& flat) -> std::optional<Decoding> {
    const int freedom = 2 * f.cell_count() - bow_parameters(f.n() < 4);
    if (f.n() < 3 || freedom <= 0) return std::nullopt;
    struct Bowed {
      Decoding d;
      double misfit;
    };
    if (f.n() == 3) return read_on_sheet(flat);
    std::vector<Bowed> bowed_readings;
    for (const Reading& r : readings) {
      if (!r.resolved || !(r.d.ink_spread <= params.max_ink_spread)) continue;
      const bool seen = std::any_of(bowed_readings.begin(), bowed_readings.end(), [&](const Bowed& b) {
        return b.d.blob_of_cell == r.d.blob_of_cell && b.d.homography == r.d.homography;
      });
      if (seen) continue;
      Decoding d = r.d;
      if (const auto misfit = read_bowed(c, design, camera, d)) bowed_readings.push_back({d, *misfit});
    }
    if (bowed_readings.empty()) return std::nullopt;
    Bowed best = *std::min_element(bowed_readings.begin(), bowed_readings.end(),
                                   [](const Bowed& a, const Bowed& b) { return a.misfit < b.misfit; });
    if (best.d.worst_cell > params.max_cell_residual) return std::nullopt;
    const double spread = std::max(std::sqrt(best.misfit / freedom), 0.02);
    for (const Bowed& other : bowed_readings)
      if (other.d.id != best.d.id &&
          std::sqrt(std::max(other.misfit - best.misfit, 0.0)) / (2 * spread) < params.min_noise_margin)
        return std::nullopt;
    return bowed_checks(best.d, best.misfit, std::nullopt);
  };
  const auto refused = [&](Decoding flat) {
    if (flat.verdict != Verdict::residual && flat.verdict != Verdict::margin) return flat;
    const auto start = std::chrono::steady_clock::now();
    const std::optional<Decoding> d = read_on_bowed_grid(flat);
    stats.decode_ms += elapsed_ms(start);
    if (!d) return flat;
    ++stats.bowed;
    return *d;
  };

  // 2x2 with tau3 at 0 (the default): a reading is accepted only when no grey level that
  // must be white is as dark as one that must be black, and the brightest edge among such
  // readings wins. Only they need the edge gradient.
  std::vector<char> zero;
  int zeros = 0;
  if (f.n() == 2 && params.decode_threshold(f) == 0 && passing > 0) {
    const auto start = std::chrono::steady_clock::now();
    // Those that pass the checks above first: when none of them is clean, the best cannot
    // be either.
    zero.assign(readings.size(), 0);
    passing = 0;
    for (int round = 0; round < 2 && (round == 0 || passing > 0); ++round)
      for (std::size_t i = 0; i < readings.size(); ++i)
        if (readings[i].passes == (round == 0)) {
          zero[i] = no_misordered_pair(f, readings[i].d.id, readings[i].d.homography, image, camera);
          zeros += zero[i];
          passing += zero[i] && readings[i].passes;
        }
    stats.hypotheses_ms += elapsed_ms(start);
  }
  // Rejected whichever reading the grey levels would make best: the verdict names the
  // first check that no reading passed.
  if (passing == 0)
    return refused(rejected(resolved == 0                 ? Verdict::resolution
                            : placed == 0                 ? Verdict::residual
                            : !zero.empty() && zeros == 0 ? Verdict::residual  // 2x2: tau3
                                                          : Verdict::ink));

  // Then the grey levels: the gradient along the projected inner border edge, and the
  // decoding error of each hypothesis (2x2: of those free of misordered pairs, error 0).
  // Scored least residual first, so that the best error is soon known: a reading whose
  // error cannot come within the decoding margin of it even at the steepest gradient a
  // Sobel sum allows (4 x 255 each way) can be neither the reading nor its rival, and is
  // not scored. (2x2 errors are no residuals: each is scored.)
  constexpr double kMaxEdgeGradient = 1443;  // above 4 x 255 x sqrt(2)
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < readings.size(); ++i)
    if (zero.empty() || zero[i]) order.push_back(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return readings[a].residual < readings[b].residual; });
  std::vector<char> scored(readings.size(), 0);
  double least_error = std::numeric_limits<double>::infinity();
  for (const std::size_t i : order) {
    Reading& r = readings[i];
    if (f.n() != 2 && r.residual / norm / kMaxEdgeGradient > params.min_decode_margin * least_error) continue;
    score(r, !zero.empty());
    scored[i] = 1;
    if (r.d.edge_score > 0) least_error = std::min(least_error, r.d.error);
  }
  std::vector<Decoding> tried;  // in the hypotheses' order, as ties are broken by it
  for (std::size_t i = 0; i < readings.size(); ++i)
    if (scored[i] && readings[i].d.edge_score > 0) tried.push_back(readings[i].d);
  if (tried.empty()) return zero.empty() ? std::nullopt : std::optional<Decoding>(rejected(Verdict::residual));
  Decoding best = *std::min_element(tried.begin(), tried.end(), better);

  // Below about half a pixel per unit the 1 u shifts are under half a pixel and blur into
  // one another: a reading there can pass every check below and still be wrong (a 3x3
  // at 0.42 px per unit did, once in the range sweep), so it is not made.
  if (smallest_scale(best.homography, middle) < params.min_pixels_per_unit) {
    best.verdict = Verdict::resolution;
    return best;
  }
  // tau3, and every digit clear of the midpoint between two positions.
  if (best.error > params.decode_threshold(f) || best.worst_cell > params.max_cell_residual) {
    best.verdict = Verdict::residual;
    return refused(best);
  }
  // Another id that fits almost as well makes the reading a guess (never, for a 2x2
  // reading free of misordered pairs: no error is below twice zero).
  for (const Decoding& d : tried)
    if (d.id != best.id && d.error < params.min_decode_margin * best.error) {
      best.verdict = Verdict::margin;
      return refused(best);
    }
  // So does another id whose blobs pass every check and fit within the same factor by
  // their residual alone: the id is carried by the blobs, and the edge gradient that
  // divides the errors can decide between two such readings only where the border is
  // straight. A bent 3x3 was read as another id so: the printed id's hypothesis left 1.8
  // times that reading's residual, but its edge under its homography was the weaker. At
  // min_decode_margin 1 neither check refuses anything.
  if (f.n() > 2 && params.min_decode_margin > 1) {
    double own = std::numeric_limits<double>::infinity();
    for (const Reading& r : readings)
      if (r.d.id == best.id) own = std::min(own, r.residual);
    for (const Reading& r : readings)
      if (r.passes && r.d.id != best.id && r.residual < params.min_decode_margin * own) {
        best.verdict = Verdict::margin;
        return refused(best);
      }
  }
  // And the least certain digit clear of the noise (every digit pattern is an id).
  if (f.n() > 2) {
    best.noise_margin = digit_noise_margin(c, design, best);
    if (f.n() >= 4) best.noise_margin = std::min(best.noise_margin, bowed_noise_margin(c, design, best, camera, false));
    if (best.noise_margin < params.min_noise_margin) {
      best.verdict = Verdict::margin;
      return refused(best);
    }
  }
  // A 3x3 reading that another hypothesis contests (another id whose blobs are as well
  // placed and inked) may be a bent sheet's, read flat as another id: the bend moves
  // squares towards other positions, and the rival ids' errors can differ by less than
  // their edge scores do (a 3x3 on a 0.16 m cylinder, tilted, was read so, 2.06 scatters
  // clear; the sheet fitted the printed id 11 times better). Where a bend shows, the
  // sheet decides (a reading of the flat id stays the flat one, with its homography, for
  // the pose); elsewhere the flat reading stands. Most contested readings are flat: the
  // sheets of the contesting readings' own ids tell them, before every id is weighed.
  const bool contested =
      std::any_of(readings.begin(), readings.end(), [&](const Reading& r) { return r.passes && r.d.id != best.id; });
  if (f.n() == 3 && contested) {
    const auto start = std::chrono::steady_clock::now();
    const double flat_misfit = flat_misfit_of(best);
    const bool maybe_bent = std::any_of(readings.begin(), readings.end(), [&](const Reading& r) {
      if (!r.passes) return false;
      const Bow sheet = unfitted_bow(f, r.d.homography, camera);
      return bend_shows(flat_misfit, fit_bow(c, sheet, r.d.blob_of_cell, units_of(f, design, r.d.id)).misfit);
    });
    bool bent = false;
    const std::optional<Decoding> sheet = maybe_bent ? read_on_sheet(best, &bent) : std::nullopt;
    stats.decode_ms += elapsed_ms(start);
    if (bent) {
      if (!sheet) {
        best.verdict = Verdict::margin;
        return best;
      }
      if (sheet->id != best.id) {
        ++stats.bowed;
        return sheet;
      }
    }
  }
  best.verdict = Verdict::accepted;
  return best;
}

std::optional<Decoding> decode_expected(const Candidate& c, TagId id, const ImageView& image, const Camera& camera,
                                        const DetectorParams& params, DetectionStats& stats) {
  const Family& f = c.family;
  if (f.n() < 3 || int(c.blobs.size()) != f.cell_count()) return std::nullopt;
  const auto start = std::chrono::steady_clock::now();
  const CellCentres& design = design_centres(f);
  const int side = f.side();
  Decoding d;
  d.id = id;
  d.blob_of_cell.resize(std::size_t(f.cell_count()));
  std::iota(d.blob_of_cell.begin(), d.blob_of_cell.end(), 0);
  const std::optional<cv::Matx33d> h = refit(c, design, d);
  const auto done = [&](std::optional<Decoding> out) {
    stats.decode_ms += elapsed_ms(start);
    return out;
  };
  if (!h || !maps_marker(f, *h)) return done(std::nullopt);
  d.homography = *h;
  CellCentres projected;
  project_centres(design, d.homography, projected);
  const double residual = read_digits(c, design, projected, d, true);
  if (d.id != id || smallest_scale(d.homography, {side / 2.0, side / 2.0}) < params.min_pixels_per_unit ||
      d.worst_cell > params.max_cell_residual)
    return done(std::nullopt);
  d.ink_spread = square_ink_spread(c, d);
  if (!(d.ink_spread <= params.max_ink_spread)) return done(std::nullopt);
  d.edge_score = edge_gradient(image, camera, d.homography, 2, side - 2);
  if (!(d.edge_score > 0)) return done(std::nullopt);
  d.error = residual / std::sqrt(std::max(1.0, c.white_area)) / d.edge_score;
  if (d.error > params.decode_threshold(f)) return done(std::nullopt);
  d.noise_margin = digit_noise_margin(c, design, d);
  if (f.n() >= 4) d.noise_margin = std::min(d.noise_margin, bowed_noise_margin(c, design, d, camera, false));
  if (d.noise_margin < params.min_noise_margin) return done(std::nullopt);
  d.verdict = Verdict::accepted;
  return done(d);
}

}  // namespace lftag::detail
