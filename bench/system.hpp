// SPDX-License-Identifier: LGPL-2.1-or-later
// What the benchmarks need from a fiducial system: draw its markers, detect them, name it.
// Every system (AprilTag, ArUco, LFTag) sits behind this one interface, so every
// experiment treats them alike and renders their markers with the same policy.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/camera.hpp"
#include "lftag/render.hpp"

namespace bench {

struct Pose {
  cv::Vec3d rvec, tvec;  // marker frame (SPEC 2: centre, x right, y down, z in) -> camera, metres
};

struct Detected {
  std::string id;                   // decimal, exact
  std::vector<cv::Point2d> points;  // what the system localises: quad corners or key points
  cv::Point2d center;               // the marker centre in the image
  std::optional<Pose> pose;
  // The planar pose's other solution, and its reprojection error over the chosen one's
  // (NaN when the system gives none).
  std::optional<Pose> alternative;
  double ambiguity_ratio = std::numeric_limits<double>::quiet_NaN();
  // The system's own measure of how sure the id is (LFTag: Detection::noise_margin;
  // AprilTag: decision_margin), and which of its paths read it; NaN and empty when none.
  double confidence = std::numeric_limits<double>::quiet_NaN();
  std::string path;
};

// White margin around every system's marker, as a fraction of the tag size (two cells of
// AprilTag 36h11). Not less: with the one-cell quiet zone of AprilTag's own images, on a
// grey background, ArUco's default minMarkerDistanceRate merges the outlines of border
// and margin and misses about half of its markers at 2 m.
constexpr double kMarginFraction = 1.0 / 4;
// Albedo of ink and paper, as lftag::SceneMarker's defaults.
constexpr float kInk = 0.05f, kPaper = 0.9f;

class FiducialSystem {
 public:
  virtual ~FiducialSystem() = default;

  // Unique, file-name safe, e.g. "apriltag-36h11-d2". Experiments select systems by it.
  virtual std::string name() const = 0;
  // The marker design, e.g. "tag36h11": systems that read the same design share it.
  virtual std::string family() const = 0;
  virtual std::string dictionary_size() const = 0;  // decimal, exact

  // The ids of `count` test markers. `seed` is for systems that draw them at random.
  virtual std::vector<std::string> marker_ids(int count, std::uint64_t seed) const = 0;
  // The design of marker `id` as a square grid of cells, 0 black and 255 white, whose
  // outer edge is the tag size (the outermost printed cells; no quiet zone).
  virtual cv::Mat1b marker_cells(const std::string& id) const = 0;

  // The camera that frames come from and the tag size poses are given for. Called before
  // detect() and whenever either changes.
  virtual void set_camera(const lftag::Camera& camera, double tag_size) = 0;
  virtual std::vector<Detected> detect(const cv::Mat1b& grey) = 0;

  // Named counters summed over detect() calls since reset_counters(): the hook for a
  // detector's own statistics (LFTag's DetectionStats funnel and stage times).
  virtual void reset_counters() {}
  virtual std::vector<std::pair<std::string, double>> counters() const { return {}; }

  // Marker `id` as a scene target with pose (rvec, tvec), drawn with the shared margin
  // and albedo policy above, so that no system gets a friendlier rendering.
  lftag::SceneTarget target(const std::string& id, double tag_size, const cv::Vec3d& rvec, const cv::Vec3d& tvec) const;
};

// The pose (and the other solution, with the ratio of their reprojection errors) of a
// square of edge `size` metres, centred on the marker centre, from its image corners
// `det.points`, clockwise from the marker's top-left, by OpenCV's IPPE for squares, which
// chooses the solution with the smaller reprojection error over the four corners. Leaves
// them unset when it fails.
void set_square_pose(Detected& det, double size, const lftag::Camera& camera);

// Where the diagonals of a quadrilateral (corners in order around it) cross: the image
// of the square's centre.
cv::Point2d quad_center(const std::vector<cv::Point2d>& corners);

}  // namespace bench
