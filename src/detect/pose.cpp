// SPDX-License-Identifier: LGPL-2.1-or-later
// Final pose (paper IV-I): PnP on all n^2 centroids, IPPE then Levenberg-Marquardt, for
// both of IPPE's solutions; the one that fits best is the pose, the other is reported
// with it. A blob's centroid is the centroid of its projected square, which perspective moves off
// the projection of the square's centre; one correction with the first pose removes
// that bias before the refinement. When the two fit the centroids nearly alike, the
// squares' inks can tell them apart (DetectorParams::shape_choice_ratio). The chosen
// pose is then refined on the border's stroke as well (border_edges.cpp), where the
// centroids agree with it.
#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>

#include "../core/geometry.hpp"
#include "../core/rotation.hpp"
#include "stages.hpp"

namespace lftag::detail {

std::vector<cv::Point2d> project_pinhole(const std::vector<cv::Point3d>& object, const cv::Vec3d& rvec,
                                         const cv::Vec3d& tvec, const cv::Matx33d& k) {
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);  // as cv::projectPoints turns them, to the bit
  std::vector<cv::Point2d> out;
  out.reserve(object.size());
  for (const cv::Point3d& p : object) {
    const double x = r(0, 0) * p.x + r(0, 1) * p.y + r(0, 2) * p.z + tvec[0];
    const double y = r(1, 0) * p.x + r(1, 1) * p.y + r(1, 2) * p.z + tvec[1];
    const double z = r(2, 0) * p.x + r(2, 1) * p.y + r(2, 2) * p.z + tvec[2];
    const double iz = z ? 1. / z : 1;
    out.emplace_back(k(0, 0) * (x * iz) + k(0, 2), k(1, 1) * (y * iz) + k(1, 2));
  }
  return out;
}

namespace {

// A pose refined on the centroids, with the observations it was refined against (moved
// from the centroids of the projected squares to the projections of their centres) and
// its RMS reprojection error over them.
struct Solution {
  cv::Vec3d rvec, tvec;
  std::vector<cv::Point2d> observed;
  double rms = 0;
  double shape_misfit = 0;  // see shape_misfit()
};

double rms_error(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& image, const cv::Vec3d& rvec,
                 const cv::Vec3d& tvec, const cv::Matx33d& k) {
  const std::vector<cv::Point2d> reprojected = project_pinhole(object, rvec, tvec, k);
  double sq = 0;
  for (std::size_t i = 0; i < image.size(); ++i) {
    const cv::Point2d e = reprojected[i] - image[i];
    sq += e.dot(e);
  }
  return std::sqrt(sq / double(image.size()));
}

// How badly a pose's foreshortening explains the squares' inks: a square's image area is
// its design area times det(H) / z^3 at its depth z (the Jacobian of the plane's
// homography), so log(ink / design area) + 3 log z is one constant over the squares. A
// separate constant for the two baselines, whose larger squares the blobs' reach cuts
// differently under blur, keeps that bias from reading as a tilt. The sum of squared
// residuals; NaN without inks (an outline reading).
double shape_misfit(const std::vector<double>& log_ink, const std::vector<bool>& baseline,
                    const std::vector<cv::Point3d>& object, const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  if (log_ink.empty()) return std::nan("");
  const cv::Matx33d r = rotation_matrix(rvec);
  std::vector<double> residual;
  double sum[2] = {0, 0};
  int count[2] = {0, 0};
  for (std::size_t g = 0; g < object.size(); ++g) {
    const double z = (r * cv::Vec3d(object[g].x, object[g].y, object[g].z) + tvec)[2];
    if (!(z > 0)) return std::nan("");
    residual.push_back(log_ink[g] + 3 * std::log(z));
    sum[baseline[g]] += residual.back(), ++count[baseline[g]];
  }
  double ss = 0;
  for (std::size_t g = 0; g < object.size(); ++g) {
    const double e = residual[g] - sum[baseline[g]] / count[baseline[g]];
    ss += e * e;
  }
  return ss;
}

}  // namespace

