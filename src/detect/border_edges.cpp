// SPDX-License-Identifier: LGPL-2.1-or-later
// The border's stroke for the final pose: once the marker is decoded, points of the
// centre line of its black border are found along its four sides.
//
// The n^2 centroids span 12 of a 3x3's 24 units; the border's centre line spans 22.
// Under noise and compression, where a centroid's error is set by the few pixels of its
// square, the border's longer baseline measures the marker's scale, and so its
// distance, better. The border is found as the squares are: the centroid of its ink
// across the stroke, between the white margin and the white interior. An edge's place
// moves with blur and the tone curve (the darker side of a blurred edge spreads under a
// gamma, as does ink bleeding on paper); the centre of a stroke lit alike on both sides
// does not, as a square's centroid does not.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Dense>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag::detail {
namespace {

// Units of paper either side of the stroke: half the narrowest gap to a square, so that
// blur brings in as little of a square as of the background past a two-unit margin.
constexpr double kReach = 1.0;
constexpr double kStep = 0.5;    // pixels between the profile's samples,
constexpr int kMaxSamples = 33;  // but no more than this many (an eighth of a unit apart)
// Paper either side of the stroke in the window whose centroid is its centre (see
// stroke_centre): half a unit, but at least a pixel and a half (the ramp of a sharp edge
// sampled bilinearly spans two pixels) up to three quarters of a unit. And the window's
// moves towards the centre: at most kMaxShifts, until a move is under kSettled units.
constexpr double kPaperInWindow = 0.5, kPaperInWindowPixels = 1.5, kMostPaperInWindow = 0.75;
constexpr int kMaxShifts = 8;
constexpr double kSettled = 3e-4;
// Units kept from the centre line's ends, where the crossing side's stroke lies across
// the profile.
constexpr double kCornerClearance = 3;
constexpr int kMaxPointsPerSide = 16;       // enough to fix a line; more only costs
constexpr double kMinPixelsPerUnit = 1.25;  // as the cell centroids (a unit must hold pixels)
// A point whose ink is under this fraction of the sides' median is not the border's
// (an occluder, a glare).
constexpr double kMinInk = 0.5;
// The two sides of the stroke differ in paper level by at most this fraction of the
// contrast: more is no white margin, or light that one level cannot stand for.
constexpr double kPaperMismatch = 0.25;
// The ink's variance across the whole profile (units^2; a sharp stroke's is 1/3, a blur
// of s units adds s^2, and the pixel's own size some more) above which the marker's
// stroke is not used: blurred by more than about 0.6 to 0.8 units, the squares two units
// inside reach the centre's window and move it inwards (on rendered 3x3 markers with a
// six-unit margin, 4 to 1.5 px a unit: 0.001 to 0.006 units at a blur of 0.6, 0.003 to
// 0.010 at 0.7). Chosen on the tuning sets of the field and video experiments among
// 0.5, 0.6 and 0.65 (with half a unit of paper in every window): the higher, the nearer
// the small markers' poses came (at 1080p through H.264 and under 2 px a unit in the
// video), with no condition worse.
constexpr double kMaxSpread = 0.65;
// Points further than this many times the side's RMS distance from its line are dropped.
constexpr double kOutlier = 3;
constexpr double kLeastScatter = 0.02;  // pixels: a sharp rendered stroke's scatter

// The least-squares line through `points`: a point on it and its unit direction.
struct Line {
  cv::Point2d origin, direction;
  cv::Point2d normal() const { return {-direction.y, direction.x}; }
  double distance(cv::Point2d p) const { return (p - origin).dot(normal()); }
};

Line fit_line(const std::vector<cv::Point2d>& points) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const cv::Point2d& p : points) mean += Eigen::Vector2d(p.x, p.y);
  mean /= double(points.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const cv::Point2d& p : points) {
    const Eigen::Vector2d d = Eigen::Vector2d(p.x, p.y) - mean;
    scatter += d * d.transpose();
  }
  // The direction of most scatter: the eigenvector of the larger eigenvalue (sorted last).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen;
  eigen.computeDirect(scatter);
  const Eigen::Vector2d direction = eigen.eigenvectors().col(1);
  return {{mean.x(), mean.y()}, {direction.x(), direction.y()}};
}

double rms(const std::vector<double>& v) {
  double ss = 0;
  for (const double x : v) ss += x * x;
  return std::sqrt(ss / double(v.size()));
}

// The grey level at a sub-pixel point at least a pixel inside the image, bilinear: what
// grey_at gives there, without its clamping (the profiles are most of this stage's time).
inline double grey_inside(const ImageView& image, cv::Point2d p) {
  const int x = int(p.x), y = int(p.y);
  const double fx = p.x - x, fy = p.y - y;
  const std::uint8_t* row = image.data + y * image.stride + x;
  const std::uint8_t* next = row + image.stride;
  return (1 - fy) * ((1 - fx) * row[0] + fx * row[1]) + fy * ((1 - fx) * next[0] + fx * next[1]);
}

