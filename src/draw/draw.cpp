// SPDX-License-Identifier: LGPL-2.1-or-later
// Overlays of detections and the debug images of the pipeline's stages.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/draw.hpp"

namespace lftag {
namespace {

// BGR(A) colours; grey images get their luminance.
cv::Scalar colour(const cv::Mat& image, double b, double g, double r) {
  if (image.channels() == 1) return cv::Scalar(0.114 * b + 0.587 * g + 0.299 * r);
  return cv::Scalar(b, g, r, 255);
}

cv::Point fixed(cv::Point2d p) { return cv::Point(cvRound(p.x * 16), cvRound(p.y * 16)); }

void line(cv::Mat& image, cv::Point2d a, cv::Point2d b, const cv::Scalar& c, int width) {
  if (!std::isfinite(a.x + a.y + b.x + b.y)) return;
  cv::line(image, fixed(a), fixed(b), c, width, cv::LINE_AA, 4);
}

// Paints `c` over `roi` with coverage `alpha` (0..255). On a BGRA layer the alpha channel
// blends the same way, which keeps the layer's premultiplied alpha right.
void paint(cv::Mat roi, const cv::Mat1b& alpha, const cv::Scalar& c) {
  const int channels = roi.channels();
  for (int y = 0; y < roi.rows; ++y) {
    std::uint8_t* p = roi.ptr<std::uint8_t>(y);
    const std::uint8_t* a = alpha.ptr<std::uint8_t>(y);
    for (int x = 0; x < roi.cols; ++x, p += channels) {
      if (a[x] == 0) continue;
      const double w = a[x] / 255.0;
      for (int k = 0; k < channels; ++k) p[k] = cv::saturate_cast<std::uint8_t>(c[k] * w + p[k] * (1 - w));
    }
  }
}

// Text with a dark outline so that it reads on any background, beside the marker (under
// its lowest corner, or over its highest when there is no room below) so that a small
// marker stays visible, and shifted to stay inside the frame (long 8x8 ids, markers at
// the edge). The text is rasterised once, anti-aliased, into a small mask and the outline
// grown from it: stroking every glyph twice with thick anti-aliased lines took most of an
// overlaid frame's time.
void label(cv::Mat& image, const std::string& text, const Detection& d, double height, int width) {
  const double scale = height / 22.0;
  const int thick = std::max(1, int(std::round(scale * 1.6)));
  int base = 0;
  const cv::Size size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, thick, &base);
  double top = d.corners[0].y, bottom = d.corners[0].y;
  for (const cv::Point2d& c : d.corners) top = std::min(top, c.y), bottom = std::max(bottom, c.y);
  const int gap = 2 * width + thick + 1;
  const double below = bottom + gap + size.height;                               // baseline under the marker
  const double baseline = below + base < image.rows ? below : top - gap - base;  // else over it
  const int x = std::clamp(cvRound(d.center.x - size.width / 2.0), 0, std::max(0, image.cols - size.width));
  const int y = std::clamp(cvRound(baseline), size.height, std::max(size.height, image.rows - base));
  const int pad = width + thick + 1;
  const cv::Rect box(x - pad, y - size.height - pad, size.width + 2 * pad, size.height + base + 2 * pad);
  const cv::Rect inside = box & cv::Rect(0, 0, image.cols, image.rows);
  if (inside.empty()) return;
  cv::Mat1b glyphs(box.size(), uchar(0)), outline;
  cv::putText(glyphs, text, cv::Point(x, y) - box.tl(), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255), thick,
              cv::LINE_AA);
  cv::dilate(glyphs, outline, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * width + 1, 2 * width + 1)));
  const cv::Rect local = inside - box.tl();
  paint(image(inside), outline(local), colour(image, 0, 0, 0));
  paint(image(inside), glyphs(local), colour(image, 255, 255, 255));
}

cv::Mat to_bgr(const cv::Mat& grey) {
  cv::Mat out;
  cv::cvtColor(grey, out, cv::COLOR_GRAY2BGR);
  return out;
}

}  // namespace

void draw_detections(cv::Mat& image, const std::vector<Detection>& detections, const Camera& camera,
                     const DrawOptions& o) {
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4))
    throw std::invalid_argument("draw_detections needs an 8-bit grey, BGR or BGRA image");
  if (image.empty()) return;
  // Legible from 480p to 4K: strokes and text grow with the frame.
  const double shorter = std::min(image.cols, image.rows);
  const int width = o.line_width > 0 ? int(std::round(o.line_width)) : std::max(1, int(std::round(shorter / 400)));
  const double text = o.text_height > 0 ? o.text_height : std::max(12.0, shorter / 36);
  for (const Detection& d : detections) {
    if (o.outline)
      for (int i = 0; i < 4; ++i) line(image, d.corners[i], d.corners[(i + 1) % 4], colour(image, 0, 255, 255), width);
    if (o.axes) {
      const double l = d.tag_size;
      cv::Matx33d r;
      cv::Rodrigues(d.rvec, r);
      const std::vector<cv::Point3d> ends = {{0, 0, 0}, {l, 0, 0}, {0, l, 0}, {0, 0, l}};
      bool in_front = true;
      for (const cv::Point3d& e : ends) in_front &= (r * cv::Vec3d(e.x, e.y, e.z) + d.tvec)[2] > 0;
      if (in_front) {
        const std::vector<cv::Point2d> p = camera.project(ends, d.rvec, d.tvec);
        line(image, p[0], p[3], colour(image, 255, 0, 0), width + 1);  // z blue
        line(image, p[0], p[2], colour(image, 0, 255, 0), width + 1);  // y green
        line(image, p[0], p[1], colour(image, 0, 0, 255), width + 1);  // x red
      }
    }
    if (o.id) label(image, d.family.name() + ":" + d.id.to_decimal(), d, text, width);
  }
}

std::map<std::string, cv::Mat> draw_trace(const cv::Mat& grey, const DetectionTrace& t, const Camera& camera) {
  std::map<std::string, cv::Mat> out;
  if (grey.empty()) return out;
  const int r = std::max(2, std::min(grey.cols, grey.rows) / 200);
  if (!t.binary.empty()) out["threshold"] = to_bgr(255 - t.binary);

  cv::Mat candidates = to_bgr(grey);
  for (const auto& blobs : t.candidates)
    for (const cv::Point2d& p : blobs) cv::circle(candidates, fixed(p), r * 16, {0, 200, 255}, 1, cv::LINE_AA, 4);
  out["candidates"] = candidates;

  cv::Mat keypoints = to_bgr(grey);
  const cv::Scalar kc[4] = {{0, 0, 255}, {0, 255, 0}, {255, 0, 0}, {255, 0, 255}};  // K0..K3
  for (const auto& k : t.keypoints)
    for (int i = 0; i < 4; ++i) cv::circle(keypoints, fixed(k[i]), r * 16, kc[i], 2, cv::LINE_AA, 4);
  out["keypoints"] = keypoints;

  cv::Mat hypotheses = to_bgr(grey);
  for (const auto& candidate : t.hypotheses)
    for (const auto& outline : candidate)
      for (std::size_t i = 0; i < outline.size(); ++i)
        line(hypotheses, outline[i], outline[(i + 1) % outline.size()], {255, 128, 0}, 1);
  out["hypotheses"] = hypotheses;

  cv::Mat final_pose = to_bgr(grey);
  draw_detections(final_pose, t.detections, camera);
  out["final"] = final_pose;
  return out;
}

}  // namespace lftag
