// SPDX-License-Identifier: LGPL-2.1-or-later
// Synthetic camera frames. Each pixel is traced back onto the target planes (or a bent
// target's cylinder) through the camera model. A pixel whose four corners fall in one
// cell of a target lies wholly in that cell (the pixel's footprint on the plane is
// convex, and so is the cell; on a cylinder nearly so at a pixel's scale), so only
// pixels that straddle an edge are supersampled.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "lftag/render.hpp"

namespace lftag {
namespace {

// Where a ray lands on a target: a cell index, or a code for a half-plane that misses it.
enum Miss : int { kLeft = -1, kRight = -2, kAbove = -3, kBelow = -4, kBehind = -5 };

struct PlaneMap {
  cv::Matx33d image_to_plane;  // normalised image coordinates -> plane grid coordinates
  int cols = 0, rows = 0;
  // A bent target (SceneTarget::bend_radius): the camera centre and the camera-to-plane
  // rotation in the plane frame, the radius and the grid's geometry.
  double bend = 0;
  cv::Matx33d camera_to_plane;
  cv::Vec3d origin;
  double half_w = 0, half_h = 0, cell = 0;

  // Grid coordinates of ray q, or false when the ray misses the plane's front.
  bool grid(double qx, double qy, double& gx, double& gy) const {
    if (bend != 0) return cylinder_grid(qx, qy, gx, gy);
    const cv::Matx33d& g = image_to_plane;
    const double w = g(2, 0) * qx + g(2, 1) * qy + g(2, 2);
    if (!(w > 0)) return false;
    gx = (g(0, 0) * qx + g(0, 1) * qy + g(0, 2)) / w;
    gy = (g(1, 0) * qx + g(1, 1) * qy + g(1, 2)) / w;
    return true;
  }

  // The ray meets the cylinder at up to two points in front of the camera; the one on
  // the sheet is taken (the nearer if both are), else the one nearest the sheet's arc,
  // so that the half-plane codes below stay consistent between neighbouring rays.
  bool cylinder_grid(double qx, double qy, double& gx, double& gy) const {
    gx = gy = -1;
    const cv::Vec3d d = camera_to_plane * cv::Vec3d(qx, qy, 1);
    const double r = bend, ox = origin[0], oz = origin[2] - r;
    const double a = d[0] * d[0] + d[2] * d[2], b = ox * d[0] + oz * d[2], c = ox * ox + oz * oz - r * r;
    const double disc = b * b - a * c;
    if (!(a > 0) || !(disc >= 0)) return false;
    const double root = std::sqrt(disc);
    bool any = false;
    double best = 0;
    for (const double lambda : {(-b - root) / a, (-b + root) / a}) {
      if (!(lambda > 0)) continue;
      const cv::Vec3d p = origin + lambda * d;
      const double theta = std::atan2(p[0] / r, (r - p[2]) / r);
      const double x = (r * theta + half_w) / cell, y = (p[1] + half_h) / cell;
      const bool on = x >= 0 && x < cols && y >= 0 && y < rows;
      if (!any || on || std::abs(theta) < best) gx = x, gy = y, best = on ? -1 : std::abs(theta);
      any = true;
      if (on) break;
    }
    return any;
  }

