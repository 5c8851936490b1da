// SPDX-License-Identifier: LGPL-2.1-or-later
// What a detection saw on its way: the per-stage counts and times (DetectionStats), and,
// on request, every candidate's and outline read's fate (DetectionTrace). Only for
// tuning, debug images (draw.hpp) and `lftag detect --why`: detector.hpp needs none of it
// to find markers, so it only declares these types.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "lftag/detector.hpp"
#include "lftag/family.hpp"
#include "lftag/tag_id.hpp"

namespace lftag {

// Outline reads a frame at most (each outline and family is one): the work bound of a
// frame full of marker-like clusters, where every read aligns a template. The reads it
// cuts are counted in DetectionStats::outline_reads_skipped.
constexpr int kMaxOutlineReads = 32;

// How many candidates each stage let through, and how long each stage took, for one
// frame or (with +=) many: the paper's false-positive funnel and timing tables.
struct DetectionStats {
  std::int64_t frames = 0;
  std::int64_t regions = 0;                // regions labelled (the frame's and the second looks')
  std::int64_t topology = 0;               // white regions with n^2..n^2+extra black children
  std::int64_t area = 0;                   // passed the area constraint
  std::int64_t geometry = 0;               // passed the geometry constraint
  std::int64_t angle = 0;                  // passed the angle constraint
  std::int64_t collinearity = 0;           // passed the collinearity constraint
  std::int64_t residual = 0;               // decoded within tau3 and the cell residual bound (a side none of
                                           // whose hypotheses match the squares' ink stops before)
  std::int64_t unambiguous = 0;            // no other id fitting within the decoding margin
  std::int64_t decoded = 0;                // the squares' ink matches the design: detections
  std::int64_t unlisted = 0;               // markers read as an id not in DetectorParams::ids: not reported
  std::int64_t bowed = 0;                  // of them, read on a bowed grid (a bent sheet) where the flat
                                           // grid left the id in doubt
  std::int64_t second_looks = 0;           // patches examined again (see DetectorParams::second_look)
  std::int64_t second_look_found = 0;      // detections made in them (outline readings included)
  std::int64_t outline_reads = 0;          // outlines aligned and read where a patch gave no candidate
  std::int64_t outline_found = 0;          // detections read from outlines
  std::int64_t outline_reads_skipped = 0;  // outline reads not made: kMaxOutlineReads was reached
  std::int64_t borders = 0;                // border proposals: black regions whose outline and grey levels
                                           // look like a marker's border, where no marker was found
  std::int64_t border_found = 0;           // detections read from them
  std::int64_t expected_reads = 0;         // expected markers (FrameHints) looked for where expected
  std::int64_t expected_found = 0;         // detections found so
  std::int64_t expected_measured = 0;      // of them, measured from the grey levels alone (no patch searched)
  std::int64_t skipped_by_budget = 0;      // candidates not decoded: DetectorParams::max_candidates was spent
  std::int64_t second_looks_skipped = 0;   // clusters not looked at again: max_second_looks or the budget
  std::int64_t past_deadline = 0;          // frames whose deadline (DetectorParams::deadline_ms) cut their second looks
  std::int64_t skipped_by_deadline = 0;    // second looks, their candidates and outline reads it cut (one under way
                                           // included; the second looks of a frame cut before they were sought are
                                           // not counted)
  double threshold_ms = 0;                 // binarisation
  double regions_ms = 0;                   // topological connected components
  double candidates_ms = 0;                // topological filtering and vertex estimation
  double keypoints_ms = 0;                 // key points and geometric filtering
  double hypotheses_ms = 0;                // 16 initial poses and their evaluation
  double decode_ms = 0;                    // decoding
  double pose_ms = 0;                      // final pose
  double borders_ms = 0;                   // proposing borders and reading them
  double second_look_ms = 0;               // finding, enlarging, binarising and labelling the patches
  double expected_ms = 0;                  // reading the expected markers (FrameHints)
  double total_ms() const;
  DetectionStats& operator+=(const DetectionStats& other);
};

// Where a topological candidate or an outline read stopped, in pipeline order.
enum class Stage {
  area,          // the area constraint (tau1)
  budget,        // not examined: the frame's candidate budget (max_candidates) or its
                 // outline reads were spent
  deadline,      // a second look's candidate not examined, or an outline read cut short: the frame's
                 // deadline had passed
  geometry,      // the geometry constraint, on every side of the hull
  angle,         // the angle constraint
  collinearity,  // the collinearity constraint (tau2)
  border,        // border proposal: the grey levels along the quadrilateral show no marker's border
  alignment,     // outline read: the marker's structure did not align from the outline
  structure,     // outline read: the aligned structure correlated under 0.75
  contrast,      // outline read: too little contrast between the white ring and the cells
  baselines,     // outline read: no two corners stand out as the baselines
  resolution,    // too few pixels per unit to read (min_pixels_per_unit)
  decoding,      // no reading within tau3 and the cell residual bound
  margin,        // another id fitted within the decoding margin, or a digit within the noise of another
  ink,           // the squares' ink did not match the design on any side
  marker,        // outline read: the whole marker of the id read fitted under 0.75
  unexpected,    // read where a marker was expected (FrameHints), as another id or family
  unlisted,      // read as an id not in DetectorParams::ids
  pose,          // no pose could be computed
  duplicate,     // a marker already found at its place
  detected,
};
const char* stage_name(Stage stage);  // "area", "budget", ..., "detected"

// One topological candidate and its fate (lftag detect --why prints these).
struct CandidateVerdict {
  Family family{3};
  bool second_look = false;            // found in an enlarged patch
  std::vector<cv::Point2d> centroids;  // its n^2 blobs, frame pixels
  Stage stage = Stage::detected;
  std::optional<TagId> reading;             // the best reading, when decoding ran
  double decode_error = 0, worst_cell = 0;  // of that reading
  double noise_margin = 0;                  // of that reading, once accepted
};

// One outline read (a marker whose squares a second look's binary image could not
// separate, or one expected there, read from the grey levels under its aligned outline)
// and its fate.
struct OutlineVerdict {
  Family family{3};
  bool expected = false;                 // a read where the caller expected a marker (FrameHints)
  bool border = false;                   // a read of a border proposal
  std::array<cv::Point2d, 4> outline{};  // the coarse outline read from, frame pixels
  Stage stage = Stage::detected;
  std::optional<TagId> reading;    // the id read, when reading ran
  double correlation = 0;          // of the aligned structure (of the start when one
                                   // far under the resolution bound was not aligned;
                                   // 0 when it did not align)
  double marker_correlation = 0;   // of the whole marker of the id read
  double contrast = 0;             // white ring minus the cells' cores, grey levels
                                   // (under a defocus: as the template's blur shows it)
  double margin = 0;               // how much worse each cell's runner-up fits (least)
  double noise_margin = 0;         // the same in standard deviations of the noise
  double listed_noise_margin = 0;  // with DetectorParams::ids_complete: noise margin and evidence
  double listed_evidence = 0;      // against the nearest other listed ids (0: the id read is not listed)
  double evidence = 0;             // least share of each cell's predicted difference
                                   // to its other positions that the image shows
  double model_ink = 0;            // the ink the pixel model fits, over `contrast`
  double pixels_per_unit = 0;      // along the most foreshortened direction
  double smear = 0;                // length of the motion blur found, units
  double defocus = 0;              // Gaussian defocus found, units (sigma)
};

// One black region whose convex hull is a quadrilateral, and what its grey levels say of
// a marker's border there (for the family it is clearest for): `border` when they refused
// it, else the furthest stage its outline reads reached.
struct BorderVerdict {
  std::array<cv::Point2d, 4> outline{};  // frame pixels, clockwise on screen
  Family family{3};
  Stage stage = Stage::border;
  double contrast = 0;   // the margin's grey level minus the border's
  double noise = 0;      // their samples' standard deviation
  double ring = 0;       // the white ring's level, from the border's (0) to the margin's (1)
  int darker_sides = 0;  // sides whose border is darker than their margin
  double structure = 0;  // ring and lines between cells above the cores, over the contrast
};

// What the stages saw, for debug images (see draw.hpp) and for tuning: filled only on request.
struct DetectionTrace {
  cv::Mat binary;                                                 // 255 = black, as thresholded
  double noise = 0;                                               // the frame's pixel noise (grey levels)
  std::vector<std::vector<cv::Point2d>> candidates;               // blob centroids of every topological candidate
  std::vector<std::array<cv::Point2d, 4>> keypoints;              // K0..K3 of candidates that passed the constraints
  std::vector<std::vector<std::vector<cv::Point2d>>> hypotheses;  // per candidate: 16 projected inner edges
  std::vector<Detection> detections;
  std::vector<CandidateVerdict> verdicts;     // every topological candidate
  std::vector<OutlineVerdict> outline_reads;  // every outline read (and skipped)
  std::vector<BorderVerdict> borders;         // every quadrilateral black region and its fate
  std::vector<cv::Rect> second_looks;         // the clusters looked at again
};

}  // namespace lftag