// What cv::solvePnPRefineLM minimises, without its generic machinery (Jacobians for every
// intrinsic and distortion term, matrices made at every step: 47 us for the 9 points of a
// 3x3, a fifth of a tracked marker's time) and run until it settles: its 20 steps left
// markers seen nearly face on, whose error changes slowly with the tilt, short of the
// optimum (Pose.RefinementReachesTheLeastSquaresOptimum). The rotation moves by a small
// turn applied in the camera frame.
void refine_pose(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& observed, const cv::Matx33d& k,
                 cv::Vec3d& rvec, cv::Vec3d& tvec, const std::vector<EdgePoint>& edges, double edge_weight) {
  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  cv::Matx33d r = rotation_matrix(rvec);
  // The squared error of (r, t), with the normal equations when asked.
  const std::size_t points = object.size() + (edge_weight > 0 ? edges.size() : 0);
  const auto evaluate = [&](const cv::Matx33d& r, const cv::Vec3d& t, Matrix6* h, Vector6* g) {
    double cost = 0;
    if (h) h->setZero(), g->setZero();
    for (std::size_t i = 0; i < points; ++i) {
      const bool edge = i >= object.size();
      const cv::Point3d& o = edge ? edges[i - object.size()].object : object[i];
      const cv::Point2d& seen = edge ? edges[i - object.size()].observed : observed[i];
      const cv::Vec3d turned = r * cv::Vec3d(o.x, o.y, o.z);
      const cv::Vec3d p = turned + t;
      if (!(p[2] > 0)) return std::numeric_limits<double>::infinity();
      const double iz = 1 / p[2], x = p[0] * iz, y = p[1] * iz;
      const double ex = k(0, 0) * x + k(0, 1) * y + k(0, 2) - seen.x, ey = k(1, 1) * y + k(1, 2) - seen.y;
      // A stroke's point counts only its distance across the stroke: it may lie anywhere along it.
      const cv::Point2d n =
          edge ? edges[i - object.size()].normal * (edge_weight * std::sqrt(edges[i - object.size()].weight))
               : cv::Point2d();
      const double across = n.x * ex + n.y * ey;
      cost += edge ? across * across : ex * ex + ey * ey;
      if (!h) continue;
      // d(pixel)/d(camera point), then through p = turned + t: d/dt is the identity and a
      // small turn w moves p by w x turned.
      Eigen::Matrix<double, 2, 3> dp;
      dp << k(0, 0) * iz, k(0, 1) * iz, -(k(0, 0) * x + k(0, 1) * y) * iz, 0, k(1, 1) * iz, -k(1, 1) * y * iz;
      Eigen::Matrix3d cross;
      cross << 0, turned[2], -turned[1], -turned[2], 0, turned[0], turned[1], -turned[0], 0;
      Eigen::Matrix<double, 2, 6> j;
      j << dp * cross, dp;
      if (edge) {
        const Eigen::Matrix<double, 1, 6> je = Eigen::RowVector2d(n.x, n.y) * j;
        *h += je.transpose() * je;
        *g += je.transpose() * across;
      } else {
        *h += j.transpose() * j;
        *g += j.transpose() * Eigen::Vector2d(ex, ey);
      }
    }
    return cost;
  };
  Matrix6 h;
  Vector6 g;
  double cost = evaluate(r, tvec, &h, &g), lambda = 1e-3;
  if (!std::isfinite(cost)) return;
  for (int iteration = 0; iteration < 50; ++iteration) {
    Matrix6 damped = h;
    damped.diagonal() *= 1 + lambda;
    const Vector6 step = damped.ldlt().solve(-g);
    if (!step.allFinite()) return;
    const cv::Matx33d r_next = rotation_matrix(cv::Vec3d(step[0], step[1], step[2])) * r;
    const cv::Vec3d t_next = tvec + cv::Vec3d(step[3], step[4], step[5]);
    const double next = evaluate(r_next, t_next, nullptr, nullptr);
    // A step below a ten-billionth of a radian and of the distance changes nothing a
    // double can show; one that fails there is rounding, not a worse pose.
    const bool negligible = step.head<3>().norm() < 1e-10 && step.tail<3>().norm() < 1e-10 * cv::norm(tvec);
    if (next < cost) {
      const bool settled = cost - next <= 1e-12 * cost || negligible;
      r = r_next, tvec = t_next, cost = next, lambda = std::max(lambda / 10, 1e-12);
      if (settled) break;
      evaluate(r, tvec, &h, &g);
    } else {
      lambda *= 10;
      if (lambda > 1e12 || negligible) break;
    }
  }
  rvec = rotation_vector(r);
}