  int code(double qx, double qy) const {
    double gx, gy;
    // Written so that NaN (a ray of a degenerate camera) falls outside, never into a cell.
    if (!grid(qx, qy, gx, gy)) return kBehind;
    if (!(gx >= 0)) return kLeft;
    if (!(gx < cols)) return kRight;
    if (!(gy >= 0)) return kAbove;
    if (!(gy < rows)) return kBelow;
    return int(gy) * cols + int(gx);
  }
};

PlaneMap plane_map(const SceneTarget& t) {
  cv::Matx33d r;
  cv::Rodrigues(t.rvec, r);
  // Plane grid (gx, gy) -> plane metres -> camera: H = [r1 r2 t] * A.
  const double half_w = t.albedo.cols * t.cell_size / 2, half_h = t.albedo.rows * t.cell_size / 2;
  const cv::Matx33d a(t.cell_size, 0, -half_w, 0, t.cell_size, -half_h, 0, 0, 1);
  const cv::Matx33d h =
      cv::Matx33d(r(0, 0), r(0, 1), t.tvec[0], r(1, 0), r(1, 1), t.tvec[1], r(2, 0), r(2, 1), t.tvec[2]) * a;
  PlaneMap m;
  // H maps a plane point to depth * (x, y, 1), so H^-1 maps a ray to (gx, gy, 1) / depth:
  // the third coordinate is positive exactly in front of the camera.
  m.image_to_plane = h.inv();
  m.cols = t.albedo.cols;
  m.rows = t.albedo.rows;
  if (t.bend_radius != 0) {
    if (!(std::abs(t.bend_radius) * CV_PI > half_w))
      throw std::invalid_argument("a bent target's radius must exceed its half width / pi");
    m.bend = t.bend_radius;
    m.camera_to_plane = r.t();
    m.origin = -(r.t() * t.tvec);
    m.half_w = half_w, m.half_h = half_h, m.cell = t.cell_size;
  }
  return m;
}

// A point of a target's grid (metres from its centre, in the plane) in the plane frame:
// on the cylinder for a bent target.
cv::Vec3d on_target(const SceneTarget& t, double x, double y) {
  if (t.bend_radius == 0) return {x, y, 0};
  const double r = t.bend_radius, theta = x / r;
  return {r * std::sin(theta), y, r * (1 - std::cos(theta))};
}

// The image rectangle a target can touch (whole frame if it crosses the camera plane).
cv::Rect footprint(const Camera& cam, const SceneTarget& t, cv::Size size) {
  cv::Matx33d r;
  cv::Rodrigues(t.rvec, r);
  const double hw = t.albedo.cols * t.cell_size / 2, hh = t.albedo.rows * t.cell_size / 2;
  std::vector<cv::Point3d> pts;
  // Distortion and bending bend the edges.
  const int steps = cam.has_distortion() || t.bend_radius != 0 ? 32 : 1;
  for (int i = 0; i <= steps; ++i) {
    const double f = double(i) / steps;
    for (cv::Point2d p : {cv::Point2d(-hw + 2 * hw * f, -hh), cv::Point2d(hw, -hh + 2 * hh * f),
                          cv::Point2d(hw - 2 * hw * f, hh), cv::Point2d(-hw, hh - 2 * hh * f)}) {
      const cv::Vec3d c = r * on_target(t, p.x, p.y) + t.tvec;
      if (c[2] <= 1e-9) return cv::Rect(cv::Point(0, 0), size);
      pts.emplace_back(c[0], c[1], c[2]);
    }
  }
  const std::vector<cv::Point2d> img = cam.project(pts);
  double x0 = 1e18, y0 = 1e18, x1 = -1e18, y1 = -1e18;
  for (const cv::Point2d& p : img) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return cv::Rect(cv::Point(0, 0), size);
    x0 = std::min(x0, p.x), x1 = std::max(x1, p.x), y0 = std::min(y0, p.y), y1 = std::max(y1, p.y);
  }
  const double lim = 1e7;
  const cv::Rect box(cv::Point(int(std::floor(std::max(x0, -lim))) - 2, int(std::floor(std::max(y0, -lim))) - 2),
                     cv::Point(int(std::ceil(std::min(x1, lim))) + 3, int(std::ceil(std::min(y1, lim))) + 3));
  return box & cv::Rect(cv::Point(0, 0), size);
}

// Draws one target over `image` (albedo), compositing by the covered fraction of each pixel.
void draw_target(const SceneTarget& t, const cv::Mat2f& rays, int supersample, const cv::Rect& box, cv::Mat1f& image) {
  const PlaneMap map = plane_map(t);
  const int ss = supersample;
  const float inv_samples = 1.0f / float(ss * ss);
  std::vector<int> codes_top(box.width + 1), codes_bottom(box.width + 1);
  auto row_codes = [&](int corner_y, std::vector<int>& codes) {
    const cv::Vec2f* ray = rays.ptr<cv::Vec2f>(corner_y) + box.x;
    for (int i = 0; i <= box.width; ++i) codes[i] = map.code(ray[i][0], ray[i][1]);
  };
  row_codes(box.y, codes_top);
  for (int y = box.y; y < box.y + box.height; ++y) {
    row_codes(y + 1, codes_bottom);
    const cv::Vec2f* top = rays.ptr<cv::Vec2f>(y);
    const cv::Vec2f* bottom = rays.ptr<cv::Vec2f>(y + 1);
    float* out = image.ptr<float>(y);
    for (int i = 0; i < box.width; ++i) {
      const int x = box.x + i;
      const int c = codes_top[i];
      if (c == codes_top[i + 1] && c == codes_bottom[i] && c == codes_bottom[i + 1]) {
        if (c >= 0) out[x] = t.albedo(c / map.cols, c % map.cols);
        continue;  // wholly inside one cell, or wholly on the far side of one edge line
      }
      float sum = 0.0f;
      int hits = 0;
      for (int sy = 0; sy < ss; ++sy) {
        const float fy = (sy + 0.5f) / ss;
        // Rays at the left and right edges of this sub-row, interpolated between corners.
        const float lx = top[x][0] + (bottom[x][0] - top[x][0]) * fy;
        const float ly = top[x][1] + (bottom[x][1] - top[x][1]) * fy;
        const float rx = top[x + 1][0] + (bottom[x + 1][0] - top[x + 1][0]) * fy;
        const float ry = top[x + 1][1] + (bottom[x + 1][1] - top[x + 1][1]) * fy;
        for (int sx = 0; sx < ss; ++sx) {
          const float fx = (sx + 0.5f) / ss;
          double gx, gy;
          if (!map.grid(lx + (rx - lx) * fx, ly + (ry - ly) * fx, gx, gy)) continue;
          if (!(gx >= 0 && gy >= 0 && gx < map.cols && gy < map.rows)) continue;  // NaN misses too
          sum += t.albedo(int(gy), int(gx));
          ++hits;
        }
      }
      out[x] = out[x] * (1.0f - hits * inv_samples) + sum * inv_samples;
    }
    std::swap(codes_top, codes_bottom);
  }
}

}  // namespace

