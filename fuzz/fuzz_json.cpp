// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the plugin's records of detections and their serialisations, which
// nothing in the project parses back as JSON, so each is checked against the other:
//
//   - Detections from arbitrary bytes (any double, NaN and infinities included, any id,
//     any number of centroids) into "lftag/detection" structures and back
//     (metaconversion: detection_structure, detection_from_structure), through their
//     text (gst_structure_to_string and back, as `gst-launch-1.0 -m` prints messages),
//     and in an LFTagMeta on a buffer (add_detection_meta, read_detection_meta), must
//     give exactly the detections, bit for bit (through text: NaN as any NaN); the
//     buffer's JSON line (lftagjson's buffer_json, what lftagpublish writes) must be valid
//     JSON (nlohmann parses its dump) holding the same values: ids exact (a number when
//     under 2^53, else a decimal string, and id_hex), doubles exact, non-finite ones null.
//   - Arbitrary GstStructure text (what any element upstream may attach as an LFTagMeta
//     or an LFTagTruthMeta) read back by read_detection_meta, read_truth_meta,
//     detection_from_structure and truth_from_structure: read, or refused with
//     std::invalid_argument, never anything else; what was read writes and reads back
//     to itself, and its JSON is checked as above.
//
// Byte 0 even: binary detections (see read_frame); odd: the rest is structure text.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "check.hpp"
#include "gst_fuzz.hpp"
#include "lftag-meta.h"
#include "lftagjson.h"
#include "metaconversion.h"

using lftag::Detection;
using lftag::MarkerTruth;
using lftag::TagId;
using lftag::fuzz::check;
using lftag::fuzz::Reader;
using lftag::gst::FrameDetections;
using lftag::gst::FrameTruth;

namespace {

double raw_double(Reader& in) {
  const std::uint64_t bits = in.u64();
  double x;
  std::memcpy(&x, &bits, sizeof x);
  return x;
}

// Bit for bit, so that -0 and NaN payloads count.
bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }
// As text keeps doubles: exactly, but any NaN for a NaN.
bool same_value(double a, double b) { return std::isnan(a) ? std::isnan(b) : same_bits(a, b); }

template <class Same>
bool same_points(const cv::Point2d* a, const cv::Point2d* b, std::size_t n, Same same) {
  for (std::size_t i = 0; i < n; ++i)
    if (!same(a[i].x, b[i].x) || !same(a[i].y, b[i].y)) return false;
  return true;
}

// Every field the structure holds (ink_spread is not one of them).
template <class Same>
bool same_detection(const Detection& a, const Detection& b, Same same) {
  return a.family == b.family && a.id == b.id && a.centroids.size() == b.centroids.size() &&
         same_points(a.centroids.data(), b.centroids.data(), a.centroids.size(), same) &&
         same_points(a.keypoints.data(), b.keypoints.data(), 4, same) &&
         same_points(a.corners.data(), b.corners.data(), 4, same) && same_points(&a.center, &b.center, 1, same) &&
         same(a.rvec[0], b.rvec[0]) && same(a.rvec[1], b.rvec[1]) && same(a.rvec[2], b.rvec[2]) &&
         same(a.tvec[0], b.tvec[0]) && same(a.tvec[1], b.tvec[1]) && same(a.tvec[2], b.tvec[2]) &&
         same(a.tag_size, b.tag_size) && a.calibrated == b.calibrated && same(a.decode_error, b.decode_error) &&
         same(a.worst_cell, b.worst_cell) && same(a.edge_score, b.edge_score) &&
         same(a.reprojection_error, b.reprojection_error) && a.from_outline == b.from_outline;
}

bool same_truth(const MarkerTruth& a, const MarkerTruth& b) {
  auto points = [](const std::vector<cv::Point2d>& p, const std::vector<cv::Point2d>& q) {
    return p.size() == q.size() && same_points(p.data(), q.data(), p.size(), same_bits);
  };
  return a.family == b.family && a.id == b.id && same_bits(a.tag_size, b.tag_size) && same_bits(a.rvec[0], b.rvec[0]) &&
         same_bits(a.rvec[1], b.rvec[1]) && same_bits(a.rvec[2], b.rvec[2]) && same_bits(a.tvec[0], b.tvec[0]) &&
         same_bits(a.tvec[1], b.tvec[1]) && same_bits(a.tvec[2], b.tvec[2]) && points(a.keypoints, b.keypoints) &&
         points(a.centers, b.centers) && points(a.centroids, b.centroids) && points(a.corners, b.corners) &&
         same_points(&a.center, &b.center, 1, same_bits) && a.fully_visible == b.fully_visible &&
         same_bits(a.edge_px, b.edge_px);
}

