// SPDX-License-Identifier: LGPL-2.1-or-later
// The LFTag detector: finds, decodes and localises markers in a grey image.
//
//   lftag::Detector detector;                       // 3x3 and 4x4, the defaults below
//   for (const lftag::Detection& d : detector.detect(lftag::ImageView(grey)))
//     std::cout << d.family.name() << " " << d.id.to_decimal() << "\n";
//
// Threads: a Detector keeps its working buffers from frame to frame and detect() writes
// them, so one Detector must never be used from two threads at once without external
// locking (a mutex around every detect() call). Use one Detector per thread: building one
// is cheap, and different Detectors share no mutable state, so they may detect at the same
// time (tests/lib/test_threads.cpp checks this under ThreadSanitizer).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/camera.hpp"
#include "lftag/family.hpp"

namespace lftag {

// A read-only view of 8-bit grey pixels (such as the luma plane of a video frame):
// nothing is copied.
struct ImageView {
  const std::uint8_t* data = nullptr;
  int width = 0;
  int height = 0;
  std::ptrdiff_t stride = 0;  // bytes from one row to the next

  ImageView() = default;
  ImageView(const std::uint8_t* data, int width, int height, std::ptrdiff_t stride);
  // A CV_8UC1 matrix; throws std::invalid_argument for any other type.
  explicit ImageView(const cv::Mat& grey);
  cv::Mat mat() const;  // a header over the same pixels
  bool empty() const { return width <= 0 || height <= 0; }
};

// The grey level that weighs zero when blob centroids are taken from the inverted image.
enum class CentroidReference {
  local_white,  // the upper quartile of the marker's white region: the paper's inversion, but
                // white paper around a blob weighs nothing, which keeps small blobs' centroids
                // from snapping to the pixel grid
  full_scale,   // 255, the paper's plain inversion
};

struct DetectorParams {
  // Families searched in one pass (they share the threshold and the region tree).
  std::vector<Family> families{Family(3), Family(4)};
  // The ids in use (empty, the default: every id of the families). A marker read as
  // another id is not reported (DetectionStats::unlisted counts it; lftag detect --why
  // shows it as "unlisted"), and its place is not read again in the frame: a print of
  // someone else's marker, or a misreading that lands outside the ids printed, never
  // reaches the caller. Each id must be an id of at least one of the families.
  std::vector<TagId> ids;
  // The ids listed are every marker that may be in view (a closed set, as a square-marker
  // system's dictionary is). A reading from the grey levels (an outline reading) that its
  // margins against every id one square off refuse is then judged against the nearest
  // other listed id instead, which differs in several squares: it passes when that id
  // fits kMinListedNoiseMargin standard deviations worse. A marker in view whose id is not
  // listed may then be read as a listed neighbour: list every id printed. Needs `ids`.
  bool ids_complete = false;

  // -- Binarisation: a pixel is black when darker than the mean of the M x M window
  //    around it by more than `threshold_offset` grey levels. The paper uses the plain
  //    mean (offset 0); 4 levels keep the sensor noise of flat areas out of the binary
  //    image (20 % fewer runs on photos, the labelling 30 % faster) and detected as well
  //    as 0 in every range, blur, noise and low-light test.
  int threshold_window = 16;  // M (paper: 16)
  int threshold_offset = 4;   // grey levels

  // -- Second look, where no marker was found: black regions whose outline and grey
  //    levels look like a marker's border (touching squares, a shadow across the marker),
  //    and small, isolated clusters of black regions (markers at about half a pixel per
  //    unit, whose gaps the frame's binary image closes), each enlarged if small,
  //    binarised at the midpoint of its own dark and bright levels and taken through the
  //    same stages, then read from its outline's grey levels; everything is measured in
  //    the frame.
  bool second_look = true;
  int max_second_looks = 64;  // patches per frame at most, the work bound of a cluttered frame

