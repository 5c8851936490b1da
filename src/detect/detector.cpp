// SPDX-License-Identifier: LGPL-2.1-or-later
// The chain of stages, with timing and the false-positive funnel.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <tuple>

#include <time.h>

#include <opencv2/imgproc.hpp>

#include "../core/geometry.hpp"
#include "stages.hpp"

namespace lftag {

using Clock = std::chrono::steady_clock;
using detail::elapsed_ms;

ImageView::ImageView(const std::uint8_t* d, int w, int h, std::ptrdiff_t s) : data(d), width(w), height(h), stride(s) {}

ImageView::ImageView(const cv::Mat& grey) {
  if (grey.type() != CV_8UC1 && !grey.empty())
    throw std::invalid_argument("the detector needs an 8-bit, one-channel (grey) image");
  data = grey.data, width = grey.cols, height = grey.rows, stride = std::ptrdiff_t(grey.step);
}

cv::Mat ImageView::mat() const {
  if (empty()) return {};
  return cv::Mat(height, width, CV_8UC1, const_cast<std::uint8_t*>(data), std::size_t(stride));
}

double decode_threshold_default(const Family& family) {
  switch (family.n()) {
    case 2: return 0.0;   // misordered black/white sample pairs (see decode.cpp): none
    case 3: return 5e-4;  // the paper
    case 4: return 1e-3;  // the paper
    default: return 1e-3 * family.data_cell_count() / 14.0;  // the paper's per-cell value, scaled
  }
}

double DetectorParams::decode_threshold(const Family& family) const {
  const double t = max_decode_error[family.n()];
  return t > 0 ? t : decode_threshold_default(family);
}

void DetectorParams::validate() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  if (families.empty()) fail("no marker family to detect");
  if (threshold_window < 2 || threshold_window > 1024) fail("threshold window must be 2 to 1024 pixels");
  if (threshold_offset < 0 || threshold_offset > 255) fail("threshold offset must be 0 to 255");
  if (!(min_child_fraction >= 0 && min_child_fraction < 1)) fail("the minimum child fraction must be in [0, 1)");
  if (!(max_child_ratio >= 1)) fail("the maximum child ratio must be at least 1");
  if (max_second_looks < 0) fail("the number of second looks must not be negative");
  if (max_candidates < 0) fail("the candidate budget must not be negative (0: no limit)");
  if (!(deadline_ms >= 0 && deadline_ms <= 1e7)) fail("the deadline must be 0 (none) to 10,000,000 ms");
  if (max_extra_children < 0 || max_extra_children > 64) fail("extra children must be 0 to 64");
  if (dilation < 0 || dilation > 8) fail("dilation must be 0 to 8 pixels");
  if (!(max_ink_ratio >= 1)) fail("the ink ratio (tau1) must be at least 1");
  if (!(min_spread_ratio >= 0 && min_spread_ratio <= 1)) fail("the spread ratio (tau2) must be in [0, 1]");
  if (!(max_cell_residual > 0 && max_cell_residual <= 1)) fail("the cell residual bound must be in (0, 1] units");
  if (!(max_ink_spread >= 1)) fail("the ink spread bound must be at least 1");
  if (!(min_decode_margin >= 1)) fail("the decoding margin must be at least 1");
  if (!(min_noise_margin >= 0)) fail("the noise margin must be at least 0");
  if (!(min_pixels_per_unit >= 0 && min_pixels_per_unit < 100)) fail("the minimum pixels per unit must be in [0, 100)");
  for (double t : max_decode_error)
    if (!(t >= 0) || !std::isfinite(t)) fail("decode error thresholds (tau3) must be finite and not negative");
  if (!(tag_size > 0) || !std::isfinite(tag_size)) fail("the tag size must be positive");
  if (!(shape_choice_ratio >= 0)) fail("the shape choice ratio must be at least 0 (0: by the centroids alone)");
  if (camera) camera->validate();
  if (ids_complete && ids.empty()) fail("ids_complete (ids-complete) needs the ids in use (ids), and none are listed");
  for (const TagId& id : ids)
    if (std::none_of(families.begin(), families.end(), [&](const Family& f) { return f.contains(id); }))
      fail("id " + id.to_decimal() + " is not an id of any family detected (the largest is " +
           std::max_element(families.begin(), families.end(),
                            [](const Family& a, const Family& b) { return a.n() < b.n(); })
               ->max_id()
               .to_decimal() +
           ")");
}

namespace {
auto fields(const DetectorParams& p) {
  return std::tie(p.families, p.ids, p.ids_complete, p.threshold_window, p.threshold_offset, p.second_look,
                  p.max_second_looks, p.max_candidates, p.deadline_ms, p.min_child_fraction, p.max_child_ratio,
                  p.max_extra_children, p.dilation, p.centroid_reference, p.max_ink_ratio, p.min_spread_ratio,
                  p.max_decode_error, p.max_cell_residual, p.min_pixels_per_unit, p.min_decode_margin,
                  p.min_noise_margin, p.max_ink_spread, p.camera, p.tag_size, p.refine_pose, p.shape_choice_ratio);
}
}  // namespace

bool operator==(const DetectorParams& a, const DetectorParams& b) { return fields(a) == fields(b); }

double DetectionStats::total_ms() const {
  return threshold_ms + regions_ms + candidates_ms + keypoints_ms + hypotheses_ms + decode_ms + pose_ms + borders_ms +
         second_look_ms + expected_ms;
}

