// SPDX-License-Identifier: LGPL-2.1-or-later
// The outline reading's alignment: the enhanced correlation coefficient (ECC) of a template
// with an image, maximised over a homography (Evangelidis and Psarakis, 2008), step for
// step as cv::findTransformECC takes it with a smoothing of 3 and no mask.
//
// Why not cv::findTransformECC itself: it smooths the image and takes its gradients anew
// for every template aligned to it (a reading aligns two to four), and every step warps
// three images, builds eight Jacobian images and takes 52 dot products over them, with
// allocations, which made it a third of a shadowed or blurred frame's time. Here the image
// is prepared once and a step is two passes over the template's pixels.

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "stages.hpp"

namespace lftag::detail {
namespace {

constexpr int kSmoothing = 3;  // cv::findTransformECC's gaussFiltSize as the reading used it
// cv::warpPerspective's sub-pixel grid: positions are rounded to 1/32 of a pixel.
constexpr int kTabBits = 5, kTabSize = 1 << kTabBits;

// A position rounded to the nearest integer, as cv::saturate_cast<int> rounds it.
int round_to_int(double d) { return cvRound(std::clamp(d, double(INT_MIN), double(INT_MAX))); }

}  // namespace

EccAlignment::EccAlignment(const cv::Mat1f& image) {
  cv::Mat1f smooth, gx, gy;
  cv::GaussianBlur(image, smooth, cv::Size(kSmoothing, kSmoothing), 0, 0);
  const cv::Matx13f derivative(-0.5f, 0.0f, 0.5f);
  cv::filter2D(smooth, gx, -1, derivative);
  cv::filter2D(smooth, gy, -1, derivative.t());
  cv::merge(std::vector<cv::Mat>{smooth, gx, gy}, prepared_);
}

std::optional<double> EccAlignment::align(const cv::Mat1f& templ, cv::Matx33f& warp, int max_steps,
                                          double min_change) const {
  cv::Mat1f t;
  cv::GaussianBlur(templ, t, cv::Size(kSmoothing, kSmoothing), 0, 0);
  const int ws = t.cols, hs = t.rows, wd = prepared_.cols, hd = prepared_.rows;
  const std::size_t pixels = std::size_t(ws) * hs;
  // Per template pixel: the image and its gradients where the warp puts it, and whether
  // the nearest image pixel exists there (the mask that cv::findTransformECC warps).
  std::vector<cv::Vec3f> warped(pixels);
  std::vector<std::uint8_t> inside(pixels);
  // A row's columns: the Jacobian of the warped image in the warp's 8 parameters (in the
  // order m00 m10 m20 m01 m11 m21 m02 m12), the zero-mean image and the zero-mean template.
  // Their Gram matrix holds the Hessian, both projections and the correlation; it is
  // symmetric, so only its lower triangle is summed (a row's 55 dot products).
  using Columns = Eigen::Matrix<float, Eigen::Dynamic, 10>;
  Columns columns(ws, 10);
  Eigen::Matrix<float, 10, 10> row_gram = Eigen::Matrix<float, 10, 10>::Zero();

  double rho = -1, last_rho = -min_change;
  for (int step = 1; step <= max_steps && std::abs(rho - last_rho) >= min_change; ++step) {
    // Pass 1: the image and its gradients sampled under the warp (bilinear on the 1/32
    // pixel grid, zero outside, as cv::warpPerspective with WARP_INVERSE_MAP samples
    // them), and both images' sums over the mask.
    const cv::Matx33d m = warp;
    double count = 0, sum_i = 0, sum_ii = 0, sum_t = 0, sum_tt = 0;
    for (int y = 0; y < hs; ++y) {
      const double x0 = m(0, 1) * y + m(0, 2), y0 = m(1, 1) * y + m(1, 2), w0 = m(2, 1) * y + m(2, 2);
      const float* trow = t[y];
      for (int x = 0; x < ws; ++x) {
        const std::size_t k = std::size_t(y) * ws + x;
        const double w = w0 + m(2, 0) * x;
        const double scale = w != 0 ? 1 / w : 0, u = (x0 + m(0, 0) * x) * scale, v = (y0 + m(1, 0) * x) * scale;
        const int nx = round_to_int(u), ny = round_to_int(v);  // the nearest pixel
        inside[k] = nx >= 0 && ny >= 0 && nx < wd && ny < hd;
        const int fx = round_to_int(u * kTabSize), fy = round_to_int(v * kTabSize);
        const int sx = fx >> kTabBits, sy = fy >> kTabBits;
        const float ax = float(fx & (kTabSize - 1)) / kTabSize, ay = float(fy & (kTabSize - 1)) / kTabSize;
        const float weights[4] = {(1 - ay) * (1 - ax), (1 - ay) * ax, ay * (1 - ax), ay * ax};
        cv::Vec3f sample(0, 0, 0);
        if (sx >= 0 && sy >= 0 && sx + 1 < wd && sy + 1 < hd) {
          const cv::Vec3f* row0 = prepared_[sy] + sx;
          const cv::Vec3f* row1 = prepared_[sy + 1] + sx;
          sample = row0[0] * weights[0] + row0[1] * weights[1] + row1[0] * weights[2] + row1[1] * weights[3];
        } else if (sx >= -1 && sy >= -1 && sx < wd && sy < hd) {  // partly outside: zero there
          const int xs[2] = {sx, sx + 1}, ys[2] = {sy, sy + 1};
          for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i)
              if (xs[i] >= 0 && ys[j] >= 0 && xs[i] < wd && ys[j] < hd)
                sample += prepared_(ys[j], xs[i]) * weights[j * 2 + i];
        }
        warped[k] = sample;
        if (inside[k]) {
          const double i = sample[0], tv = trow[x];
          count += 1, sum_i += i, sum_ii += i * i, sum_t += tv, sum_tt += tv * tv;
        }
      }
    }
    if (count == 0) return std::nullopt;
    const double mean_i = sum_i / count, mean_t = sum_t / count;
    const double image_norm = std::sqrt(std::max(0.0, sum_ii - count * mean_i * mean_i));
    const double template_norm = std::sqrt(std::max(0.0, sum_tt - count * mean_t * mean_t));

    // Pass 2, a row at a time: the columns, then their Gram matrix. Outside the mask the
    // template counts as zero and the image as sampled.
    Eigen::Matrix<double, 10, 10> gram = Eigen::Matrix<double, 10, 10>::Zero();
    for (int y = 0; y < hs; ++y) {
      const float* trow = t[y];
      for (int x = 0; x < ws; ++x) {
        const std::size_t k = std::size_t(y) * ws + x;
        // cv::findTransformECC's Jacobian takes the warp's last entry as 1.
        const double inv_den = 1 / (m(2, 0) * x + m(2, 1) * y + 1);
        const float hat_x = float(-(m(0, 0) * x + m(0, 1) * y + m(0, 2)) * inv_den);
        const float hat_y = float(-(m(1, 0) * x + m(1, 1) * y + m(1, 2)) * inv_den);
        const float gx = warped[k][1] * float(inv_den), gy = warped[k][2] * float(inv_den);
        const float along = hat_x * gx + hat_y * gy, xf = float(x), yf = float(y);
        columns.row(x) << xf * gx, xf * gy, xf * along, yf * gx, yf * gy, yf * along, gx, gy,
            inside[k] ? warped[k][0] - float(mean_i) : warped[k][0], inside[k] ? trow[x] - float(mean_t) : 0.0f;
      }
      for (int j = 0; j < 10; ++j)
        for (int i = j; i < 10; ++i) row_gram(i, j) = columns.col(i).dot(columns.col(j));
      gram += row_gram.cast<double>();
    }
    for (int j = 1; j < 10; ++j)
      for (int i = 0; i < j; ++i) gram(i, j) = gram(j, i);
    const Eigen::Matrix<double, 8, 8> hessian = gram.topLeftCorner<8, 8>();
    const Eigen::Matrix<double, 8, 1> image_projection = gram.block<8, 1>(0, 8);
    const Eigen::Matrix<double, 8, 1> template_projection = gram.block<8, 1>(0, 9);
    const double correlation = gram(9, 8);
    // cv::Mat::inv gives zeros for a singular matrix: no step, and the loop ends.
    const Eigen::FullPivLU<Eigen::Matrix<double, 8, 8>> lu(hessian);
    const Eigen::Matrix<double, 8, 8> hessian_inv =
        lu.isInvertible() ? Eigen::Matrix<double, 8, 8>(lu.inverse()) : Eigen::Matrix<double, 8, 8>::Zero();

    last_rho = rho;
    rho = correlation / (image_norm * template_norm);
    if (std::isnan(rho)) return std::nullopt;
    // The illumination's gain (lambda), then the step that maximises the correlation.
    const Eigen::Matrix<double, 8, 1> image_projection_h = hessian_inv * image_projection;
    const double lambda_n = image_norm * image_norm - image_projection.dot(image_projection_h);
    const double lambda_d = correlation - template_projection.dot(image_projection_h);
    if (lambda_d <= 0) return std::nullopt;  // the correlation would be minimised
    const double lambda = lambda_n / lambda_d;
    const Eigen::Matrix<double, 8, 1> delta = hessian_inv * (lambda * template_projection - image_projection);
    warp(0, 0) += float(delta[0]), warp(1, 0) += float(delta[1]), warp(2, 0) += float(delta[2]);
    warp(0, 1) += float(delta[3]), warp(1, 1) += float(delta[4]), warp(2, 1) += float(delta[5]);
    warp(0, 2) += float(delta[6]), warp(1, 2) += float(delta[7]);
  }
  return rho;
}

}  // namespace lftag::detail