  // -- Per-frame budget: at most this many topological candidates (white regions with
  //    n^2 black children, in the frame and in its second looks together) are measured
  //    and decoded; the rest are skipped and counted (DetectionStats::skipped_by_budget),
  //    and once the budget is spent no further second look is taken. When a frame holds
  //    more candidates than the budget left, the most plausible go first: the first
  //    candidate of every enclosing black region (a marker's border holds one white
  //    interior, the grout of a tiled wall thousands), fewest siblings first, before the
  //    second of any region. Ordinary frames make a handful of candidates (photos: under
  //    one a frame); a grid of dotted tiles makes thousands. 0: no limit.
  int max_candidates = 128;

  // -- Per-frame deadline: milliseconds of the calling thread's processor time from the
  //    start of detect(). Once they are spent, the frame's optional work is skipped and
  //    counted (DetectionStats::past_deadline, skipped_by_deadline): the second looks not
  //    yet taken, the candidates and outline reads of the one under way, and the rest of an
  //    outline read under way. The frame's own candidates are always examined (the budget
  //    bounds them), so every sharp marker is found however slow the machine. It bounds
  //    what a frame of look-alikes or sensor noise costs in milliseconds, where the counts
  //    above bound it only in work;
  //    processor time rather than wall-clock time, so that other programs on the machine
  //    do not cut a frame (a stream that falls behind is GStreamer's QoS's to handle).
  //    0: none, so that a detection does all its work and gives the same result on any
  //    machine; the GStreamer element and the command line default to kLiveDeadlineMs.
  double deadline_ms = 0;

  // -- Candidates: a white region with at least n^2 black children. Children smaller than
  //    `min_child_fraction` of the white region's area, or than the largest child over
  //    `max_child_ratio`, are noise; at most n^2 + max_extra_children children remain, of
  //    which the n^2 largest are kept. The largest square is 16/9 of the smallest by
  //    design and up to about 14 times under the steepest perspective we decode (80
  //    degrees at 1.5 tag sizes from the camera).
  double min_child_fraction = 1.0 / 500;
  double max_child_ratio = 40;
  int max_extra_children = 3;

  // -- Vertex estimation: centroids of the inverted grey image over each black region
  //    and the white pixels within `dilation` pixels of it (a Euclidean radius, where the
  //    paper dilates by an L-infinity square; see BlobMeasurer).
  int dilation = 1;  // delta (paper: 1)
  CentroidReference centroid_reference = CentroidReference::local_white;

  // -- Constraints.
  // tau1: largest / smallest blob ink (design ratio 16/9), once the perspective's
  // growth of area across the marker is taken out (a plane fitted to the cube roots).
  double max_ink_ratio = 5.0;
  // tau2, scale-free: reject near-collinear blobs whose centroid scatter has a smaller
  // to larger principal axis ratio (sqrt of the eigenvalue ratio) below this.
  double min_spread_ratio = 0.1;

  // -- Decoding: reject when the decoding error metric exceeds tau3 for the family.
  //    0 selects the default of decode_threshold_default().
  std::array<double, Family::kMaxN + 1> max_decode_error{};
  // The paper's metric shrinks with the marker's size, so far markers need a scale-free
  // bound too: every data centroid within this many units of its decoded position (the
  // four positions are 1 u apart, so 0.5 would be a coin toss).
  double max_cell_residual = 0.35;
  // Markers smaller than this many pixels per unit along their most foreshortened
  // direction are not read (a 3x3 under 10.3 px across face-on): at 0.42 a wrong id was
  // read in the range sweep.
  double min_pixels_per_unit = 0.43;
  // Reject a reading when a hypothesis giving another id has a decoding error within this
  // factor of the best one's: at the limit of resolution two ids can fit nearly as well.
  double min_decode_margin = 2.0;
  // A reading of 3x3 and larger by its blobs must have its least certain data cell this
  // many standard deviations of the blobs' scatter from reading as another digit
  // (Detection::noise_margin): every digit pattern is an id, so a guessed cell is a wrong
  // id. In the field experiment (docs/BENCHMARKS.md) the wrong ids of flat markers read
  // by their blobs had 1.2 to 2.0, and 0.6 % of the right readings were under 2. From 4x4
  // the same margin is kept from each reading that moves a band of rows or columns one
  // unit, under a grid free to bow (a bent sheet's 4x4 was read so, at 3.4 on its
  // digits; under the bow 0). Outline
  // readings report their noise margin but are not held to it: there the residual is
  // mostly the model's misfit, and right readings of blurred markers have 0.7 to 1.4.
  double min_noise_margin = 2.0;
  // The squares' ink per unit of design area, largest over smallest, under the decoded
  // homography: at most 1.24 for true markers in our renders, from 3 m to the range limit,
  // tilted or blurred; 16/9 when one square has the wrong size, and about 2 to 3 when the
  // baseline is taken on a wrong side (a data square in a baseline's place and the other
  // way round). This settles the turn.
  double max_ink_spread = 1.5;