DetectionStats& DetectionStats::operator+=(const DetectionStats& o) {
  frames += o.frames, regions += o.regions, topology += o.topology, area += o.area, geometry += o.geometry;
  angle += o.angle, collinearity += o.collinearity, residual += o.residual, unambiguous += o.unambiguous;
  decoded += o.decoded, unlisted += o.unlisted, bowed += o.bowed, second_looks += o.second_looks,
      second_look_found += o.second_look_found;
  outline_reads += o.outline_reads, outline_found += o.outline_found, outline_reads_skipped += o.outline_reads_skipped;
  expected_reads += o.expected_reads, expected_found += o.expected_found, expected_measured += o.expected_measured;
  borders += o.borders, border_found += o.border_found, borders_ms += o.borders_ms;
  skipped_by_budget += o.skipped_by_budget, second_looks_skipped += o.second_looks_skipped;
  past_deadline += o.past_deadline, skipped_by_deadline += o.skipped_by_deadline;
  second_look_ms += o.second_look_ms, expected_ms += o.expected_ms;
  threshold_ms += o.threshold_ms, regions_ms += o.regions_ms, candidates_ms += o.candidates_ms;
  keypoints_ms += o.keypoints_ms, hypotheses_ms += o.hypotheses_ms, decode_ms += o.decode_ms, pose_ms += o.pose_ms;
  return *this;
}

double detail::Deadline::thread_time() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

namespace {

CandidateVerdict verdict_of(const detail::Candidate& c, bool second_look, Stage stage) {
  CandidateVerdict v;
  v.family = c.family;
  v.second_look = second_look;
  v.stage = stage;
  for (const detail::Blob& b : c.blobs) v.centroids.push_back(b.centroid);
  return v;
}

// Whether point q lies inside (or on) the outline of a detection already made.
bool already_found(const std::vector<Detection>& found, cv::Point2d q) {
  return std::any_of(found.begin(), found.end(), [&](const Detection& f) {
    const std::vector<cv::Point2f> outline(f.corners.begin(), f.corners.end());
    return cv::pointPolygonTest(outline, cv::Point2f(q), false) >= 0;
  });
}

// The detection of a decoded candidate, posed from each square's ink over its window
// under the decoding's homography, unbiased by defocus (cell_centroids.cpp; the blobs'
// centroids for a marker under 1.25 px per unit or by the frame's edge) and from the
// border's stroke. `centroids_final`: the candidate's blobs are those windows' centroids
// already (a tracked marker's, tracked.cpp). None when no pose could be computed.
std::optional<Detection> pose_decoded(const detail::Candidate& c, const detail::Decoding& d, const detail::KeyPoints& k,
                                      const ImageView& work, const Camera& camera, const DetectorParams& p,
                                      const detail::BorderEdges& edges, bool centroids_final = false) {
  Detection det;
  det.family = c.family;
  det.id = d.id;
  det.decode_error = d.error;
  det.worst_cell = d.worst_cell;
  det.noise_margin = d.noise_margin;
  det.ink_spread = d.ink_spread;
  det.edge_score = d.edge_score;
  detail::Candidate for_pose = c;
  const std::vector<cv::Point2d> cells =
      centroids_final ? std::vector<cv::Point2d>{}
                      : detail::cell_centroids(work, camera, c.family, d.id, d.homography, c.paper);
  if (!cells.empty()) {
    const std::vector<cv::Point2d> ideal = camera.undistort(cells);
    for (int g = 0; g < c.family.cell_count(); ++g) {
      detail::Blob& b = for_pose.blobs[d.blob_of_cell[g]];
      b.centroid = cells[g], b.point = ideal[g];
    }
  }
  for (int g = 0; g < c.family.cell_count(); ++g) det.centroids.push_back(for_pose.blobs[d.blob_of_cell[g]].centroid);
  for (int i = 0; i < 4; ++i) det.keypoints[i] = for_pose.blobs[k.blob[i]].centroid;
  if (!detail::estimate_pose(for_pose, d, camera, p, det, edges)) return std::nullopt;
  return det;
}

// Key points, decoding and pose of every candidate, most plausible first, until the
// deadline (a second look's; none for the frame's own); detections are appended to `found`, except where a detection
// already stands (a second look can overlap one).
void decode_candidates(const std::vector<detail::Candidate>& candidates, const ImageView& work, const Camera& camera,
                       const DetectorParams& p, bool second_look, const detail::Deadline& deadline,
                       DetectionStats& stats, DetectionTrace* trace, std::vector<Detection>& found) {
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const detail::Candidate& c = candidates[i];
    if (deadline.passed()) {
      stats.skipped_by_deadline += std::int64_t(candidates.size() - i);
      if (trace)
        for (; i < candidates.size(); ++i)
          trace->verdicts.push_back(verdict_of(candidates[i], second_look, Stage::deadline));
      return;
    }
    if (trace) {
      std::vector<cv::Point2d> centroids;
      for (const detail::Blob& b : c.blobs) centroids.push_back(b.centroid);
      trace->candidates.push_back(centroids);
    }
    auto start = Clock::now();
    DetectionStats constraints;  // which of the paper's constraints some side passed
    std::vector<detail::KeyPoints> sides = detail::find_keypoints(c, p, constraints);
    stats += constraints;
    // The side whose K0 and K1 carry the most ink (perspective taken out) is most likely
    // the baseline: decoding it first usually spares the other three.
    const auto baseline_ink = [&](const detail::KeyPoints& k) {
      return c.blobs[k.blob[0]].relative_ink + c.blobs[k.blob[1]].relative_ink;
    };
    std::stable_sort(sides.begin(), sides.end(), [&](const detail::KeyPoints& a, const detail::KeyPoints& b) {
      return baseline_ink(a) > baseline_ink(b);
    });
    stats.keypoints_ms += elapsed_ms(start);
    // The first decoding of a hull side whose squares' ink matches the design: a wrong side
    // puts squares of the wrong size in the baseline's and data cells' places (spread 2 to
    // 3), so no two sides pass.
    std::optional<detail::KeyPoints> k;
    std::optional<detail::Decoding> d, best;  // accepted; the best reading of any side (for the trace)
    std::array<bool, 2> passed{};             // residual, margin: for any side
    for (const detail::KeyPoints& side : sides) {
      if (trace) {
        std::array<cv::Point2d, 4> points;
        for (int i = 0; i < 4; ++i) points[i] = c.blobs[side.blob[i]].centroid;
        trace->keypoints.push_back(points);
        trace->hypotheses.emplace_back();
      }
      auto decoded = detail::decode(c, side, work, camera, p, stats, trace ? &trace->hypotheses.back() : nullptr);
      if (!decoded) continue;
      passed[0] |= decoded->verdict >= detail::Verdict::margin;
      passed[1] |= decoded->verdict == detail::Verdict::accepted;
      if (!best || int(decoded->verdict) > int(best->verdict)) best = decoded;
      if (decoded->verdict == detail::Verdict::accepted && decoded->ink_spread <= p.max_ink_spread) {
        d = decoded;
        k = side;
        break;
      }
    }
    stats.residual += passed[0], stats.unambiguous += passed[1];
    if (trace) {
      // Where the candidate stopped: the last of the paper's constraints that no side
      // passed, or the furthest any side's decoding got.
      Stage stage = Stage::detected;
      if (!constraints.geometry)
        stage = Stage::geometry;
      else if (!constraints.angle)
        stage = Stage::angle;
      else if (!constraints.collinearity)
        stage = Stage::collinearity;
      else if (!best)
        stage = Stage::decoding;
      else if (!d)
        stage = passed[1]                                      ? Stage::ink
                : passed[0]                                    ? Stage::margin
                : best->verdict == detail::Verdict::ink        ? Stage::ink
                : best->verdict == detail::Verdict::resolution ? Stage::resolution
                                                               : Stage::decoding;
      CandidateVerdict v = verdict_of(c, second_look, stage);
      if (best)
        v.reading = best->id, v.decode_error = best->error, v.worst_cell = best->worst_cell,
        v.noise_margin = best->noise_margin;
      trace->verdicts.push_back(std::move(v));
    }
    if (!d) continue;
    ++stats.decoded;

    start = Clock::now();
    std::optional<Detection> det = pose_decoded(
        c, *d, *k, work, camera, p, detail::border_edges(work, camera, c.family, d->homography, p.tag_size));
    stats.pose_ms += elapsed_ms(start);
    const Stage outcome = !det ? Stage::pose : already_found(found, det->center) ? Stage::duplicate : Stage::detected;
    if (trace) trace->verdicts.back().stage = outcome;
    if (outcome != Stage::detected) continue;
    found.push_back(std::move(*det));
  }
}