struct Found {
  cv::Point2d unit;      // where on the edge, in units
  cv::Point2d observed;  // image pixels as observed
  double ink = 0;
  double spread = 0;  // the ink's variance across the stroke, units^2
  int side = 0;
};

// The centre line of the border's stroke along the normal through `outer` (the outer
// edge, image pixels as observed), `inward` a unit's step into the marker. The ink is
// weighed against the brighter end's paper: a level interpolated between the two ends
// takes the darker background, blurred in past a narrow margin, for paper, and moves the
// centre inwards (0.01 px, a tenth of a percent of the distance, on 50 px markers
// defocused by 1.2 px; BorderEdges.PointsLieOnTheStrokesCentreLine). The centre is the
// ink's centroid in a window of the stroke and some paper either side, centred on it: a
// blurred stroke's tails, cut alike on both sides, do not move it, and the squares two
// units inside reach the window only by a blur's far tail. (Over the whole profile the
// squares' ink moves it inwards: by 0.018 units at a blur of 0.6 units, against 0.0015
// in a window with half a unit of paper, in a profile model with the squares two units
// in and a six-unit margin.) A window too tight for the pixels cuts a sharp edge's ramp
// where the sampling puts it: on sharp markers of 2 px a unit, the 99th percentile of a
// marker's median point offset was 0.016 px with half a unit of paper, 0.011 to 0.013
// over the whole profile, 0.013 to 0.014 with a pixel and a half of paper. False when
// the two ends are not paper alike (no white margin, a shadow's edge along the border),
// no ink is found, or the centre leaves the profile's middle.
bool stroke_centre(const ImageView& image, cv::Point2d outer, cv::Point2d inward, cv::Point2d& centre, double& ink,
                   double& spread) {
  const double unit = cv::norm(inward);
  constexpr double kFrom = -kReach, kTo = 2 + kReach;  // units from the outer edge
  const int samples = std::clamp(int(std::ceil((kTo - kFrom) * unit / kStep)) + 1, 9, kMaxSamples);
  double grey[kMaxSamples];
  const double step = (kTo - kFrom) / (samples - 1);
  for (int i = 0; i < samples; ++i) grey[i] = grey_inside(image, outer + inward * (kFrom + i * step));
  // The paper at each end: the brightest of its half unit.
  const int end = std::max(1, int(0.5 / step));
  const double out_paper = *std::max_element(grey, grey + end + 1);
  const double in_paper = *std::max_element(grey + samples - 1 - end, grey + samples);
  const double darkest = *std::min_element(grey, grey + samples);
  const double contrast = std::min(out_paper, in_paper) - darkest;
  if (!(contrast > 0) || std::abs(out_paper - in_paper) > kPaperMismatch * contrast) return false;
  double dark[kMaxSamples], sum = 0, moment = 0;
  for (int i = 0; i < samples; ++i) {
    dark[i] = std::max(0.0, std::max(out_paper, in_paper) - grey[i]);
    sum += dark[i], moment += dark[i] * (kFrom + i * step);
  }
  if (!(sum > 0)) return false;
  // The blur, measured over the whole profile.
  const double mean = moment / sum;
  double second = 0;
  for (int i = 0; i < samples; ++i) second += dark[i] * (kFrom + i * step - mean) * (kFrom + i * step - mean);
  // The centre, from the whole profile's centroid: samples at the window's ends count in
  // part, so that the centroid moves smoothly with the window.
  const double paper = std::clamp(kPaperInWindowPixels / unit, kPaperInWindow, kMostPaperInWindow);
  const double half_window = 1 + paper;
  double middle = std::clamp(mean, 1 - (kReach - paper), 1 + (kReach - paper));
  for (int shift = 0; shift < kMaxShifts; ++shift) {
    double weight = 0, weighted = 0;
    for (int i = 0; i < samples; ++i) {
      const double at = kFrom + i * step, w = std::clamp((half_window - std::abs(at - middle)) / step + 0.5, 0.0, 1.0);
      weight += w * dark[i], weighted += w * dark[i] * at;
    }
    if (!(weight > 0)) return false;
    const double moved = weighted / weight - middle;
    middle += moved;
    if (std::abs(moved) < kSettled) break;
  }
  if (!(std::abs(middle - 1) <= kReach - paper)) return false;
  centre = outer + inward * middle;
  ink = sum * step;
  spread = second / sum;
  return true;
}

}  // namespace