  // -- Pose.
  // Intrinsics and distortion, scaled to the frame by Camera::for_frame. None (the
  // default) selects Camera::default_for(frame): decoding is unaffected; poses are then
  // marked uncalibrated. A camera given here must pass Camera::validate().
  std::optional<Camera> camera;
  double tag_size = 0.1;  // metres, outer edge of the black border
  // Iterative refinement of the final pose on all n^2 centroids and the border's stroke.
  bool refine_pose = true;
  // The planar pose's two solutions (see Detection::ambiguity_ratio) are told apart by how
  // well they fit the n^2 centroids, and, when the other fits within this factor of the
  // best, by the squares' foreshortening instead: the side of the marker nearer the camera
  // images larger, so each solution predicts each square's ink (area grows as depth^-3),
  // and the one whose prediction fits the measured inks best is chosen. 0: by the
  // centroids alone. Markers read from their outline have no measured inks. Chosen on the
  // ambiguity experiment's tuning set (docs/BENCHMARKS.md): wrong choices of 3x3 and 4x4
  // 123 -> 106, and on its validation set 129 -> 111; from 1.05 up the inks, whose
  // foreshortening is a few per cent on a small marker, choose worse than the centroids.
  double shape_choice_ratio = 1.03;

  // The tau3 in force for `family`.
  double decode_threshold(const Family& family) const;
  // Throws std::invalid_argument naming the first parameter out of range.
  void validate() const;