// The detection of an accepted outline reading: posed from the squares' centres under
// the aligned outline, which is where the pose's perspective correction expects a blob's
// centroid. None when no pose could be computed.
std::optional<Detection> pose_outline(const detail::OutlineReading& reading, const Family& f, const Camera& camera,
                                      const DetectorParams& p) {
  detail::Candidate c;
  c.family = f;
  detail::Decoding d;
  d.id = reading.id;
  d.homography = reading.homography;
  std::vector<cv::Point2d> observed;
  for (int g = 0; g < f.cell_count(); ++g) {
    const UnitRect s = f.square(g, f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g)));
    std::vector<cv::Point2d> square = {
        {s.x, s.y}, {s.x + s.width, s.y}, {s.x + s.width, s.y + s.height}, {s.x, s.y + s.height}};
    cv::perspectiveTransform(square, square, reading.homography);
    observed.push_back(detail::polygon_centroid(square));
    d.blob_of_cell.push_back(g);
  }
  const std::vector<cv::Point2d> ideal = camera.undistort(observed);
  for (int g = 0; g < f.cell_count(); ++g) {
    detail::Blob b;
    b.centroid = observed[g], b.point = ideal[g];
    c.blobs.push_back(b);
  }
  Detection det;
  det.family = f;
  det.id = d.id;
  det.centroids = observed;
  det.from_outline = true;
  det.noise_margin = reading.noise_margin;
  const std::array<int, 4> keypoint_cells = f.keypoint_cells();
  for (int i = 0; i < 4; ++i) det.keypoints[i] = observed[keypoint_cells[i]];
  if (!detail::estimate_pose(c, d, camera, p, det)) return std::nullopt;
  return det;
}

// An accepted outline reading of family `f` posed and added to `found`, unless no pose
// could be computed or a detection stands at its place already (the verdict then says
// which); its place is recorded in `read_places`.
bool add_outline_detection(const detail::OutlineReading& reading, const Family& f, const Camera& camera,
                           const DetectorParams& p, std::vector<Detection>& found, detail::ReadPlaces& read_places,
                           OutlineVerdict* verdict) {
  std::optional<Detection> det = pose_outline(reading, f, camera, p);
  const Stage stage = !det ? Stage::pose : already_found(found, det->center) ? Stage::duplicate : Stage::detected;
  if (verdict) verdict->stage = stage;
  if (stage != Stage::detected) return false;
  read_places.add(f.n(), reading.homography, f, reading.pixels_per_unit);
  found.push_back(std::move(*det));
  return true;
}