cv::Vec3d rotation_from_angles(double roll_deg, double tilt_deg, double pan_deg) {
  const double d = CV_PI / 180;
  cv::Matx33d roll, tilt, pan;
  cv::Rodrigues(cv::Vec3d(0, 0, roll_deg * d), roll);
  cv::Rodrigues(cv::Vec3d(tilt_deg * d, 0, 0), tilt);
  cv::Rodrigues(cv::Vec3d(0, pan_deg * d, 0), pan);
  cv::Vec3d r;
  cv::Rodrigues(pan * tilt * roll, r);
  return r;
}

SceneTarget to_target(const SceneMarker& m) {
  if (!(m.tag_size > 0)) throw std::invalid_argument("the tag size must be positive");
  if (!(m.margin_units >= 0) || m.margin_units != std::floor(m.margin_units))
    throw std::invalid_argument("the margin must be a whole number of units");
  const int margin = int(m.margin_units);
  const cv::Mat1b bits = m.family.unit_bitmap(m.id);
  cv::Mat1f albedo(bits.rows + 2 * margin, bits.cols + 2 * margin, m.white);
  for (int y = 0; y < bits.rows; ++y)
    for (int x = 0; x < bits.cols; ++x) albedo(y + margin, x + margin) = bits(y, x) ? m.white : m.black;
  return {albedo, m.tag_size / m.family.side(), m.rvec, m.tvec};
}