namespace {

// The 99th percentile of the F distribution with (6, 2n^2 - 6) degrees of freedom, for
// n = 3..8: how much the centroids' squared error may grow, over its share of their
// noise, when the pose also has to fit the border's stroke, before the two disagree
// (1 % of markers that agree would be refused).
constexpr double kCentroidsAgree[] = {4.821, 3.591, 3.243, 3.088, 3.004, 2.953};

// `chosen` refined on the border's stroke as well as the centroids, each of its points
// weighed by the centroids' noise over the stroke's (the centroids' measured from their
// own fit), unless the centroids then fit worse than their noise allows: the marker is
// not the flat rigid square the two share (a bent sheet, a rolling shutter's skew), and
// the centroids, nearer its centre, are the better guide. 2x2 has two degrees of freedom
// left over its four centroids, too few to measure their noise.
void add_border_edges(const std::vector<cv::Point3d>& object, const cv::Matx33d& k, const BorderEdges& edges,
                      Solution& chosen) {
  const int freedom = 2 * int(object.size()) - 6;
  const int n = int(std::lround(std::sqrt(double(object.size()))));
  if (edges.sides.empty() || n < 3 || n > 8 || !(chosen.rms > 0)) return;
  const double weight = chosen.rms * std::sqrt(double(object.size()) / freedom) / edges.noise;
  if (!(weight > 0) || !std::isfinite(weight)) return;
  cv::Vec3d rvec = chosen.rvec, tvec = chosen.tvec;
  refine_pose(object, chosen.observed, k, rvec, tvec, edges.sides, weight);
  const double rms = rms_error(object, chosen.observed, rvec, tvec, k);
  const double growth = (rms * rms / (chosen.rms * chosen.rms) - 1) * freedom / 6;
  if (!(growth <= kCentroidsAgree[n - 3])) return;
  // Its rms stays its own fit's to the centroids: what the ambiguity ratio compares.
  chosen.rvec = rvec, chosen.tvec = tvec;
}

}  // namespace