BorderEdges border_edges(const ImageView& image, const Camera& camera, const Family& family,
                         const cv::Matx33d& homography, double tag_size) {
  BorderEdges out;
  const double s = family.side();
  const double lo = 1, hi = s - 1;  // the stroke's centre line
  if (!(smallest_scale(homography, {s / 2, s / 2}) >= kMinPixelsPerUnit)) return out;
  // The four sides: a start, the direction along it and the inward normal, in units.
  const cv::Point2d start[4] = {{lo, lo}, {hi, lo}, {hi, hi}, {lo, hi}};
  const cv::Point2d along[4] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
  const cv::Point2d inward[4] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};
  const double length = hi - lo - 2 * kCornerClearance;
  const int per_side = std::min(kMaxPointsPerSide, int(length) + 1);

  std::vector<cv::Point2d> units, ideal;
  for (int k = 0; k < 4; ++k)
    for (int i = 0; i < per_side; ++i) {
      const cv::Point2d u = start[k] + along[k] * (kCornerClearance + length * i / (per_side - 1));
      units.push_back(u);
      ideal.push_back(apply(homography, u - inward[k]));  // the outer edge
      ideal.push_back(apply(homography, u));
    }
  std::vector<cv::Point2d> seen = ideal;
  distort(camera, seen);

  std::vector<Found> found;
  for (std::size_t j = 0; j < units.size(); ++j) {
    const cv::Point2d a = seen[2 * j], b = seen[2 * j + 1];
    const cv::Point2d step = b - a;
    // The profile, with the pixel beyond it that bilinear sampling reads, inside the image.
    const double reach = cv::norm(step) * (2 + kReach) + 1;
    if (!(reach > 1) || a.x < reach || a.y < reach || a.x > image.width - 1 - reach || a.y > image.height - 1 - reach)
      continue;
    Found f;
    f.unit = units[j];
    f.side = int(j) / per_side;
    if (stroke_centre(image, a, step, f.observed, f.ink, f.spread)) found.push_back(f);
  }
  if (found.empty()) return out;
  std::vector<double> spreads;
  for (const Found& f : found) spreads.push_back(f.spread);
  std::nth_element(spreads.begin(), spreads.begin() + spreads.size() / 2, spreads.end());
  if (spreads[spreads.size() / 2] > kMaxSpread) return out;
  std::vector<double> inks;
  for (const Found& f : found) inks.push_back(f.ink);
  std::nth_element(inks.begin(), inks.begin() + inks.size() / 2, inks.end());
  const double min_ink = kMinInk * inks[inks.size() / 2];
  found.erase(std::remove_if(found.begin(), found.end(), [&](const Found& f) { return f.ink < min_ink; }), found.end());

  std::vector<cv::Point2d> observed;
  for (const Found& f : found) observed.push_back(f.observed);
  const std::vector<cv::Point2d> undistorted = camera.undistort(observed);

  // Each side's line, fitted to its points; their scatter about it is their noise. For
  // the pose, two points of the line a standard deviation either side of the points'
  // middle, each standing for half of them, hold what they say of where the side lies:
  // the squared distances of the points from a line near theirs sum, to first order,
  // to the two's (the points' scatter about their own line apart).
  double squares = 0;
  int freedom = 0;
  for (int k = 0; k < 4; ++k) {
    std::vector<int> members;
    for (std::size_t j = 0; j < found.size(); ++j)
      if (found[j].side == k) members.push_back(int(j));
    std::vector<cv::Point2d> points;
    std::vector<double> distance;
    const auto fit = [&] {
      points.clear(), distance.clear();
      for (int j : members) points.push_back(undistorted[j]);
      const Line line = fit_line(points);
      for (const cv::Point2d& p : points) distance.push_back(line.distance(p));
      return line;
    };
    if (members.size() < 3) continue;
    fit();
    const double limit = kOutlier * std::max(rms(distance), kLeastScatter);
    std::vector<int> kept;
    for (std::size_t m = 0; m < members.size(); ++m)
      if (std::abs(distance[m]) <= limit) kept.push_back(members[m]);
    members = kept;
    if (members.size() < 3) continue;
    const Line line = fit();
    squares += rms(distance) * rms(distance) * double(members.size()), freedom += int(members.size()) - 2;

    double mean = 0, spread = 0;  // of the points' places along the side, units
    for (int j : members) {
      const double a = (found[j].unit - start[k]).dot(along[k]);
      mean += a, spread += a * a;
      out.points.push_back({family.to_marker_frame(found[j].unit, tag_size), undistorted[j], line.normal()});
    }
    mean /= double(members.size());
    spread = std::sqrt(std::max(0.0, spread / double(members.size()) - mean * mean));
    for (const double a : {mean - spread, mean + spread}) {
      const cv::Point2d u = start[k] + along[k] * a;
      const cv::Point2d near = apply(homography, u);
      out.sides.push_back({family.to_marker_frame(u, tag_size),
                           line.origin + line.direction * (near - line.origin).dot(line.direction), line.normal(),
                           double(members.size()) / 2});
    }
  }
  if (freedom > 0) out.noise = std::sqrt(squares / freedom);
  if (!(out.noise > 0)) out.points.clear(), out.sides.clear();
  return out;
}

}  // namespace lftag::detail