MarkerTruth make_truth(const Camera& camera, const SceneMarker& m) {
  MarkerTruth t;
  t.family = m.family, t.id = m.id, t.tag_size = m.tag_size, t.rvec = m.rvec, t.tvec = m.tvec;
  auto project = [&](const std::vector<cv::Point2d>& units) {
    std::vector<cv::Point3d> pts;
    for (const cv::Point2d& u : units) pts.push_back(m.family.to_marker_frame(u, m.tag_size));
    return camera.project(pts, m.rvec, m.tvec);
  };
  const auto kp = m.family.keypoints(m.id);
  const auto oc = m.family.outer_corners();
  t.keypoints = project({kp.begin(), kp.end()});
  t.centers = project(m.family.centers(m.id));
  // Area centroid of each projected square: its outline, densely sampled so that lens
  // distortion bends it, as a polygon.
  for (const UnitRect& r : m.family.black_squares(m.id)) {
    std::vector<cv::Point2d> outline;
    const int steps = 16;
    for (int i = 0; i < steps; ++i) outline.emplace_back(r.x + r.width * double(i) / steps, r.y);
    for (int i = 0; i < steps; ++i) outline.emplace_back(r.x + r.width, r.y + r.height * double(i) / steps);
    for (int i = 0; i < steps; ++i) outline.emplace_back(r.x + r.width * (1 - double(i) / steps), r.y + r.height);
    for (int i = 0; i < steps; ++i) outline.emplace_back(r.x, r.y + r.height * (1 - double(i) / steps));
    t.centroids.push_back(detail::polygon_centroid(project(outline)));
  }
  t.corners = project({oc.begin(), oc.end()});
  t.center = project({cv::Point2d(m.family.side() / 2.0, m.family.side() / 2.0)})[0];
  cv::Matx33d r;
  cv::Rodrigues(m.rvec, r);
  bool visible = true;
  for (const cv::Point2d& c : oc) {
    const cv::Point3d p = m.family.to_marker_frame(c, m.tag_size);
    if ((r * cv::Vec3d(p.x, p.y, p.z) + m.tvec)[2] <= 0) visible = false;
  }
  for (int i = 0; i < 4; ++i) {
    const cv::Point2d& c = t.corners[i];
    if (c.x < 0 || c.y < 0 || c.x > camera.width - 1 || c.y > camera.height - 1) visible = false;
    t.edge_px += cv::norm(t.corners[(i + 1) % 4] - c) / 4;
  }
  t.fully_visible = visible;
  return t;
}

SceneRenderer::SceneRenderer(SceneParams p) : params_(std::move(p)) {
  const Camera& cam = params_.camera;
  cam.validate();
  const int w = cam.width, h = cam.height;
  if (w <= 0 || h <= 0) throw std::invalid_argument("the scene camera needs a frame size");
  if (params_.supersample < 1 || params_.supersample > 64)
    throw std::invalid_argument("supersample must be between 1 and 64");
  if (!(params_.blur_length_px >= 0) || !(params_.noise_sigma >= 0))
    throw std::invalid_argument("blur length and noise must not be negative");

  // Normalised coordinates of every pixel corner (x - 0.5, y - 0.5).
  corner_rays_.create(h + 1, w + 1);
  if (cam.has_distortion()) {
    std::vector<cv::Point2f> corners, rays;
    corners.reserve(std::size_t(w + 1) * (h + 1));
    for (int y = 0; y <= h; ++y)
      for (int x = 0; x <= w; ++x) corners.emplace_back(x - 0.5f, y - 0.5f);
    cv::undistortPoints(corners, rays, cam.matrix(), cam.distortion_mat(), cv::noArray(), cv::noArray(),
                        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 1e-9));
    std::copy(rays.begin(), rays.end(), corner_rays_.begin());
  } else {
    for (int y = 0; y <= h; ++y)
      for (int x = 0; x <= w; ++x)
        corner_rays_(y, x) = cv::Vec2f(float((x - 0.5 - cam.cx) / cam.fx), float((y - 0.5 - cam.cy) / cam.fy));
  }

  fit_background();

  light_.create(h, w);
  const double a = params_.light_angle_deg * CV_PI / 180, ca = std::cos(a), sa = std::sin(a);
  const double extent = std::abs(w * ca) + std::abs(h * sa);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double along = ((x - w / 2.0) * ca + (y - h / 2.0) * sa) / extent;  // -0.5 .. 0.5
      light_(y, x) = float(255.0 * params_.exposure * (1.0 + params_.light_gradient * along));
    }
}