// One outline read from `outline` (the frame's bound of reads and its deadline allowing,
// counted in `reads`), recorded in the trace; the reading when it passed every check (the
// trace's stage is then `detected` until the caller says otherwise).
std::optional<detail::OutlineReading> read_one_outline(const ImageView& work, const std::array<cv::Point2d, 4>& outline,
                                                       const Family& f, const DetectorParams& p,
                                                       const detail::Deadline& deadline, DetectionStats& stats,
                                                       std::int64_t& reads, int& reads_left,
                                                       detail::ReadPlaces& read_places, OutlineVerdict* verdict,
                                                       std::optional<TagId> expected = std::nullopt) {
  if (verdict) verdict->family = f, verdict->outline = outline;
  if (reads_left <= 0) {
    ++stats.outline_reads_skipped;
    if (verdict) verdict->stage = Stage::budget;
    return std::nullopt;
  }
  if (deadline.passed()) {
    ++stats.skipped_by_deadline;
    if (verdict) verdict->stage = Stage::deadline;
    return std::nullopt;
  }
  --reads_left;
  ++reads;
  std::optional<detail::OutlineReading> reading = detail::read_outline(
      work, outline, f, p.min_pixels_per_unit, deadline, &read_places, expected, p.ids_complete ? &p.ids : nullptr);
  const Stage stage = reading ? detail::outline_stage(*reading, p) : Stage::alignment;
  if (stage == Stage::deadline) ++stats.skipped_by_deadline;
  // A place read and plainly refused is not read again in this frame: another outline of
  // the same marker (a second look's, after its border's) aligns there too, to a fraction
  // of a unit (ReadPlaces::seen), and a marker whose cells show under half the evidence a
  // reading needs does not reach it from another start. Nearer the bound, or with a motion
  // blur (which another start may find otherwise), another reading may pass: in the field
  // experiment's tuning set, readings refused at 0.26 to 0.39 were read again at 0.40 to
  // 0.46, and two smeared ones at 0.07 and 0.24 at 0.64. A tracked marker's reading, which
  // only its own id passes, leaves the place to the others.
  if (reading && reading->read && !expected && reading->smear == 0 && stage == Stage::margin &&
      reading->evidence < detail::kEvidenceNotReadAgain)
    read_places.add(f.n(), reading->homography, f, reading->pixels_per_unit);
  if (verdict) {
    verdict->stage = stage;
    if (reading) {
      if (reading->read) verdict->reading = reading->id;
      verdict->correlation = reading->correlation, verdict->marker_correlation = reading->marker_correlation;
      verdict->contrast = reading->contrast, verdict->margin = reading->margin;
      verdict->noise_margin = reading->noise_margin, verdict->evidence = reading->evidence;
      verdict->listed_noise_margin = reading->listed_noise_margin, verdict->listed_evidence = reading->listed_evidence;
      verdict->model_ink = reading->model_ink;
      verdict->pixels_per_unit = reading->pixels_per_unit, verdict->smear = reading->smear;
      verdict->defocus = reading->defocus;
    }
  }
  if (stage != Stage::detected) return std::nullopt;
  return reading;
}

// A second look's working state, kept from patch to patch and frame to frame.
struct PatchLook {
  detail::Patch patch;
  cv::Mat mean;  // the window means of look_as_searched's threshold
  detail::BinaryImage binary;
  detail::RegionTree tree;
  std::vector<detail::Candidate> candidates;
};

// The patch around `box` looked at again: enlarged as `look` says, binarised at its own
// midpoint and labelled, its candidates in `out.candidates` (within the budget left). False
// when the patch is empty.
bool look_at_patch(const ImageView& image, cv::Rect box, const detail::SecondLook& look, const DetectorParams& p,
                   const Camera& camera, detail::RegionLabeller& labeller, PatchLook& out, DetectionStats& stats,
                   int* budget_left, std::vector<detail::Candidate>* area_rejected,
                   std::vector<detail::Candidate>* skipped, cv::Point origin = {}) {
  if (!detail::enlarge_patch(image, box, look, out.patch)) return false;
  out.patch.frame.origin += origin;
  detail::binarise_patch(out.patch, out.binary);
  labeller.label(out.binary, out.tree);
  detail::find_candidates(out.tree, out.binary, ImageView(out.patch.grey), p, camera, out.candidates, stats,
                          out.patch.frame, area_rejected, budget_left, skipped);
  return true;
}

// `box` looked at as the search looks at the frame: at the frame's resolution, its pixels
// binarised as the frame's are (the threshold's window, half of it all round, is taken
// with them). Its candidates in `out.candidates` (within the budget left); false when it
// is empty.
bool look_as_searched(const ImageView& image, cv::Rect box, const DetectorParams& p, const Camera& camera,
                      detail::RegionLabeller& labeller, PatchLook& out, DetectionStats& stats, int* budget_left,
                      cv::Point origin = {}) {
  const int margin = p.threshold_window / 2;
  const cv::Rect area = cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin, box.height + 2 * margin) &
                        cv::Rect(0, 0, image.width, image.height);
  if (area.empty()) return false;
  const ImageView view(image.data + std::ptrdiff_t(area.y) * image.stride + area.x, area.width, area.height,
                       image.stride);
  detail::threshold_mean(view, p.threshold_window, p.threshold_offset, out.mean, out.binary);
  labeller.label(out.binary, out.tree);
  detail::PatchFrame frame;
  frame.origin = area.tl() + origin;
  detail::find_candidates(out.tree, out.binary, view, p, camera, out.candidates, stats, frame, nullptr, budget_left,
                          nullptr);
  return true;
}

// The candidates of a patch looked at with the light taken out (`even`): their squares are
// measured again in the frame (the pose's cell centroids), each pixel against the paper
// under it, as the search measures a shadowed candidate's (paper_under).
void measured_under(const detail::EvenLight& even, std::vector<detail::Candidate>& candidates) {
  for (detail::Candidate& c : candidates) c.paper.local = even.paper, c.paper.origin = even.origin;
}