bool same_frame(const FrameDetections& a, const FrameDetections& b) {
  if (a.width != b.width || a.height != b.height || a.analysed != b.analysed ||
      a.detections.size() != b.detections.size())
    return false;
  for (std::size_t i = 0; i < a.detections.size(); ++i)
    if (!same_detection(a.detections[i], b.detections[i], same_bits)) return false;
  return true;
}

// ---- the JSON, parsed back

// A double as the JSON holds it: the same number, or null for NaN and the infinities.
void check_number(const nlohmann::json& j, double x, const char* what) {
  if (!std::isfinite(x)) {
    check(j.is_null(), what);
    return;
  }
  check(j.is_number() && j.get<double>() == x && std::signbit(j.get<double>()) == std::signbit(x), what);
}

void check_points(const nlohmann::json& j, const cv::Point2d* p, std::size_t n, const char* what) {
  check(j.is_array() && j.size() == n, what);
  for (std::size_t i = 0; i < n; ++i) {
    check(j[i].is_array() && j[i].size() == 2, what);
    check_number(j[i][0], p[i].x, what);
    check_number(j[i][1], p[i].y, what);
  }
}

void check_vec(const nlohmann::json& j, const cv::Vec3d& v, const char* what) {
  check(j.is_array() && j.size() == 3, what);
  for (int i = 0; i < 3; ++i) check_number(j[i], v[i], what);
}

void check_detection_json(const nlohmann::json& j, const Detection& d) {
  check(j.is_object() && j.at("family") == d.family.name(), "JSON family");
  const nlohmann::json& id = j.at("id");
  if (d.id.fits_53_bits())
    check(id.is_number_unsigned() && id.get<std::uint64_t>() == d.id.low(), "JSON id (a number under 2^53)");
  else
    check(id.is_string() && TagId::parse(id.get<std::string>()) == d.id && id.get<std::string>() == d.id.to_decimal(),
          "JSON id (a decimal string from 2^53)");
  check(j.at("id_hex").is_string() && TagId::parse(j.at("id_hex").get<std::string>()) == d.id, "JSON id_hex");
  check_points(j.at("keypoints"), d.keypoints.data(), 4, "JSON keypoints");
  check_points(j.at("corners"), d.corners.data(), 4, "JSON corners");
  check_points(j.at("centroids"), d.centroids.data(), d.centroids.size(), "JSON centroids");
  const nlohmann::json& center = j.at("center");
  check(center.is_array() && center.size() == 2, "JSON center");
  check_number(center[0], d.center.x, "JSON center");
  check_number(center[1], d.center.y, "JSON center");
  const nlohmann::json& pose = j.at("pose");
  check_vec(pose.at("rvec"), d.rvec, "JSON rvec");
  check_vec(pose.at("tvec"), d.tvec, "JSON tvec");
  check(pose.at("calibrated") == d.calibrated, "JSON calibrated");
  check_number(pose.at("tag_size"), d.tag_size, "JSON tag_size");
  check_number(j.at("decode_error"), d.decode_error, "JSON decode_error");
  check_number(j.at("worst_cell"), d.worst_cell, "JSON worst_cell");
  check_number(j.at("edge_score"), d.edge_score, "JSON edge_score");
  check_number(j.at("reprojection_error"), d.reprojection_error, "JSON reprojection_error");
  check(j.at("from_outline") == d.from_outline, "JSON from_outline");
}

void check_time(const nlohmann::json& j, GstClockTime t, const char* what) {
  if (GST_CLOCK_TIME_IS_VALID(t))
    check(j.is_number_unsigned() && j.get<std::uint64_t>() == t, what);
  else
    check(j.is_null(), what);
}

