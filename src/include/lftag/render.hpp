// SPDX-License-Identifier: LGPL-2.1-or-later
// Drawing markers: printable files, exact anti-aliased rasters, and synthetic camera
// scenes with ground truth for tests, benchmarks and the synthetic video source.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/camera.hpp"
#include "lftag/family.hpp"

namespace lftag {

// ---------------------------------------------------------------------------
// Rasters

// Exact area-coverage resampling of an axis-aligned grid of cells (values 0..1 or 0..255)
// into an image: every output pixel is the area-weighted mean of the cells it overlaps.
// Pixel centres are at integer coordinates; cell (0, 0) starts at image point `origin`
// (so origin (-0.5, -0.5) puts it at the top-left corner of the image) and each cell is
// `pixels_per_cell` pixels wide. Pixels outside the grid get `outside`.
cv::Mat1f resample_cells(const cv::Mat1f& cells, cv::Size image_size, double pixels_per_cell, cv::Point2d origin,
                         float outside = 1.0f);

// A fronto-parallel marker image at `pixels_per_unit` with a white margin of
// `margin_units` around the black border, by exact area coverage (0 black, 255 white).
cv::Mat1b rasterize_marker(const Family& family, TagId id, double pixels_per_unit, double margin_units = 2.0);

// ---------------------------------------------------------------------------
// Printable files

struct PrintOptions {
  double size_m = 0.1;        // outer edge of the black border
  double margin_units = 2.0;  // white margin around the border, in marker units
  bool caption = true;        // family, id and size under the marker
  double dpi = 300;           // PNG only: pixels per inch
};

// Writes one marker to `path`; the format follows the extension: .svg, .pdf or .png.
// PNG pixels come from rasterize_marker (exact coverage). Throws std::runtime_error
// when the file cannot be written and std::invalid_argument on bad options.
void write_marker(const std::string& path, const Family& family, TagId id, const PrintOptions& options);

enum class Paper { a4, letter };
Paper parse_paper(const std::string& name);  // "a4" or "letter"; throws std::invalid_argument

// Lays out many markers on pages of `paper` (as many pages as needed; SVG and PNG hold
// one page, so they reject a layout that needs more). Returns the number of pages.
int write_sheet(const std::string& path, const Family& family, const std::vector<TagId>& ids,
                const PrintOptions& options, Paper paper);

// ---------------------------------------------------------------------------
// Scenes

// A flat textured plane in the scene: a grid of cells of `cell_size` metres with
// albedo 0..1, seen with pose (rvec, tvec) from the plane frame to the camera frame.
// The plane frame has its origin at the centre of the grid, x right, y down, z into
// the plane (the marker frame of SPEC 2 when the grid is a marker).
struct SceneTarget {
  cv::Mat1f albedo;
  double cell_size = 0;
  cv::Vec3d rvec, tvec;
  // Not 0: the grid is bent onto a cylinder of this radius (metres) whose axis is
  // parallel to the plane's y axis, keeping its arc length along x (a sheet wrapped
  // round a pipe). Positive: the axis lies on the +z side, so the centre bulges
  // towards a camera the sheet faces; negative: the sides come towards it. The plane
  // frame is the tangent plane at the grid's centre. |bend_radius| must exceed half the
  // grid's width divided by pi.
  double bend_radius = 0;
};

// The rotation vector (marker frame -> camera frame) of a marker that faces the camera
// upright, turned `roll` degrees in its own plane, then tilted `tilt` degrees about the
// camera's x axis and panned `pan` degrees about its y axis.
cv::Vec3d rotation_from_angles(double roll_deg, double tilt_deg, double pan_deg);

// An LFTag marker as a scene target: `margin_units` of white paper around the border.
struct SceneMarker {
  Family family{3};
  TagId id;
  double tag_size = 1.0;  // metres, outer edge of the black border
  cv::Vec3d rvec, tvec;
  double margin_units = 2.0;
  float black = 0.05f;  // albedo of the ink
  float white = 0.9f;   // albedo of the paper
};
SceneTarget to_target(const SceneMarker& marker);

struct SceneParams {
  // Width and height give the frame size; the default is the LFTag paper's simulation
  // camera (640x480, fx = fy = 320).
  Camera camera = Camera::pinhole(320, 320, 319.5, 239.5, 640, 480);
  int supersample = 8;           // samples per pixel edge where a pixel straddles an edge
  double background = 0.5;       // flat background albedo (when no photo)
  cv::Mat photo;                 // optional background photo, scaled to cover the frame
  double exposure = 1.0;         // grey = 255 * exposure * illumination * albedo
  double light_gradient = 0.0;   // illumination varies by +-gradient/2 across the frame
  double light_angle_deg = 0.0;  // direction of increasing light, 0 = +x
  double blur_length_px = 0.0;   // linear motion blur, length in pixels
  double blur_angle_deg = 0.0;   // 0 = vertical, 90 = horizontal (the paper's convention)
  double noise_sigma = 0.0;      // Gaussian noise, grey levels
  std::uint64_t seed = 1;        // noise seed
};

// The truth about one marker in a rendered frame, in pixels of that frame.
struct MarkerTruth {
  Family family{3};
  TagId id;
  double tag_size = 0;
  cv::Vec3d rvec, tvec;
  std::vector<cv::Point2d> keypoints;  // K0..K3 (projected centres)
  std::vector<cv::Point2d> centers;    // all n^2 square centres, grid order
  // Area centroids of the projected squares, grid order: where an ideal detector's blob
  // centroids fall. They differ from `centers` by the perspective bias (up to ~0.1 px
  // for a 100 px marker tilted 40 degrees).
  std::vector<cv::Point2d> centroids;
  std::vector<cv::Point2d> corners;  // outer corners of the border, clockwise from top-left
  cv::Point2d center;                // the marker's centre
  bool fully_visible = false;        // in front of the camera and wholly inside the frame
  double edge_px = 0;                // mean projected edge of the black border, pixels
};
MarkerTruth make_truth(const Camera& camera, const SceneMarker& marker);

// Renders frames for one camera; keeps what depends only on the camera (the
// undistortion map), so rendering many frames of a video is cheap.
class SceneRenderer {
 public:
  explicit SceneRenderer(SceneParams params);
  const SceneParams& params() const { return params_; }
  // The same renderer over another background photo (params.photo): the pixel corners
  // traced back through the camera are shared, not traced again, so that the frames of
  // a video through a distorted lens cost what an undistorted one's do.
  SceneRenderer with_photo(cv::Mat photo) const;
  // Targets are drawn far to near. `seed` replaces params.seed for the noise when non-zero.
  cv::Mat1b render(const std::vector<SceneTarget>& targets, std::uint64_t seed = 0) const;
  // The same without quantisation to 8 bits and without noise: grey levels 0..255.
  cv::Mat1f render_linear(const std::vector<SceneTarget>& targets) const;
  // The last step of render(): adds the noise (seeded as render() is) and rounds to 8 bits.
  // render(t, s) == quantize(render_linear(t), s); frames averaged from several linear
  // renders (sub-frame motion blur) go through it once.
  cv::Mat1b quantize(const cv::Mat1f& linear, std::uint64_t seed = 0) const;

 private:
  void fit_background();  // background_ from params_.photo or params_.background

  SceneParams params_;
  cv::Mat2f corner_rays_;  // normalised image coordinates at the pixel corners
  cv::Mat1f background_;   // albedo per pixel
  cv::Mat1f light_;        // exposure * illumination per pixel
};

// One-shot rendering of markers, with their truths.
struct RenderedScene {
  cv::Mat1b image;
  std::vector<MarkerTruth> truth;
};
RenderedScene render_scene(const SceneParams& params, const std::vector<SceneMarker>& markers);

// A normalised linear motion-blur kernel (anti-aliased line of `length_px`).
cv::Mat1f motion_blur_kernel(double length_px, double angle_deg);

}  // namespace lftag