// The marker in a second look's patch whose squares its binary image could not separate:
// its outline aligned and its cells read from the grey levels (outline.cpp), then posed
// from the squares' centres under the aligned outline like any other detection.
// `reads_left`: the frame's remaining outline reads (kMaxOutlineReads a frame).
void read_outlines(const detail::BinaryImage& binary, const detail::PatchFrame& frame, const ImageView& work,
                   const Camera& camera, const DetectorParams& p, const detail::Deadline& deadline,
                   DetectionStats& stats, std::vector<Detection>& found, int& reads_left,
                   detail::ReadPlaces& read_places, DetectionTrace* trace) {
  for (const std::array<cv::Point2d, 4>& outline : detail::coarse_outlines(binary, frame))
    for (const Family& f : p.families) {
      OutlineVerdict* verdict = trace ? &trace->outline_reads.emplace_back() : nullptr;
      const std::optional<detail::OutlineReading> reading =
          read_one_outline(work, outline, f, p, deadline, stats, stats.outline_reads, reads_left, read_places, verdict);
      if (!reading || !add_outline_detection(*reading, f, camera, p, found, read_places, verdict)) continue;
      ++stats.decoded, ++stats.second_look_found, ++stats.outline_found;
      return;  // one marker to a patch
    }
}

// An outline read from `outline` (read_one_outline), in the frame or, where `even` holds
// the light taken out there, in its pixels, the reading then placed back in the frame.
std::optional<detail::OutlineReading> read_one_outline_in(const std::optional<detail::EvenLight>& even,
                                                          const ImageView& work,
                                                          const std::array<cv::Point2d, 4>& outline, const Family& f,
                                                          const DetectorParams& p, const detail::Deadline& deadline,
                                                          DetectionStats& stats, int& reads_left,
                                                          detail::ReadPlaces& read_places, OutlineVerdict* verdict) {
  if (!even)
    return read_one_outline(work, outline, f, p, deadline, stats, stats.outline_reads, reads_left, read_places,
                            verdict);
  const cv::Point2d origin(even->origin);
  std::array<cv::Point2d, 4> moved = outline;
  for (cv::Point2d& q : moved) q -= origin;
  detail::ReadPlaces none;  // (they are the frame's)
  std::optional<detail::OutlineReading> reading = read_one_outline(
      ImageView(even->pixels), moved, f, p, deadline, stats, stats.outline_reads, reads_left, none, verdict);
  if (verdict) verdict->outline = outline;
  if (reading) reading->homography = cv::Matx33d(1, 0, origin.x, 0, 1, origin.y, 0, 0, 1) * reading->homography;
  return reading;
}

// What the trace tells of a border proposal: its outline and evidence (its stage is
// filled in as it is read).
BorderVerdict border_verdict(const detail::BorderProposal& proposal) {
  BorderVerdict v;
  v.outline = proposal.corners;
  v.contrast = proposal.evidence->contrast, v.noise = proposal.evidence->noise;
  v.ring = proposal.evidence->ring, v.darker_sides = proposal.evidence->darker_sides;
  v.structure = proposal.evidence->structure;
  return v;
}

// The border proposals of the frame (borders.cpp) that no detection covers, clearest
// first, each looked at as a second look would (its patch binarised at its own midpoint,
// with the light taken out where a shadow crosses it, its candidates decoded: a reading by
// the squares poses more precisely than one by the outline, and costs less), then read
// from its quadrilateral for the families whose border it may be;
// one marker to a proposal. Within the frame's budget, outline reads and deadline. (The
// outlines of the patch's other pieces are left to the second look, which reads them
// anyway where no marker was found.)
void read_borders(const std::vector<detail::BorderProposal>& proposals, const ImageView& work, const Camera& camera,
                  const DetectorParams& p, const detail::SecondLook& look, const detail::Deadline& deadline,
                  detail::RegionLabeller& labeller, PatchLook& patch_look, int* budget_left, DetectionStats& stats,
                  std::vector<Detection>& found, int& reads_left, detail::ReadPlaces& read_places,
                  DetectionTrace* trace) {
  for (const detail::BorderProposal& proposal : proposals) {
    const cv::Point2d centre =
        (proposal.corners[0] + proposal.corners[1] + proposal.corners[2] + proposal.corners[3]) / 4;
    BorderVerdict* border = trace ? &trace->borders.emplace_back(border_verdict(proposal)) : nullptr;
    if (already_found(found, centre)) {  // read from another proposal of the same marker
      if (border) border->stage = Stage::duplicate;
      continue;
    }
    if (deadline.passed()) {
      ++stats.skipped_by_deadline;
      if (border) border->stage = Stage::deadline;
      continue;
    }
    if (budget_left && *budget_left <= 0) {  // spent: no second look, here as anywhere
      ++stats.second_looks_skipped;
      if (border) border->stage = Stage::budget;
      continue;
    }
    ++stats.borders;
    const cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(proposal.corners.begin(), proposal.corners.end()));
    ++stats.second_looks;
    // Where the light under it varies (a shadow's edge across the marker), the patch is
    // looked at with the light taken out, as the first family it may be reads it: its
    // squares then separate as in even light, and are decoded, cheaper and more precise
    // than a reading of its outline.
    std::optional<detail::EvenLight> even;
    int even_n = 0;  // the family `even` was taken out for
    for (const Family& f : p.families)
      if (!even_n && proposal.families[std::size_t(f.n())])
        even = detail::even_light(work, proposal.corners, f), even_n = f.n();
    const cv::Point origin = even ? even->origin : cv::Point();
    const bool patched = look_at_patch(even ? ImageView(even->pixels) : work, box - origin, look, p, camera, labeller,
                                       patch_look, stats, budget_left, nullptr, nullptr, origin);
    if (patched && even) measured_under(*even, patch_look.candidates);
    if (patched) {
      if (trace) trace->second_looks.push_back(box);
      const std::size_t before = found.size();
      decode_candidates(patch_look.candidates, work, camera, p, true, deadline, stats, trace, found);
      if (found.size() > before) {
        stats.second_look_found += std::int64_t(found.size() - before);
        stats.border_found += std::int64_t(found.size() - before);
        if (border) border->stage = Stage::detected;
        continue;
      }
    }
    for (const Family& f : p.families) {
      if (!proposal.families[std::size_t(f.n())]) continue;
      OutlineVerdict* verdict = nullptr;
      if (trace) {
        verdict = &trace->outline_reads.emplace_back();
        verdict->border = true;
      }
      const std::optional<detail::OutlineReading> reading =
          read_one_outline_in(f.n() == even_n ? even : detail::even_light(work, proposal.corners, f), work,
                              proposal.corners, f, p, deadline, stats, reads_left, read_places, verdict);
      if (border && verdict && (border->stage == Stage::border || int(verdict->stage) > int(border->stage)))
        border->family = f, border->stage = verdict->stage;
      if (!reading || !add_outline_detection(*reading, f, camera, p, found, read_places, verdict)) continue;
      if (border) border->stage = Stage::detected;
      ++stats.decoded, ++stats.border_found, ++stats.outline_found;
      break;
    }
  }
}

