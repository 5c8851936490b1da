// SPDX-License-Identifier: LGPL-2.1-or-later
// The chain of stages, with timing and the false-positive funnel.
#include <algorithm>
#include <cmath>
#include <stdexcept>

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
    case 2: return 0.0;     // misordered black/white sample pairs (see decode.cpp): none
    case 3: return 5e-4;    // the paper
    case 4: return 1e-3;    // the paper
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
}

double DetectionStats::total_ms() const {
  return threshold_ms + regions_ms + candidates_ms + keypoints_ms + hypotheses_ms + decode_ms + pose_ms +
         second_look_ms;
}

DetectionStats& DetectionStats::operator+=(const DetectionStats& o) {
  frames += o.frames, regions += o.regions, topology += o.topology, area += o.area, geometry += o.geometry;
  angle += o.angle, collinearity += o.collinearity, residual += o.residual, unambiguous += o.unambiguous;
  decoded += o.decoded, second_looks += o.second_looks, second_look_found += o.second_look_found;
  outline_reads += o.outline_reads, outline_found += o.outline_found, outline_reads_skipped += o.outline_reads_skipped;
  skipped_by_budget += o.skipped_by_budget, second_looks_skipped += o.second_looks_skipped;
  past_deadline += o.past_deadline, skipped_by_deadline += o.skipped_by_deadline;
  second_look_ms += o.second_look_ms;
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

// Key points, decoding and pose of every candidate, most plausible first, until the
// deadline (a second look's; none for the frame's own); detections are appended to `found`, except where a detection already stands
// (a second look can overlap one).
void decode_candidates(const std::vector<detail::Candidate>& candidates, const ImageView& work, const Camera& camera,
                       const DetectorParams& p, bool second_look, const detail::Deadline& deadline,
                       DetectionStats& stats, DetectionTrace* trace, std::vector<Detection>& found) {
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    const detail::Candidate& c = candidates[i];
    if (deadline.passed()) {
      stats.skipped_by_deadline += std::int64_t(candidates.size() - i);
      if (trace)
        for (; i < candidates.size(); ++i) trace->verdicts.push_back(verdict_of(candidates[i], second_look, Stage::deadline));
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
    std::array<bool, 2> passed{};  // residual, margin: for any side
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
      if (!constraints.geometry) stage = Stage::geometry;
      else if (!constraints.angle) stage = Stage::angle;
      else if (!constraints.collinearity) stage = Stage::collinearity;
      else if (!best) stage = Stage::decoding;
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
    Detection det;
    det.family = c.family;
    det.id = d->id;
    det.decode_error = d->error;
    det.worst_cell = d->worst_cell;
    det.noise_margin = d->noise_margin;
    det.ink_spread = d->ink_spread;
    det.edge_score = d->edge_score;
    // The pose's centroids: each square's ink over its window under the decoding's
    // homography, unbiased by defocus (cell_centroids.cpp); the blobs' for a marker under
    // 1.25 px per unit or by the frame's edge.
    detail::Candidate for_pose = c;
    const std::vector<cv::Point2d> cells = detail::cell_centroids(work, camera, c.family, d->id, d->homography);
    if (!cells.empty()) {
      const std::vector<cv::Point2d> ideal = camera.undistort(cells);
      for (int g = 0; g < c.family.cell_count(); ++g) {
        detail::Blob& b = for_pose.blobs[d->blob_of_cell[g]];
        b.centroid = cells[g], b.point = ideal[g];
      }
    }
    for (int g = 0; g < c.family.cell_count(); ++g) det.centroids.push_back(for_pose.blobs[d->blob_of_cell[g]].centroid);
    for (int i = 0; i < 4; ++i) det.keypoints[i] = for_pose.blobs[k->blob[i]].centroid;
    const bool posed = detail::estimate_pose(for_pose, *d, camera, p, det);
    stats.pose_ms += elapsed_ms(start);
    Stage outcome = Stage::detected;
    if (!posed) outcome = Stage::pose;
    else if (already_found(found, det.center)) outcome = Stage::duplicate;
    if (trace) trace->verdicts.back().stage = outcome;
    if (outcome != Stage::detected) continue;
    stats.second_look_found += second_look;
    found.push_back(std::move(det));
  }
}

// The marker in a second look's patch whose squares its binary image could not separate:
// its outline aligned and its cells read from the grey levels (outline.cpp), then posed
// from the squares' centres under the aligned outline like any other detection.
// `reads_left`: the frame's remaining outline reads (detail::kMaxOutlineReads a frame).
void read_outlines(const detail::BinaryImage& binary, const detail::PatchFrame& frame, const ImageView& work,
                   const Camera& camera, const DetectorParams& p, const detail::Deadline& deadline,
                   DetectionStats& stats, std::vector<Detection>& found, int& reads_left,
                   detail::ReadPlaces& read_places, DetectionTrace* trace) {
  for (const std::array<cv::Point2d, 4>& outline : detail::coarse_outlines(binary, frame))
    for (const Family& f : p.families) {
      OutlineVerdict* verdict = nullptr;
      if (trace) {
        verdict = &trace->outline_reads.emplace_back();
        verdict->family = f, verdict->outline = outline;
      }
      if (reads_left <= 0) {
        ++stats.outline_reads_skipped;
        if (verdict) verdict->stage = Stage::budget;
        continue;
      }
      if (deadline.passed()) {
        ++stats.skipped_by_deadline;
        if (verdict) verdict->stage = Stage::deadline;
        continue;
      }
      --reads_left;
      ++stats.outline_reads;
      const std::optional<detail::OutlineReading> reading =
          detail::read_outline(work, outline, f, p.min_pixels_per_unit, deadline, &read_places);
      const Stage stage = reading ? detail::outline_stage(*reading, p) : Stage::alignment;
      if (stage == Stage::deadline) ++stats.skipped_by_deadline;
      if (verdict) {
        verdict->stage = stage;
        if (reading) {
          if (reading->read) verdict->reading = reading->id;
          verdict->correlation = reading->correlation, verdict->marker_correlation = reading->marker_correlation;
          verdict->contrast = reading->contrast, verdict->margin = reading->margin;
          verdict->noise_margin = reading->noise_margin, verdict->evidence = reading->evidence;
          verdict->pixels_per_unit = reading->pixels_per_unit, verdict->smear = reading->smear;
          verdict->defocus = reading->defocus;
        }
      }
      if (stage != Stage::detected) continue;
      // Blobs at the centroids of the squares under the homography, which is what the
      // pose's perspective correction expects of a blob.
      detail::Candidate c;
      c.family = f;
      detail::Decoding d;
      d.id = reading->id;
      d.homography = reading->homography;
      std::vector<cv::Point2d> observed;
      for (int g = 0; g < f.cell_count(); ++g) {
        const UnitRect s = f.square(g, f.is_baseline(g) ? 0 : d.id.digit(f.data_index(g)));
        std::vector<cv::Point2d> square = {{s.x, s.y}, {s.x + s.width, s.y}, {s.x + s.width, s.y + s.height},
                                           {s.x, s.y + s.height}};
        cv::perspectiveTransform(square, square, reading->homography);
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
      det.noise_margin = reading->noise_margin;
      const std::array<int, 4> keypoint_cells = f.keypoint_cells();
      for (int i = 0; i < 4; ++i) det.keypoints[i] = observed[keypoint_cells[i]];
      if (!detail::estimate_pose(c, d, camera, p, det)) {
        if (verdict) verdict->stage = Stage::pose;
        continue;
      }
      if (already_found(found, det.center)) {
        if (verdict) verdict->stage = Stage::duplicate;
        continue;
      }
      ++stats.decoded, ++stats.second_look_found, ++stats.outline_found;
      read_places.add(f.n(), reading->homography, f, reading->pixels_per_unit);
      found.push_back(std::move(det));
      return;  // one marker to a patch
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
    case Stage::alignment: return "alignment";
    case Stage::structure: return "structure";
    case Stage::contrast: return "contrast";
    case Stage::baselines: return "baselines";
    case Stage::resolution: return "resolution";
    case Stage::decoding: return "decoding";
    case Stage::margin: return "margin";
    case Stage::ink: return "ink";
    case Stage::marker: return "marker";
    case Stage::smear: return "smear";
    case Stage::pose: return "pose";
    case Stage::duplicate: return "duplicate";
    case Stage::detected: return "detected";
  }
  return "?";
}

struct Detector::Impl {
  DetectorParams params;
  cv::Mat mean;
  detail::BinaryImage binary;
  detail::RegionLabeller labeller;
  detail::RegionTree tree;
  std::vector<detail::Candidate> candidates, area_rejected, skipped;
  // The second look's patch and its binary image and tree.
  detail::Patch patch;
  detail::BinaryImage patch_binary;
  detail::RegionTree patch_tree;
  Camera camera;  // for the last frame size
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
  impl_->params = std::move(params);
}
Detector::~Detector() = default;
Detector::Detector(Detector&&) noexcept = default;
Detector& Detector::operator=(Detector&&) noexcept = default;

const DetectorParams& Detector::params() const { return impl_->params; }

std::vector<Detection> Detector::detect(const ImageView& image, DetectionStats* stats_out, DetectionTrace* trace) {
  if (image.width < 0 || image.height < 0) throw std::invalid_argument("image size must not be negative");
  if (!image.empty() && (image.data == nullptr || image.stride < image.width))
    throw std::invalid_argument("image has no pixels or a stride shorter than its width");
  Impl& s = *impl_;
  DetectionStats stats;
  stats.frames = 1;
  std::vector<Detection> found;
  if (trace) *trace = DetectionTrace{};
  if (image.empty()) throw std::invalid_argument("the image is empty (" + std::to_string(image.width) + "x" +
                                                 std::to_string(image.height) + ")");
  const DetectorParams& p = s.params;
  auto start = Clock::now();
  const detail::Deadline deadline(detail::Deadline::thread_time(), p.deadline_ms);
  const Camera& camera = s.camera_for(image.width, image.height);
  detail::threshold_mean(image, p.threshold_window, p.threshold_offset, s.mean, s.binary);
  stats.threshold_ms = elapsed_ms(start);
  if (trace) trace->binary = s.binary.to_mat();

  start = Clock::now();
  s.labeller.label(s.binary, s.tree);
  stats.regions_ms = elapsed_ms(start);

  // The candidates the frame may still examine, its own and its second looks'.
  int budget = p.max_candidates;
  int* const budget_left = p.max_candidates > 0 ? &budget : nullptr;
  const auto record_rejected = [&](bool second_look) {
    if (!trace) return;
    for (const detail::Candidate& c : s.area_rejected) trace->verdicts.push_back(verdict_of(c, second_look, Stage::area));
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

  // The second look, around clusters that no detection covers: the optional work the
  // deadline cuts (not sought at all once it has passed).
  const std::int64_t skipped_before = stats.skipped_by_deadline;
  bool cut = false;
  if (p.second_look && deadline.passed()) cut = true;
  if (p.second_look && !cut) {
    start = Clock::now();
    detail::SecondLook look;
    look.sought.reset();
    for (const Family& f : p.families) look.sought.set(f.n());
    std::vector<cv::Rect> taken;
    for (const Detection& d : found)
      taken.push_back(cv::boundingRect(std::vector<cv::Point2f>(d.corners.begin(), d.corners.end())));
    std::vector<cv::Rect> boxes = detail::near_candidates(s.tree, s.binary, image, look, taken);
    int outline_reads_left = detail::kMaxOutlineReads;
    detail::ReadPlaces read_places;  // where this frame's outline readings found markers
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
      if (!detail::enlarge_patch(image, box, look, s.patch)) {
        stats.second_look_ms += elapsed_ms(start);
        continue;
      }
      detail::binarise_patch(s.patch, 0.5, s.patch_binary);
      s.labeller.label(s.patch_binary, s.patch_tree);
      detail::find_candidates(s.patch_tree, s.patch_binary, ImageView(s.patch.grey), p, camera, s.candidates, stats,
                              s.patch.frame, trace ? &s.area_rejected : nullptr, budget_left,
                              trace ? &s.skipped : nullptr);
      stats.second_look_ms += elapsed_ms(start);
      if (trace) trace->second_looks.push_back(box);
      record_rejected(true);
      const std::size_t before = found.size();
      decode_candidates(s.candidates, image, camera, p, true, deadline, stats, trace, found);
      if (found.size() == before) {
        start = Clock::now();
        read_outlines(s.patch_binary, s.patch.frame, image, camera, p, deadline, stats, found, outline_reads_left,
                      read_places, trace);
        stats.second_look_ms += elapsed_ms(start);
      }
    }
  }

  stats.past_deadline = cut || stats.skipped_by_deadline > skipped_before ? 1 : 0;
  if (trace) trace->detections = found;
  if (stats_out) *stats_out += stats;
  return found;
}

}  // namespace lftag