void SceneRenderer::fit_background() {
  const int w = params_.camera.width, h = params_.camera.height;
  if (!params_.photo.empty()) {
    cv::Mat grey;
    if (params_.photo.channels() == 3)
      cv::cvtColor(params_.photo, grey, cv::COLOR_BGR2GRAY);
    else if (params_.photo.channels() == 4)
      cv::cvtColor(params_.photo, grey, cv::COLOR_BGRA2GRAY);
    else
      grey = params_.photo;
    // Scale to cover the frame, then crop the centre.
    const double s = std::max(double(w) / grey.cols, double(h) / grey.rows);
    cv::Mat scaled;
    cv::resize(grey, scaled,
               cv::Size(std::max(w, int(std::ceil(grey.cols * s))), std::max(h, int(std::ceil(grey.rows * s)))), 0, 0,
               s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    scaled(cv::Rect((scaled.cols - w) / 2, (scaled.rows - h) / 2, w, h)).convertTo(background_, CV_32F, 1.0 / 255);
  } else {
    background_ = cv::Mat1f(h, w, float(params_.background));
  }
}

SceneRenderer SceneRenderer::with_photo(cv::Mat photo) const {
  SceneRenderer r = *this;  // shares the traced pixel corners and the light
  r.params_.photo = std::move(photo);
  r.background_ = cv::Mat1f();  // a buffer of its own, not the one shared with *this
  r.fit_background();
  return r;
}

cv::Mat1f SceneRenderer::render_linear(const std::vector<SceneTarget>& targets) const {
  const cv::Size size(params_.camera.width, params_.camera.height);
  cv::Mat1f image = background_.clone();
  std::vector<std::size_t> order(targets.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return cv::norm(targets[a].tvec) > cv::norm(targets[b].tvec); });
  for (std::size_t i : order) {
    const SceneTarget& t = targets[i];
    if (t.albedo.empty() || !(t.cell_size > 0)) throw std::invalid_argument("a scene target is empty");
    const cv::Rect box = footprint(params_.camera, t, size);
    if (!box.empty()) draw_target(t, corner_rays_, params_.supersample, box, image);
  }
  cv::multiply(image, light_, image);
  if (params_.blur_length_px > 0)
    cv::filter2D(image, image, -1, motion_blur_kernel(params_.blur_length_px, params_.blur_angle_deg),
                 cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
  return image;
}

cv::Mat1b SceneRenderer::render(const std::vector<SceneTarget>& targets, std::uint64_t seed) const {
  return quantize(render_linear(targets), seed);
}

cv::Mat1b SceneRenderer::quantize(const cv::Mat1f& linear, std::uint64_t seed) const {
  cv::Mat1f image = linear.clone();
  if (params_.noise_sigma > 0) {
    cv::Mat1f noise(image.size());
    cv::RNG rng(seed ? seed : params_.seed);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, params_.noise_sigma);
    image += noise;
  }
  cv::Mat1b out;
  image.convertTo(out, CV_8U);  // rounds and saturates
  return out;
}

RenderedScene render_scene(const SceneParams& params, const std::vector<SceneMarker>& markers) {
  RenderedScene scene;
  std::vector<SceneTarget> targets;
  for (const SceneMarker& m : markers) {
    targets.push_back(to_target(m));
    scene.truth.push_back(make_truth(params.camera, m));
  }
  scene.image = SceneRenderer(params).render(targets);
  return scene;
}

cv::Mat1f motion_blur_kernel(double length_px, double angle_deg) {
  if (!(length_px >= 0)) throw std::invalid_argument("blur length must not be negative");
  const int half = int(std::ceil(length_px / 2)) + 1;
  cv::Mat1f k(2 * half + 1, 2 * half + 1, 0.0f);
  // 0 degrees is vertical, 90 horizontal. Splat many points of the segment bilinearly.
  const double a = angle_deg * CV_PI / 180, dx = std::sin(a), dy = std::cos(a);
  const int samples = std::max(1, int(std::ceil(length_px * 32)));
  for (int i = 0; i < samples; ++i) {
    const double s = length_px * ((i + 0.5) / samples - 0.5);
    const double x = half + s * dx, y = half + s * dy;
    const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
    const float fx = float(x - x0), fy = float(y - y0);
    k(y0, x0) += (1 - fx) * (1 - fy);
    k(y0, x0 + 1) += fx * (1 - fy);
    k(y0 + 1, x0) += (1 - fx) * fy;
    k(y0 + 1, x0 + 1) += fx * fy;
  }
  return k / cv::sum(k)[0];
}

}  // namespace lftag