// The buffer's JSON line, dumped and parsed back, against what its meta holds.
void check_json(GstBuffer* buffer, const GstSegment& segment, guint64 frame, const FrameDetections& expected) {
  const std::optional<nlohmann::ordered_json> line = lftag::gst::buffer_json(buffer, segment, frame);
  check(line.has_value(), "no JSON for a buffer with an LFTagMeta");
  const nlohmann::json j = nlohmann::json::parse(line->dump());  // throws (a crash) on invalid JSON
  check(j.at("frame") == frame, "JSON frame");
  check_time(j.at("pts"), GST_BUFFER_PTS(buffer), "JSON pts");
  check_time(j.at("dts"), GST_BUFFER_DTS(buffer), "JSON dts");
  check_time(j.at("duration"), GST_BUFFER_DURATION(buffer), "JSON duration");
  if (GST_BUFFER_PTS_IS_VALID(buffer))
    check(j.at("time").is_number() && j.at("time").get<double>() == double(GST_BUFFER_PTS(buffer)) / GST_SECOND,
          "JSON time");
  else
    check(j.at("time").is_null(), "JSON time");
  const bool in_time = segment.format == GST_FORMAT_TIME && GST_BUFFER_PTS_IS_VALID(buffer);
  check_time(
      j.at("running_time"),
      in_time ? gst_segment_to_running_time(&segment, GST_FORMAT_TIME, GST_BUFFER_PTS(buffer)) : GST_CLOCK_TIME_NONE,
      "JSON running_time");
  check_time(
      j.at("stream_time"),
      in_time ? gst_segment_to_stream_time(&segment, GST_FORMAT_TIME, GST_BUFFER_PTS(buffer)) : GST_CLOCK_TIME_NONE,
      "JSON stream_time");
  check(j.at("width") == expected.width && j.at("height") == expected.height, "JSON width, height");
  const nlohmann::json& detections = j.at("detections");
  check(detections.is_array() && detections.size() == expected.detections.size(), "JSON detections");
  for (std::size_t i = 0; i < expected.detections.size(); ++i)
    check_detection_json(detections[i], expected.detections[i]);
}

// ---- binary mode

Detection read_detection(Reader& in) {
  Detection d;
  const std::uint8_t shape = in.u8();
  d.family = lftag::Family(lftag::Family::kMinN + shape % (lftag::Family::kMaxN - lftag::Family::kMinN + 1));
  const std::uint64_t high = in.u64(), low = in.u64();
  // Mostly an id of the family; the reader does not check that, so any id too.
  d.id = shape & 128 ? TagId(high, low) : TagId(high & d.family.max_id().high(), low & d.family.max_id().low());
  const int n = d.family.n();
  d.centroids.resize(in.u8() % (n * n + 3));
  for (cv::Point2d& p : d.centroids) p = {raw_double(in), raw_double(in)};
  for (cv::Point2d& p : d.keypoints) p = {raw_double(in), raw_double(in)};
  for (cv::Point2d& p : d.corners) p = {raw_double(in), raw_double(in)};
  d.center = {raw_double(in), raw_double(in)};
  for (int i = 0; i < 3; ++i) d.rvec[i] = raw_double(in);
  for (int i = 0; i < 3; ++i) d.tvec[i] = raw_double(in);
  d.tag_size = raw_double(in);
  d.decode_error = raw_double(in);
  d.worst_cell = raw_double(in);
  d.edge_score = raw_double(in);
  d.reprojection_error = raw_double(in);
  const std::uint8_t flags = in.u8();
  d.calibrated = flags & 1;
  d.from_outline = flags & 2;
  return d;
}

void binary(Reader& in) {
  FrameDetections frame;
  frame.width = gint(in.u32());
  frame.height = gint(in.u32());
  const std::uint8_t flags = in.u8();
  frame.analysed = flags & 1;
  for (int n = in.u8() % 5; n > 0; --n) frame.detections.push_back(read_detection(in));

  for (const Detection& d : frame.detections) {
    GstStructure* s = lftag::gst::detection_structure(d);
    check(same_detection(lftag::gst::detection_from_structure(s), d, same_bits), "structure round trip");
    gchar* text = gst_structure_to_string(s);
    GstStructure* parsed = gst_structure_from_string(text, nullptr);
    if (!parsed) std::fprintf(stderr, "structure text: %s\n", text);
    check(parsed != nullptr, "a detection structure's text does not parse");
    check(same_detection(lftag::gst::detection_from_structure(parsed), d, same_value), "structure text round trip");
    gst_structure_free(parsed);
    g_free(text);
    gst_structure_free(s);
  }

  GstBuffer* buffer = gst_buffer_new();
  GST_BUFFER_PTS(buffer) = flags & 2 ? in.u64() : GST_CLOCK_TIME_NONE;
  GST_BUFFER_DTS(buffer) = flags & 4 ? in.u64() : GST_CLOCK_TIME_NONE;
  GST_BUFFER_DURATION(buffer) = flags & 8 ? in.u64() : GST_CLOCK_TIME_NONE;
  lftag::gst::add_detection_meta(buffer, frame.width, frame.height, frame.detections, frame.analysed);
  const std::optional<FrameDetections> read = lftag::gst::read_detection_meta(buffer);
  check(read.has_value() && same_frame(*read, frame), "LFTagMeta round trip");

  GstSegment segment;
  gst_segment_init(&segment, flags & 16 ? GST_FORMAT_TIME : GST_FORMAT_BYTES);
  if (flags & 16) {
    segment.rate = flags & 32 ? 2.0 : 1.0;
    segment.start = in.u32() * GST_MSECOND;
    segment.time = in.u32() * GST_MSECOND;
    segment.base = in.u32() * GST_MSECOND;
  }
  check_json(buffer, segment, in.u64(), frame);
  gst_buffer_unref(buffer);
}