bool estimate_pose(const Candidate& c, const Decoding& d, const Camera& camera, const DetectorParams& params,
                   Detection& out, const BorderEdges& edges) {
  const Family& f = c.family;
  const double size = params.tag_size;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  std::vector<UnitRect> squares;
  std::vector<double> log_ink;  // per design area; empty when a square has no ink measured
  std::vector<bool> baseline;
  for (int g = 0; g < f.cell_count(); ++g) {
    const int digit = f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g));
    const Blob& blob = c.blobs[d.blob_of_cell[g]];
    object.push_back(f.to_marker_frame(f.center(g, digit), size));
    image.push_back(blob.point);
    squares.push_back(f.square(g, digit));
    log_ink.push_back(std::log(blob.mass / (squares.back().width * squares.back().height)));
    baseline.push_back(f.is_baseline(g));
  }
  if (!std::all_of(log_ink.begin(), log_ink.end(), [](double v) { return std::isfinite(v); })) log_ink.clear();
  const cv::Matx33d k = camera.matrix();  // the points are undistorted already
  std::vector<cv::Point3d> corners;
  for (const UnitRect& s : squares)
    for (const cv::Point2d u : {cv::Point2d(s.x, s.y), cv::Point2d(s.x + s.width, s.y),
                                cv::Point2d(s.x + s.width, s.y + s.height), cv::Point2d(s.x, s.y + s.height)})
      corners.push_back(f.to_marker_frame(u, size));
  // Each of IPPE's solutions, refined: each observation moved from the centroid of the
  // projected square to the projection of its centre, as that solution predicts (the bias
  // is small beside the pose's error, so the first pose is good enough for it), then
  // Levenberg-Marquardt on all n^2 points.
  const auto refine = [&](cv::Vec3d rvec, cv::Vec3d tvec) {
    Solution s{rvec, tvec, image, 0};
    if (params.refine_pose) {
      const std::vector<cv::Point2d> centres = project_pinhole(object, rvec, tvec, k);
      const std::vector<cv::Point2d> quads = project_pinhole(corners, rvec, tvec, k);
      for (int g = 0; g < f.cell_count(); ++g) {
        const std::vector<cv::Point2d> quad(quads.begin() + 4 * g, quads.begin() + 4 * g + 4);
        s.observed[g] -= polygon_centroid(quad) - centres[g];
      }
      refine_pose(object, s.observed, k, s.rvec, s.tvec);
    }
    s.rms = rms_error(object, s.observed, s.rvec, s.tvec, k);
    s.shape_misfit = shape_misfit(log_ink, baseline, object, s.rvec, s.tvec);
    return s;
  };
  std::vector<Solution> solutions;
  try {
    std::vector<cv::Mat> rvecs, tvecs;
    cv::solvePnPGeneric(object, image, k, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
    for (std::size_t i = 0; i < rvecs.size(); ++i) {
      Solution s = refine(cv::Vec3d(rvecs[i]), cv::Vec3d(tvecs[i]));
      // In front of the camera, or no pose at all.
      if (std::isfinite(s.tvec[2]) && s.tvec[2] > 0 && std::isfinite(s.rms)) solutions.push_back(std::move(s));
    }
  } catch (const cv::Exception&) {
    return false;  // a degenerate point set: not a marker we can localise
  }
  if (solutions.empty()) return false;
  std::stable_sort(solutions.begin(), solutions.end(),
                   [](const Solution& a, const Solution& b) { return a.rms < b.rms; });
  // Where the centroids hardly tell the two apart, the squares' foreshortening does.
  if (solutions.size() > 1 && solutions[1].rms < params.shape_choice_ratio * solutions[0].rms &&
      solutions[1].shape_misfit < solutions[0].shape_misfit)
    std::swap(solutions[0], solutions[1]);
  Solution& best = solutions[0];
  if (params.refine_pose) add_border_edges(object, k, edges, best);
  const cv::Vec3d rvec = best.rvec, tvec = best.tvec;
  out.reprojection_error = best.rms;
  out.alternative_rvec = out.alternative_tvec = cv::Vec3d();
  out.alternative_reprojection_error = out.ambiguity_ratio = 0;
  if (solutions.size() > 1) {
    out.alternative_rvec = solutions[1].rvec, out.alternative_tvec = solutions[1].tvec;
    out.alternative_reprojection_error = solutions[1].rms;
    // A perfect fit (a synthetic marker) is unambiguous whenever the other is not perfect.
    // Under 1 when the squares' foreshortening chose against the centroids.
    out.ambiguity_ratio = solutions[1].rms / std::max(best.rms, 1e-12);
  }
  out.rvec = rvec, out.tvec = tvec;
  out.tag_size = size;
  out.calibrated = camera.calibrated;
  std::vector<cv::Point3d> outline;
  for (const cv::Point2d& u : f.outer_corners()) outline.push_back(f.to_marker_frame(u, size));
  outline.emplace_back(0, 0, 0);
  const std::vector<cv::Point2d> projected = camera.project(outline, rvec, tvec);
  for (int i = 0; i < 4; ++i) out.corners[i] = projected[i];
  out.center = projected[4];
  return true;
}

}  // namespace lftag::detail