  // Every field (a new field must join the comparison in detector.cpp).
  friend bool operator==(const DetectorParams& a, const DetectorParams& b);
  friend bool operator!=(const DetectorParams& a, const DetectorParams& b) { return !(a == b); }
};

// The deadline of the element and the command line (DetectorParams::deadline_ms): a 720p
// frame's fixed work (binarisation, labelling, its own candidates) takes 1 to 3 ms in
// ordinary frames, and the step under way when the deadline passes up to about 13 ms more
// (with 25 ms the adversarial experiment's look-alike and torn frames took up to 36 to
// 42 ms on a quiet machine), so that a frame stays within the 33 ms of 30 fps.
constexpr double kLiveDeadlineMs = 20;

// tau3 defaults: the paper's 5e-4 (3x3) and 1e-3 (4x4), and calibrated values for the others.
double decode_threshold_default(const Family& family);

struct Detection {
  Family family{3};
  TagId id;
  // The n^2 squares' centroids the pose was computed from, grid order (image pixels): each
  // square's ink over its window under the decoded homography, or the blob's centroid
  // for a marker under 1.25 pixels per unit or by the frame's edge.
  std::vector<cv::Point2d> centroids;
  std::array<cv::Point2d, 4> keypoints;  // K0..K3 (image pixels)
  std::array<cv::Point2d, 4> corners;    // outer border corners from the pose, clockwise from top-left
  cv::Point2d center;                    // marker centre from the pose (image pixels)
  cv::Vec3d rvec, tvec;                  // marker frame -> camera frame, metres (SPEC 2)
  double tag_size = 0;                   // the size the pose assumes
  bool calibrated = false;               // pose from a real calibration, not the default camera
  double decode_error = 0;               // the decoding error metric (lower is better; <= tau3)
  double worst_cell = 0;                 // largest centroid offset from its decoded position, units
  double ink_spread = 0;                 // ink per design area, largest / smallest square
  double edge_score = 0;                 // mean Sobel magnitude along the inner border edge
  // RMS over the n^2 centroids of the chosen solution fitted to them, pixels (rvec/tvec
  // are then refined on the border's stroke as well, where the two agree).
  double reprojection_error = 0;
  // How sure the id is: how many standard deviations of the noise measured on this marker
  // its least certain data cell stands from reading as another digit (every digit pattern
  // is an id, so one cell read wrong is another marker's id). From the blobs' scatter about
  // the fitted grid (at least DetectorParams::min_noise_margin; from 4x4 also each band of
  // rows or columns from its one-unit shift, under a grid free to bow), or for an outline reading
  // the grey levels' residual about the fitted marker, correlated between neighbours as
  // it is (that residual is mostly misfit: right readings of blurred markers show 0.7 to
  // 1.4). 0 for 2x2 (its four blobs fit exactly; its grey levels decide).
  double noise_margin = 0;
  // The planar pose has two solutions (IPPE finds both), each refined on the n^2 centroids:
  // the one that fits them best is rvec/tvec, the other is here. A small marker seen
  // nearly face on fits its flip (the marker tilted the other way) almost as well.
  cv::Vec3d alternative_rvec, alternative_tvec;
  double alternative_reprojection_error = 0;  // RMS of the other solution, pixels
  // alternative_reprojection_error / reprojection_error: how much worse the other pose
  // fits. Near 1 the pose is ambiguous (the chosen one may be the flip, and the z axis may
  // jump between frames); from about 3 it is settled. 0 when there was no other solution.
  double ambiguity_ratio = 0;
  // Read from the grey levels under its outline (a far or blurred marker whose squares no
  // binary image separated; see DetectorParams::second_look): decode_error, worst_cell and
  // ink_spread are then 0, and the centroids are the squares' centres under the aligned
  // outline.
  bool from_outline = false;
};

// A marker the caller expects in a frame, and where: a track's prediction
// (Tracker::expected). It is read from the grey levels under that outline, as a far or
// blurred marker is (Detection::from_outline), and taken only with the id expected.
struct ExpectedMarker {
  Family family{3};
  TagId id;
  std::array<cv::Point2d, 4> corners;  // outer border corners, clockwise on screen, frame pixels
};

// What the caller knows of a frame before it is searched.
struct FrameHints {
  // Looked for where expected once the frame's own candidates are decoded, unless the
  // search found them already: a marker that a motion blur or a shake keeps from being
  // found by its squares is still read where its track puts it.
  std::vector<ExpectedMarker> expected;
  // Search the whole frame (the topological path and the second look). False: only read
  // the expected markers, which costs a small fraction of a search; new markers are then
  // not found, so a caller searches in full every few frames (lftagdetect's
  // full-detection-interval).
  bool full_search = true;
};

// Per-stage counts and times, and what the stages saw: lftag/trace.hpp.
struct DetectionStats;
struct DetectionTrace;

class Detector {
 public:
  // Throws std::invalid_argument when a parameter is out of range.
  explicit Detector(DetectorParams params = {});
  ~Detector();
  Detector(Detector&&) noexcept;
  Detector& operator=(Detector&&) noexcept;

  const DetectorParams& params() const;

  // Detects markers. Throws std::invalid_argument for an empty (0 x 0) image, a null
  // pointer or a stride shorter than the width, and for a frame the camera's calibration
  // cannot be scaled to (Camera::for_frame). When not null, `stats` has this frame's
  // counts and times added to it (so one DetectionStats sums many frames) and `trace` is
  // replaced by this frame's.
  // Not thread-safe on one Detector (see the top of this file); `image` is only read.
  std::vector<Detection> detect(const ImageView& image, DetectionStats* stats = nullptr,
                                DetectionTrace* trace = nullptr);
  // The same, with what the caller knows of the frame (expected markers of families not
  // in params().families are not looked for).
  std::vector<Detection> detect(const ImageView& image, const FrameHints& hints, DetectionStats* stats = nullptr,
                                DetectionTrace* trace = nullptr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lftag