// The markers the caller expects (FrameHints::expected) that the search did not find,
// each looked for where it is expected: the place looked at as the search looks at the
// frame, then as a second look would (its squares found and decoded as the search's are,
// wherever in the patch the marker has moved), then the grey levels under the expected
// outline read (a marker whose squares the blur merged).
// Each is taken only as the family and id expected: another id there is refused (a
// marker that crossed the expected one, which the search finds by itself, or a
// misreading: a wrong id is worse than a miss). The outline reads are bounded as the
// second look's are (kMaxOutlineReads a frame), and all of it by the deadline.
void read_expected(const std::vector<ExpectedMarker>& expected, const ImageView& work, const Camera& camera,
                   const DetectorParams& p, const detail::Deadline& deadline, detail::RegionLabeller& labeller,
                   PatchLook& patch_look, int* budget_left, DetectionStats& stats, std::vector<Detection>& found,
                   detail::ReadPlaces& read_places, DetectionTrace* trace) {
  int reads_left = kMaxOutlineReads;
  const auto is_expected = [](const ExpectedMarker& e, const Detection& d) {
    return d.family == e.family && d.id == e.id;
  };
  // The camera's own shake moves every marker alike, and no track's motion foresees it:
  // the markers of the frame found so far say how far it took them from where their
  // tracks put them, and the grey-level measurement of the next starts that much further on.
  const auto shake = [&](std::size_t upto) {
    cv::Point2d sum;
    int count = 0;
    for (std::size_t i = 0; i < upto; ++i) {
      const auto it =
          std::find_if(found.begin(), found.end(), [&](const Detection& d) { return is_expected(expected[i], d); });
      if (it == found.end()) continue;
      sum += it->center - detail::diagonals_crossing(expected[i].corners);
      ++count;
    }
    return count > 0 ? sum / count : cv::Point2d();
  };
  for (std::size_t index = 0; index < expected.size(); ++index) {
    const ExpectedMarker& e = expected[index];
    const bool sought = std::find(p.families.begin(), p.families.end(), e.family) != p.families.end();
    const bool present = std::any_of(found.begin(), found.end(), [&](const Detection& d) { return is_expected(e, d); });
    if (!sought || present) continue;
    if (deadline.passed()) {
      ++stats.skipped_by_deadline;
      continue;
    }
    ++stats.expected_reads;
    // The patch: the expected outline's box and an eighth of its side all round (the
    // patch adds a quarter of that again), room for a prediction a few units off; the
    // patch's pixels are most of what this look costs.
    cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(e.corners.begin(), e.corners.end()));
    const int grow = std::max(box.width, box.height) / 8;
    box = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow);
    // A marker that stayed sharp is measured where expected from the grey levels alone
    // (tracked.cpp), without the patch's threshold, regions and blobs.
    const cv::Point2d moved = shake(index);
    std::array<cv::Point2d, 4> shaken = e.corners;
    for (cv::Point2d& corner : shaken) corner += moved;
    if (std::optional<detail::TrackedMeasurement> m =
            detail::measure_tracked(work, camera, p, e.family, e.id, shaken, stats)) {
      std::optional<Detection> det =
          pose_decoded(m->candidate, m->decoding, m->keypoints, work, camera, p, m->edges, true);
      if (det && !already_found(found, det->center)) {
        ++stats.decoded, ++stats.expected_found, ++stats.expected_measured;
        found.push_back(std::move(*det));
        continue;
      }
    }
    detail::SecondLook look;
    look.sought.reset().set(e.family.n());
    // Otherwise a marker that stayed sharp is found as the search found it, at a fraction of a
    // second look's cost (no enlarged patch, no local extremes), and where a shadow crosses
    // the expected outline so again with the light taken out (the closing is spared the
    // markers the plain look finds); a blurred one by the second look. (The second look and
    // the outline read stay in the frame's pixels: a motion blur's smear also makes the
    // paper's level look uneven, and the evened pixels lose the smeared squares.)
    bool taken = false;
    enum class Look { searched, searched_in_even_light, second };
    for (const Look kind : {Look::searched, Look::searched_in_even_light, Look::second}) {
      if (taken || (budget_left && *budget_left <= 0)) break;
      std::optional<detail::EvenLight> even;
      if (kind == Look::searched_in_even_light && !(even = detail::even_light(work, e.corners, e.family))) continue;
      const ImageView pixels = even ? ImageView(even->pixels) : work;
      const cv::Point origin = even ? even->origin : cv::Point();
      std::vector<Detection> local;
      if (kind == Look::second
              ? look_at_patch(pixels, box - origin, look, p, camera, labeller, patch_look, stats, budget_left, nullptr,
                              nullptr, origin)
              : look_as_searched(pixels, box - origin, p, camera, labeller, patch_look, stats, budget_left, origin)) {
        if (even) measured_under(*even, patch_look.candidates);
        decode_candidates(patch_look.candidates, work, camera, p, true, deadline, stats, trace, local);
      }
      const auto it = std::find_if(local.begin(), local.end(), [&](const Detection& d) { return is_expected(e, d); });
      taken = it != local.end() && !already_found(found, it->center);
      stats.decoded -= std::int64_t(local.size()) - taken;  // the others are not detections
      if (taken) {
        ++stats.expected_found;
        found.push_back(std::move(*it));
      }
    }
    if (taken) continue;
    OutlineVerdict* verdict = nullptr;
    if (trace) {
      verdict = &trace->outline_reads.emplace_back();
      verdict->expected = true;
    }
    const std::optional<detail::OutlineReading> reading = read_one_outline(
        work, e.corners, e.family, p, deadline, stats, stats.outline_reads, reads_left, read_places, verdict, e.id);
    if (!reading) continue;
    if (reading->id != e.id) {
      if (verdict) verdict->stage = Stage::unexpected;
      continue;
    }
    if (!add_outline_detection(*reading, e.family, camera, p, found, read_places, verdict)) continue;
    ++stats.decoded, ++stats.expected_found, ++stats.outline_found;
  }
}

}  // namespace