// ---- text mode

void copy_fields(const GstStructure* from, GstStructure* to) {
  gst_structure_foreach(
      from,
      [](GQuark field, const GValue* value, gpointer to) -> gboolean {
        gst_structure_id_set_value(static_cast<GstStructure*>(to), field, value);
        return TRUE;
      },
      to);
}

void text(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);  // up to its first NUL
  GstStructure* s;
  {
    const lftag::fuzz::Tolerance tolerance;
    s = gst_structure_from_string(text.c_str(), nullptr);
  }
  if (!s) return;

  try {
    const Detection d = lftag::gst::detection_from_structure(s);
    GstStructure* again = lftag::gst::detection_structure(d);
    check(same_detection(lftag::gst::detection_from_structure(again), d, same_bits), "detection read, written, read");
    gst_structure_free(again);
  } catch (const std::invalid_argument&) {
  }
  try {
    const MarkerTruth t = lftag::gst::truth_from_structure(s);
    GstStructure* again = lftag::gst::truth_structure(t);
    check(same_truth(lftag::gst::truth_from_structure(again), t), "truth read, written, read");
    gst_structure_free(again);
  } catch (const std::invalid_argument&) {
  }

  // The same fields as both metas of a buffer, as an element upstream could attach them.
  GstBuffer* buffer = gst_buffer_new();
  lftag::gst::detection_meta_info();
  lftag::gst::truth_meta_info();
  copy_fields(s, gst_custom_meta_get_structure(gst_buffer_add_custom_meta(buffer, LFTAG_META_NAME)));
  copy_fields(s, gst_custom_meta_get_structure(gst_buffer_add_custom_meta(buffer, LFTAG_TRUTH_META_NAME)));
  gst_structure_free(s);
  try {
    const std::optional<FrameDetections> frame = lftag::gst::read_detection_meta(buffer);
    check(frame.has_value(), "an LFTagMeta not found");
    GstBuffer* copy = gst_buffer_new();
    lftag::gst::add_detection_meta(copy, frame->width, frame->height, frame->detections, frame->analysed);
    const std::optional<FrameDetections> again = lftag::gst::read_detection_meta(copy);
    check(again.has_value() && same_frame(*again, *frame), "LFTagMeta read, written, read");
    gst_buffer_unref(copy);
    GstSegment segment;
    gst_segment_init(&segment, GST_FORMAT_TIME);
    check_json(buffer, segment, 0, *frame);
  } catch (const std::invalid_argument&) {
  }
  try {
    const std::optional<FrameTruth> truth = lftag::gst::read_truth_meta(buffer);
    check(truth.has_value(), "an LFTagTruthMeta not found");
    GstBuffer* copy = gst_buffer_new();
    lftag::gst::add_truth_meta(copy, truth->camera, truth->markers);
    const std::optional<FrameTruth> again = lftag::gst::read_truth_meta(copy);
    check(again.has_value() && again->markers.size() == truth->markers.size(), "LFTagTruthMeta read, written, read");
    const lftag::Camera &a = again->camera, &b = truth->camera;
    check(a.width == b.width && a.height == b.height && same_bits(a.fx, b.fx) && same_bits(a.fy, b.fy) &&
              same_bits(a.cx, b.cx) && same_bits(a.cy, b.cy) && a.distortion.size() == b.distortion.size(),
          "LFTagTruthMeta camera read, written, read");
    for (std::size_t i = 0; i < a.distortion.size(); ++i)
      check(same_bits(a.distortion[i], b.distortion[i]), "LFTagTruthMeta distortion read, written, read");
    for (std::size_t i = 0; i < truth->markers.size(); ++i)
      check(same_truth(again->markers[i], truth->markers[i]), "LFTagTruthMeta marker read, written, read");
    gst_buffer_unref(copy);
  } catch (const std::invalid_argument&) {
  }
  gst_buffer_unref(buffer);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  lftag::fuzz::start_gstreamer();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  if (data[0] & 1) {
    text(data + 1, size - 1);
  } else {
    Reader in(data + 1, size - 1);
    binary(in);
  }
  return 0;
}