const char* stage_name(Stage stage) {
  switch (stage) {
    case Stage::area: return "area";
    case Stage::budget: return "budget";
    case Stage::deadline: return "deadline";
    case Stage::geometry: return "geometry";
    case Stage::angle: return "angle";
    case Stage::collinearity: return "collinearity";
    case Stage::border: return "border";
    case Stage::alignment: return "alignment";
    case Stage::structure: return "structure";
    case Stage::contrast: return "contrast";
    case Stage::baselines: return "baselines";
    case Stage::resolution: return "resolution";
    case Stage::decoding: return "decoding";
    case Stage::margin: return "margin";
    case Stage::ink: return "ink";
    case Stage::marker: return "marker";
    case Stage::unexpected: return "unexpected";
    case Stage::unlisted: return "unlisted";
    case Stage::pose: return "pose";
    case Stage::duplicate: return "duplicate";
    case Stage::detected: return "detected";
  }
  return "?";
}

namespace {

// The detections whose id is not in `listed` (sorted; empty: every id is) taken out of
// `found` and counted, and the verdicts that read them marked so in `trace`. They are
// taken out only now so that, found, they kept their places from being read again.
void drop_unlisted(const std::vector<TagId>& listed, std::vector<Detection>& found, DetectionStats& stats,
                   DetectionTrace* trace) {
  if (listed.empty()) return;
  const auto is_listed = [&](TagId id) { return std::binary_search(listed.begin(), listed.end(), id); };
  const auto unlisted =
      std::remove_if(found.begin(), found.end(), [&](const Detection& d) { return !is_listed(d.id); });
  stats.unlisted += found.end() - unlisted;
  found.erase(unlisted, found.end());
  if (!trace) return;
  const auto mark = [&](auto& verdicts) {
    for (auto& v : verdicts)
      if (v.stage == Stage::detected && v.reading && !is_listed(*v.reading)) v.stage = Stage::unlisted;
  };
  mark(trace->verdicts);
  mark(trace->outline_reads);
}

}  // namespace

struct Detector::Impl {
  DetectorParams params;
  std::vector<TagId> listed;  // params.ids, sorted
  cv::Mat mean;
  detail::BinaryImage binary;
  detail::RegionLabeller labeller;
  detail::RegionTree tree;
  std::vector<detail::Candidate> candidates, area_rejected, skipped;
  PatchLook patch_look;  // the second look's and the expected markers' patches
  Camera camera;         // for the last frame size
  cv::Size camera_size;

  const Camera& camera_for(int w, int h) {
    if (camera_size != cv::Size(w, h)) {
      camera = params.camera ? params.camera->for_frame(w, h) : Camera::default_for(w, h);
      camera_size = cv::Size(w, h);
    }
    return camera;
  }
};

Detector::Detector(DetectorParams params) : impl_(std::make_unique<Impl>()) {
  params.validate();
  impl_->listed = params.ids;
  std::sort(impl_->listed.begin(), impl_->listed.end());
  impl_->params = std::move(params);
}
Detector::~Detector() = default;
Detector::Detector(Detector&&) noexcept = default;
Detector& Detector::operator=(Detector&&) noexcept = default;

const DetectorParams& Detector::params() const { return impl_->params; }

std::vector<Detection> Detector::detect(const ImageView& image, DetectionStats* stats_out, DetectionTrace* trace) {
  return detect(image, FrameHints{}, stats_out, trace);
}

std::vector<Detection> Detector::detect(const ImageView& image, const FrameHints& hints, DetectionStats* stats_out,
                                        DetectionTrace* trace) {
  if (image.width < 0 || image.height < 0) throw std::invalid_argument("image size must not be negative");
  if (!image.empty() && (image.data == nullptr || image.stride < image.width))
    throw std::invalid_argument("image has no pixels or a stride shorter than its width");
  Impl& s = *impl_;
  DetectionStats stats;
  stats.frames = 1;
  std::vector<Detection> found;
  if (trace) *trace = DetectionTrace{};
  if (image.empty())
    throw std::invalid_argument("the image is empty (" + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + ")");
  const DetectorParams& p = s.params;
  auto start = Clock::now();
  const detail::Deadline deadline(detail::Deadline::thread_time(), p.deadline_ms);
  const Camera& camera = s.camera_for(image.width, image.height);
  detail::ReadPlaces read_places;  // where this frame's outline readings found markers
  if (!hints.full_search) {
    int budget = p.max_candidates;
    read_expected(hints.expected, image, camera, p, deadline, s.labeller, s.patch_look,
                  p.max_candidates > 0 ? &budget : nullptr, stats, found, read_places, trace);
    stats.expected_ms = elapsed_ms(start);
    stats.past_deadline = stats.skipped_by_deadline > 0 ? 1 : 0;
    drop_unlisted(s.listed, found, stats, trace);
    if (trace) trace->detections = found;
    if (stats_out) *stats_out += stats;
    return found;
  }
  detail::threshold_mean(image, p.threshold_window, p.threshold_offset, s.mean, s.binary);
  // Only the second look uses the noise (and --why reports it).
  const double noise = p.second_look || trace ? detail::estimate_noise(image) : 0.0;
  stats.threshold_ms = elapsed_ms(start);
  if (trace) trace->binary = s.binary.to_mat(), trace->noise = noise;

  start = Clock::now();
  s.labeller.label(s.binary, s.tree);
  stats.regions_ms = elapsed_ms(start);

  // The candidates the frame may still examine, its own and its second looks'.
  int budget = p.max_candidates;
  int* const budget_left = p.max_candidates > 0 ? &budget : nullptr;
  const auto record_rejected = [&](bool second_look) {
    if (!trace) return;
    for (const detail::Candidate& c : s.area_rejected)
      trace->verdicts.push_back(verdict_of(c, second_look, Stage::area));
    for (const detail::Candidate& c : s.skipped) trace->verdicts.push_back(verdict_of(c, second_look, Stage::budget));
  };

  start = Clock::now();
  detail::find_candidates(s.tree, s.binary, image, p, camera, s.candidates, stats, {},
                          trace ? &s.area_rejected : nullptr, budget_left, trace ? &s.skipped : nullptr);
  stats.candidates_ms = elapsed_ms(start);
  record_rejected(false);

  // The frame's own candidates are examined whatever the deadline (the budget bounds
  // them), so that a slow machine still finds every sharp marker.
  decode_candidates(s.candidates, image, camera, p, false, {}, stats, trace, found);
  // The expected markers the search missed, before the second look (which then leaves
  // the places of those found alone): optional work, like it.
  start = Clock::now();
  const std::int64_t skipped_before = stats.skipped_by_deadline;
  read_expected(hints.expected, image, camera, p, deadline, s.labeller, s.patch_look, budget_left, stats, found,
                read_places, trace);
  stats.expected_ms = elapsed_ms(start);

  // Border proposals and the second look, around what no detection covers: the optional
  // work the deadline cuts (not sought at all once it has passed). They share the frame's
  // outline reads.
  bool cut = false;
  if (p.second_look && deadline.passed()) cut = true;
  if (p.second_look && !cut) {
    detail::SecondLook look;
    look.sought.reset();
    for (const Family& f : p.families) look.sought.set(f.n());
    look.noise = noise;
    const auto taken_boxes = [&] {
      std::vector<cv::Rect> taken;
      for (const Detection& d : found)
        taken.push_back(cv::boundingRect(std::vector<cv::Point2f>(d.corners.begin(), d.corners.end())));
      return taken;
    };
    int outline_reads_left = kMaxOutlineReads;
    start = Clock::now();
    std::vector<detail::BorderProposal> refused;
    const std::vector<detail::BorderProposal> proposals =
        detail::propose_borders(s.tree, image, look, p.families, taken_boxes(), trace ? &refused : nullptr);
    if (trace)
      for (const detail::BorderProposal& r : refused) trace->borders.push_back(border_verdict(r));
    read_borders(proposals, image, camera, p, look, deadline, s.labeller, s.patch_look, budget_left, stats, found,
                 outline_reads_left, read_places, trace);
    stats.borders_ms += elapsed_ms(start);

    start = Clock::now();
    std::vector<cv::Rect> boxes = detail::near_candidates(s.tree, s.binary, image, look, taken_boxes());
    if (int(boxes.size()) > p.max_second_looks) {
      stats.second_looks_skipped += std::int64_t(boxes.size()) - p.max_second_looks;
      boxes.resize(p.max_second_looks);
    }
    stats.second_look_ms += elapsed_ms(start);
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      if (budget_left && *budget_left <= 0) {  // spent: what the patches hold could not be examined
        stats.second_looks_skipped += std::int64_t(boxes.size() - i);
        break;
      }
      if (deadline.passed()) {
        stats.skipped_by_deadline += std::int64_t(boxes.size() - i);
        break;
      }
      const cv::Rect& box = boxes[i];
      start = Clock::now();
      ++stats.second_looks;
      const bool looked = look_at_patch(image, box, look, p, camera, s.labeller, s.patch_look, stats, budget_left,
                                        trace ? &s.area_rejected : nullptr, trace ? &s.skipped : nullptr);
      stats.second_look_ms += elapsed_ms(start);
      if (!looked) continue;
      if (trace) trace->second_looks.push_back(box);
      record_rejected(true);
      const std::size_t before = found.size();
      decode_candidates(s.patch_look.candidates, image, camera, p, true, deadline, stats, trace, found);
      stats.second_look_found += std::int64_t(found.size() - before);
      if (found.size() == before) {
        start = Clock::now();
        read_outlines(s.patch_look.binary, s.patch_look.patch.frame, image, camera, p, deadline, stats, found,
                      outline_reads_left, read_places, trace);
        stats.second_look_ms += elapsed_ms(start);
      }
    }
  }

  stats.past_deadline = cut || stats.skipped_by_deadline > skipped_before ? 1 : 0;
  drop_unlisted(s.listed, found, stats, trace);
  if (trace) trace->detections = found;
  if (stats_out) *stats_out += stats;
  return found;
}

}  // namespace lftag
