// SPDX-License-Identifier: LGPL-2.1-or-later
#include "metaconversion.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <memory>
#include <stdexcept>
#include <string>

#include <gst/video/video.h>

namespace lftag::gst {
namespace {

const GstMetaInfo* register_custom(const char* name) {
  // Tests link this code and also load the plugin that holds another copy of it.
  if (const GstMetaInfo* info = gst_meta_get_info(name)) return info;
  // No tags: every element that copies metadata (basetransform, videoconvert,
  // videoscale, encoders) keeps a tag-less meta as it is (the truth meta).
  const gchar* no_tags[] = {nullptr};
  return gst_meta_register_custom(name, no_tags, nullptr, nullptr, nullptr);
}

// ---- writing

void append_double(GValue* array, double x) {
  GValue v = G_VALUE_INIT;
  g_value_init(&v, G_TYPE_DOUBLE);
  g_value_set_double(&v, x);
  gst_value_array_append_and_take_value(array, &v);
}

void point_value(GValue* out, cv::Point2d p) {
  gst_value_array_init(out, 2);
  append_double(out, p.x);
  append_double(out, p.y);
}

void set_point(GstStructure* s, const char* field, cv::Point2d p) {
  GValue v = G_VALUE_INIT;
  point_value(&v, p);
  gst_structure_take_value(s, field, &v);
}

template <class Points>
void set_points(GstStructure* s, const char* field, const Points& points) {
  GValue list = G_VALUE_INIT;
  gst_value_array_init(&list, guint(points.size()));
  for (const cv::Point2d& p : points) {
    GValue v = G_VALUE_INIT;
    point_value(&v, p);
    gst_value_array_append_and_take_value(&list, &v);
  }
  gst_structure_take_value(s, field, &list);
}

template <class Doubles>
void set_doubles(GstStructure* s, const char* field, const Doubles& values) {
  GValue list = G_VALUE_INIT;
  gst_value_array_init(&list, guint(std::size(values)));
  for (double x : values) append_double(&list, x);
  gst_structure_take_value(s, field, &list);
}

void set_vec3(GstStructure* s, const char* field, const cv::Vec3d& v) {
  set_doubles(s, field, std::vector<double>{v[0], v[1], v[2]});
}

void set_structures(GstStructure* s, const char* field, const std::vector<GstStructure*>& items) {
  GValue list = G_VALUE_INIT;
  gst_value_array_init(&list, guint(items.size()));
  for (GstStructure* item : items) {
    GValue v = G_VALUE_INIT;
    g_value_init(&v, GST_TYPE_STRUCTURE);
    g_value_take_boxed(&v, item);
    gst_value_array_append_and_take_value(&list, &v);
  }
  gst_structure_take_value(s, field, &list);
}

void set_identity(GstStructure* s, const Family& family, TagId id) {
  gst_structure_set(s, LFTAG_FIELD_FAMILY, G_TYPE_STRING, family.name().c_str(), nullptr);
  if (id.fits_u64()) gst_structure_set(s, LFTAG_FIELD_ID, G_TYPE_UINT64, guint64(id.low()), nullptr);
  gst_structure_set(s, LFTAG_FIELD_ID_STRING, G_TYPE_STRING, id.to_decimal().c_str(), nullptr);
}

// The fields a detection and a marker's truth share: which marker, where and how posed.
template <class Marker>
void set_marker(GstStructure* s, const Marker& m) {
  set_identity(s, m.family, m.id);
  set_points(s, LFTAG_FIELD_KEYPOINTS, m.keypoints);
  set_points(s, LFTAG_FIELD_CENTROIDS, m.centroids);
  set_points(s, LFTAG_FIELD_CORNERS, m.corners);
  set_point(s, LFTAG_FIELD_CENTER, m.center);
  set_vec3(s, LFTAG_FIELD_RVEC, m.rvec);
  set_vec3(s, LFTAG_FIELD_TVEC, m.tvec);
}

// ---- reading

[[noreturn]] void malformed(const GstStructure* s, const char* field, const char* expected) {
  throw std::invalid_argument(std::string(gst_structure_get_name(s)) + ": field '" + field + "' " + expected);
}

const GValue* value_of(const GstStructure* s, const char* field) {
  const GValue* v = gst_structure_get_value(s, field);
  if (!v) malformed(s, field, "is missing");
  return v;
}

std::vector<double> doubles_of(const GValue* v) {
  std::vector<double> out;
  if (!GST_VALUE_HOLDS_ARRAY(v)) return out;
  for (guint i = 0; i < gst_value_array_get_size(v); ++i) {
    const GValue* x = gst_value_array_get_value(v, i);
    if (!G_VALUE_HOLDS_DOUBLE(x)) return {};
    out.push_back(g_value_get_double(x));
  }
  return out;
}

std::vector<double> get_doubles(const GstStructure* s, const char* field, std::size_t count) {
  std::vector<double> d = doubles_of(value_of(s, field));
  if (d.size() != count) malformed(s, field, ("is not an array of " + std::to_string(count) + " doubles").c_str());
  return d;
}

cv::Point2d get_point(const GstStructure* s, const char* field) {
  const std::vector<double> d = get_doubles(s, field, 2);
  return {d[0], d[1]};
}

std::vector<cv::Point2d> get_points(const GstStructure* s, const char* field) {
  const GValue* v = value_of(s, field);
  if (!GST_VALUE_HOLDS_ARRAY(v)) malformed(s, field, "is not an array of points");
  std::vector<cv::Point2d> points;
  for (guint i = 0; i < gst_value_array_get_size(v); ++i) {
    const std::vector<double> d = doubles_of(gst_value_array_get_value(v, i));
    if (d.size() != 2) malformed(s, field, "is not an array of points");
    points.emplace_back(d[0], d[1]);
  }
  return points;
}

template <std::size_t N>
std::array<cv::Point2d, N> get_point_array(const GstStructure* s, const char* field) {
  const std::vector<cv::Point2d> points = get_points(s, field);
  if (points.size() != N) malformed(s, field, ("does not hold " + std::to_string(N) + " points").c_str());
  std::array<cv::Point2d, N> out;
  std::copy(points.begin(), points.end(), out.begin());
  return out;
}

cv::Vec3d get_vec3(const GstStructure* s, const char* field) {
  const std::vector<double> d = get_doubles(s, field, 3);
  return {d[0], d[1], d[2]};
}

double get_double(const GstStructure* s, const char* field) {
  double x;
  if (!gst_structure_get_double(s, field, &x)) malformed(s, field, "is not a double");
  return x;
}

bool get_boolean(const GstStructure* s, const char* field) {
  gboolean b;
  if (!gst_structure_get_boolean(s, field, &b)) malformed(s, field, "is not a boolean");
  return b;
}

int get_int(const GstStructure* s, const char* field) {
  gint i;
  if (!gst_structure_get_int(s, field, &i)) malformed(s, field, "is not an integer");
  return i;
}

std::string get_string(const GstStructure* s, const char* field) {
  const gchar* text = gst_structure_get_string(s, field);
  if (!text) malformed(s, field, "is not a string");
  return text;
}

Family get_family(const GstStructure* s) {
  try {
    return Family::parse(get_string(s, LFTAG_FIELD_FAMILY));
  } catch (const std::invalid_argument&) {
    malformed(s, LFTAG_FIELD_FAMILY, "does not name a family");
  }
}

TagId get_id(const GstStructure* s) {
  TagId id;
  try {
    id = TagId::parse(get_string(s, LFTAG_FIELD_ID_STRING));
  } catch (const std::invalid_argument&) {
    malformed(s, LFTAG_FIELD_ID_STRING, "is not a decimal id");
  }
  guint64 low;
  const bool has_u64 = gst_structure_get_uint64(s, LFTAG_FIELD_ID, &low);
  if (has_u64 != id.fits_u64() || (has_u64 && low != id.low()))
    malformed(s, LFTAG_FIELD_ID, "disagrees with id-string");
  return id;
}

const GstStructure* meta_structure(GstBuffer* buffer, const char* name) {
  GstCustomMeta* meta = gst_buffer_get_custom_meta(buffer, name);
  return meta ? gst_custom_meta_get_structure(meta) : nullptr;
}

template <class Read>
auto read_list(const GstStructure* s, const char* field, const char* item_name, Read read) {
  const GValue* v = value_of(s, field);
  if (!GST_VALUE_HOLDS_ARRAY(v)) malformed(s, field, "is not an array");
  std::vector<decltype(read(s))> out;
  for (guint i = 0; i < gst_value_array_get_size(v); ++i) {
    const GValue* item = gst_value_array_get_value(v, i);
    if (!GST_VALUE_HOLDS_STRUCTURE(item) || !gst_structure_has_name(gst_value_get_structure(item), item_name))
      malformed(s, field, ("holds something other than " + std::string(item_name) + " structures").c_str());
    out.push_back(read(gst_value_get_structure(item)));
  }
  return out;
}

// ---- following the frame through videoscale

using StructurePtr = std::unique_ptr<GstStructure, decltype(&gst_structure_free)>;

// A point of the frame in the frame scaled by sx, sy. Pixel centres are at integer
// coordinates, so it is the frames' edges that map onto each other.
cv::Point2d scaled(cv::Point2d p, double sx, double sy) { return {(p.x + 0.5) * sx - 0.5, (p.y + 0.5) * sy - 0.5}; }

StructurePtr scaled_detection(const GstStructure* in, double sx, double sy) {
  StructurePtr out(gst_structure_copy(in), gst_structure_free);
  for (const char* field : {LFTAG_FIELD_KEYPOINTS, LFTAG_FIELD_CENTROIDS, LFTAG_FIELD_CORNERS}) {
    std::vector<cv::Point2d> points = get_points(in, field);
    for (cv::Point2d& p : points) p = scaled(p, sx, sy);
    set_points(out.get(), field, points);
  }
  set_point(out.get(), LFTAG_FIELD_CENTER, scaled(get_point(in, LFTAG_FIELD_CENTER), sx, sy));
  return out;
}

// The LFTagMeta's copy into `dest`: as it is, or (videoscale's "gst-video-scale") with its
// points and frame size in the scaled frame. Poses are the camera's and do not change;
// nor do the errors measured in pixels of the analysed frame. Any other transform, and a
// meta that cannot be read, is not copied: dropped rather than left wrong.
gboolean transform_detection_meta(GstBuffer* dest, GstCustomMeta* meta, GstBuffer*, GQuark type, gpointer data,
                                  gpointer) {
  const GstStructure* in = gst_custom_meta_get_structure(meta);
  StructurePtr out(gst_structure_copy(in), gst_structure_free);
  if (GST_VIDEO_META_TRANSFORM_IS_SCALE(type)) {
    const auto* t = static_cast<const GstVideoMetaTransform*>(data);
    const int in_w = GST_VIDEO_INFO_WIDTH(t->in_info), in_h = GST_VIDEO_INFO_HEIGHT(t->in_info);
    if (in_w <= 0 || in_h <= 0) return FALSE;
    const double sx = double(GST_VIDEO_INFO_WIDTH(t->out_info)) / in_w;
    const double sy = double(GST_VIDEO_INFO_HEIGHT(t->out_info)) / in_h;
    try {
      const GValue* list = value_of(in, LFTAG_META_FIELD_DETECTIONS);
      if (!GST_VALUE_HOLDS_ARRAY(list)) return FALSE;
      std::vector<StructurePtr> detections;
      for (guint i = 0; i < gst_value_array_get_size(list); ++i) {
        const GValue* item = gst_value_array_get_value(list, i);
        if (!GST_VALUE_HOLDS_STRUCTURE(item)) return FALSE;
        detections.push_back(scaled_detection(gst_value_get_structure(item), sx, sy));
      }
      std::vector<GstStructure*> items;
      for (StructurePtr& d : detections) items.push_back(d.release());
      set_structures(out.get(), LFTAG_META_FIELD_DETECTIONS, items);
      gst_structure_set(out.get(), LFTAG_META_FIELD_WIDTH, G_TYPE_INT,
                        int(std::lround(get_int(in, LFTAG_META_FIELD_WIDTH) * sx)), LFTAG_META_FIELD_HEIGHT, G_TYPE_INT,
                        int(std::lround(get_int(in, LFTAG_META_FIELD_HEIGHT) * sy)), nullptr);
    } catch (const std::invalid_argument&) {
      return FALSE;
    }
  } else if (!GST_META_TRANSFORM_IS_COPY(type)) {
    return FALSE;
  }
  GstStructure* copy = gst_custom_meta_get_structure(gst_buffer_add_custom_meta(dest, LFTAG_META_NAME));
  gst_structure_foreach(
      out.get(),
      [](GQuark field, const GValue* value, gpointer s) -> gboolean {
        gst_structure_id_set_value(static_cast<GstStructure*>(s), field, value);
        return TRUE;
      },
      copy);
  return TRUE;
}

}  // namespace

const GstMetaInfo* detection_meta_info() {
  static const GstMetaInfo* info = []() -> const GstMetaInfo* {
    if (const GstMetaInfo* registered = gst_meta_get_info(LFTAG_META_NAME)) return registered;
    // Tagged "video" and "size" as GstVideoRegionOfInterestMeta is: videoconvert, encoders
    // and decoders copy it, videoscale scales it (transform_detection_meta), and elements
    // that crop or box the frame (videocrop, videobox), which could not move its points,
    // drop it.
    const gchar* tags[] = {GST_META_TAG_VIDEO_STR, GST_META_TAG_VIDEO_SIZE_STR, nullptr};
    return gst_meta_register_custom(LFTAG_META_NAME, tags, transform_detection_meta, nullptr, nullptr);
  }();
  return info;
}

const GstMetaInfo* truth_meta_info() {
  static const GstMetaInfo* info = register_custom(LFTAG_TRUTH_META_NAME);
  return info;
}

GstStructure* detection_structure(const Detection& d, const TrackInfo* track) {
  GstStructure* s = gst_structure_new_empty(LFTAG_DETECTION_STRUCTURE_NAME);
  set_marker(s, d);
  gst_structure_set(s, LFTAG_FIELD_TAG_SIZE, G_TYPE_DOUBLE, d.tag_size, LFTAG_FIELD_CALIBRATED, G_TYPE_BOOLEAN,
                    gboolean(d.calibrated), LFTAG_FIELD_DECODE_ERROR, G_TYPE_DOUBLE, d.decode_error,
                    LFTAG_FIELD_WORST_CELL, G_TYPE_DOUBLE, d.worst_cell, LFTAG_FIELD_NOISE_MARGIN, G_TYPE_DOUBLE,
                    d.noise_margin, LFTAG_FIELD_EDGE_SCORE, G_TYPE_DOUBLE, d.edge_score, LFTAG_FIELD_FROM_OUTLINE,
                    G_TYPE_BOOLEAN, gboolean(d.from_outline), LFTAG_FIELD_REPROJECTION_ERROR, G_TYPE_DOUBLE,
                    d.reprojection_error, nullptr);
  set_vec3(s, LFTAG_FIELD_ALTERNATIVE_RVEC, d.alternative_rvec);
  set_vec3(s, LFTAG_FIELD_ALTERNATIVE_TVEC, d.alternative_tvec);
  gst_structure_set(s, LFTAG_FIELD_ALTERNATIVE_REPROJECTION_ERROR, G_TYPE_DOUBLE, d.alternative_reprojection_error,
                    LFTAG_FIELD_AMBIGUITY_RATIO, G_TYPE_DOUBLE, d.ambiguity_ratio, nullptr);
  if (track) {
    gst_structure_set(s, LFTAG_FIELD_TRACK_ID, G_TYPE_UINT64, guint64(track->id), LFTAG_FIELD_TRACK_STATE,
                      G_TYPE_STRING, track_state_name(track->state), LFTAG_FIELD_TRACK_AGE, G_TYPE_DOUBLE, track->age(),
                      LFTAG_FIELD_FIRST_SEEN, G_TYPE_DOUBLE, track->first_seen, LFTAG_FIELD_LAST_SEEN, G_TYPE_DOUBLE,
                      track->last_seen, LFTAG_FIELD_POSE_FLIPPED, G_TYPE_BOOLEAN, gboolean(track->flipped), nullptr);
    if (track->smoothed) {
      set_vec3(s, LFTAG_FIELD_SMOOTHED_RVEC, track->smoothed_rvec);
      set_vec3(s, LFTAG_FIELD_SMOOTHED_TVEC, track->smoothed_tvec);
    }
  }
  return s;
}

GstStructure* truth_structure(const MarkerTruth& t) {
  GstStructure* s = gst_structure_new_empty(LFTAG_TRUTH_STRUCTURE_NAME);
  set_marker(s, t);
  set_points(s, LFTAG_FIELD_CENTERS, t.centers);
  gst_structure_set(s, LFTAG_FIELD_TAG_SIZE, G_TYPE_DOUBLE, t.tag_size, LFTAG_FIELD_FULLY_VISIBLE, G_TYPE_BOOLEAN,
                    gboolean(t.fully_visible), LFTAG_FIELD_EDGE_PX, G_TYPE_DOUBLE, t.edge_px, nullptr);
  return s;
}

void set_detections(GstStructure* s, const char* field, const std::vector<Detection>& detections,
                    const std::vector<TrackInfo>* tracks) {
  std::vector<GstStructure*> items;
  for (std::size_t i = 0; i < detections.size(); ++i)
    items.push_back(detection_structure(detections[i], tracks && i < tracks->size() ? &(*tracks)[i] : nullptr));
  set_structures(s, field, items);
}

void add_detection_meta(GstBuffer* buffer, int width, int height, const std::vector<Detection>& detections,
                        bool analysed, const std::vector<TrackInfo>* tracks) {
  detection_meta_info();
  GstStructure* s = gst_custom_meta_get_structure(gst_buffer_add_custom_meta(buffer, LFTAG_META_NAME));
  gst_structure_set(s, LFTAG_META_FIELD_WIDTH, G_TYPE_INT, width, LFTAG_META_FIELD_HEIGHT, G_TYPE_INT, height,
                    LFTAG_META_FIELD_ANALYSED, G_TYPE_BOOLEAN, gboolean(analysed), nullptr);
  set_detections(s, LFTAG_META_FIELD_DETECTIONS, detections, tracks);
}

void add_truth_meta(GstBuffer* buffer, const Camera& camera, const std::vector<MarkerTruth>& markers) {
  truth_meta_info();
  GstStructure* s = gst_custom_meta_get_structure(gst_buffer_add_custom_meta(buffer, LFTAG_TRUTH_META_NAME));
  gst_structure_set(s, LFTAG_META_FIELD_WIDTH, G_TYPE_INT, camera.width, LFTAG_META_FIELD_HEIGHT, G_TYPE_INT,
                    camera.height, LFTAG_META_FIELD_FX, G_TYPE_DOUBLE, camera.fx, LFTAG_META_FIELD_FY, G_TYPE_DOUBLE,
                    camera.fy, LFTAG_META_FIELD_CX, G_TYPE_DOUBLE, camera.cx, LFTAG_META_FIELD_CY, G_TYPE_DOUBLE,
                    camera.cy, nullptr);
  set_doubles(s, LFTAG_META_FIELD_DISTORTION, camera.distortion);
  std::vector<GstStructure*> items;
  for (const MarkerTruth& t : markers) items.push_back(truth_structure(t));
  set_structures(s, LFTAG_META_FIELD_MARKERS, items);
}

Detection detection_from_structure(const GstStructure* s) {
  Detection d;
  d.family = get_family(s);
  d.id = get_id(s);
  d.keypoints = get_point_array<4>(s, LFTAG_FIELD_KEYPOINTS);
  d.centroids = get_points(s, LFTAG_FIELD_CENTROIDS);
  d.corners = get_point_array<4>(s, LFTAG_FIELD_CORNERS);
  d.center = get_point(s, LFTAG_FIELD_CENTER);
  d.rvec = get_vec3(s, LFTAG_FIELD_RVEC);
  d.tvec = get_vec3(s, LFTAG_FIELD_TVEC);
  d.tag_size = get_double(s, LFTAG_FIELD_TAG_SIZE);
  d.calibrated = get_boolean(s, LFTAG_FIELD_CALIBRATED);
  d.decode_error = get_double(s, LFTAG_FIELD_DECODE_ERROR);
  // Optional: structures from before it was added read as 0.
  if (!gst_structure_get_double(s, LFTAG_FIELD_WORST_CELL, &d.worst_cell)) d.worst_cell = 0;
  if (!gst_structure_get_double(s, LFTAG_FIELD_NOISE_MARGIN, &d.noise_margin)) d.noise_margin = 0;  // optional too
  d.edge_score = get_double(s, LFTAG_FIELD_EDGE_SCORE);
  gboolean from_outline = FALSE;  // optional, as worst-cell
  if (gst_structure_get_boolean(s, LFTAG_FIELD_FROM_OUTLINE, &from_outline)) d.from_outline = from_outline;
  d.reprojection_error = get_double(s, LFTAG_FIELD_REPROJECTION_ERROR);
  // Optional, as worst-cell: structures from before they were added have no second pose.
  if (gst_structure_has_field(s, LFTAG_FIELD_ALTERNATIVE_RVEC)) {
    d.alternative_rvec = get_vec3(s, LFTAG_FIELD_ALTERNATIVE_RVEC);
    d.alternative_tvec = get_vec3(s, LFTAG_FIELD_ALTERNATIVE_TVEC);
    d.alternative_reprojection_error = get_double(s, LFTAG_FIELD_ALTERNATIVE_REPROJECTION_ERROR);
    d.ambiguity_ratio = get_double(s, LFTAG_FIELD_AMBIGUITY_RATIO);
  }
  return d;
}

std::optional<TrackInfo> track_from_structure(const GstStructure* s) {
  if (!gst_structure_has_field(s, LFTAG_FIELD_TRACK_ID)) return std::nullopt;
  TrackInfo t;
  guint64 id;
  if (!gst_structure_get_uint64(s, LFTAG_FIELD_TRACK_ID, &id)) malformed(s, LFTAG_FIELD_TRACK_ID, "is not a guint64");
  t.id = id;
  const std::string state = get_string(s, LFTAG_FIELD_TRACK_STATE);
  if (state == track_state_name(TrackState::measured))
    t.state = TrackState::measured;
  else if (state == track_state_name(TrackState::predicted))
    t.state = TrackState::predicted;
  else
    malformed(s, LFTAG_FIELD_TRACK_STATE, "is neither \"measured\" nor \"predicted\"");
  t.first_seen = get_double(s, LFTAG_FIELD_FIRST_SEEN);
  t.last_seen = get_double(s, LFTAG_FIELD_LAST_SEEN);
  t.time = t.first_seen + get_double(s, LFTAG_FIELD_TRACK_AGE);
  t.flipped = get_boolean(s, LFTAG_FIELD_POSE_FLIPPED);
  if (gst_structure_has_field(s, LFTAG_FIELD_SMOOTHED_RVEC)) {
    t.smoothed = true;
    t.smoothed_rvec = get_vec3(s, LFTAG_FIELD_SMOOTHED_RVEC);
    t.smoothed_tvec = get_vec3(s, LFTAG_FIELD_SMOOTHED_TVEC);
  }
  return t;
}

MarkerTruth truth_from_structure(const GstStructure* s) {
  MarkerTruth t;
  t.family = get_family(s);
  t.id = get_id(s);
  t.keypoints = get_points(s, LFTAG_FIELD_KEYPOINTS);
  t.centers = get_points(s, LFTAG_FIELD_CENTERS);
  t.centroids = get_points(s, LFTAG_FIELD_CENTROIDS);
  t.corners = get_points(s, LFTAG_FIELD_CORNERS);
  t.center = get_point(s, LFTAG_FIELD_CENTER);
  t.rvec = get_vec3(s, LFTAG_FIELD_RVEC);
  t.tvec = get_vec3(s, LFTAG_FIELD_TVEC);
  t.tag_size = get_double(s, LFTAG_FIELD_TAG_SIZE);
  t.fully_visible = get_boolean(s, LFTAG_FIELD_FULLY_VISIBLE);
  t.edge_px = get_double(s, LFTAG_FIELD_EDGE_PX);
  return t;
}

std::optional<FrameDetections> read_detection_meta(GstBuffer* buffer) {
  const GstStructure* s = meta_structure(buffer, LFTAG_META_NAME);
  if (!s) return std::nullopt;
  FrameDetections frame;
  frame.width = get_int(s, LFTAG_META_FIELD_WIDTH);
  frame.height = get_int(s, LFTAG_META_FIELD_HEIGHT);
  gboolean analysed = TRUE;  // metas before the field existed were always analysed
  if (gst_structure_has_field(s, LFTAG_META_FIELD_ANALYSED) &&
      !gst_structure_get_boolean(s, LFTAG_META_FIELD_ANALYSED, &analysed))
    malformed(s, LFTAG_META_FIELD_ANALYSED, "is not a boolean");
  frame.analysed = analysed;
  frame.detections =
      read_list(s, LFTAG_META_FIELD_DETECTIONS, LFTAG_DETECTION_STRUCTURE_NAME, detection_from_structure);
  frame.tracks = read_list(s, LFTAG_META_FIELD_DETECTIONS, LFTAG_DETECTION_STRUCTURE_NAME, track_from_structure);
  return frame;
}

std::optional<FrameTruth> read_truth_meta(GstBuffer* buffer) {
  const GstStructure* s = meta_structure(buffer, LFTAG_TRUTH_META_NAME);
  if (!s) return std::nullopt;
  FrameTruth frame;
  frame.camera = Camera::pinhole(get_double(s, LFTAG_META_FIELD_FX), get_double(s, LFTAG_META_FIELD_FY),
                                 get_double(s, LFTAG_META_FIELD_CX), get_double(s, LFTAG_META_FIELD_CY),
                                 get_int(s, LFTAG_META_FIELD_WIDTH), get_int(s, LFTAG_META_FIELD_HEIGHT));
  const GValue* distortion = value_of(s, LFTAG_META_FIELD_DISTORTION);
  frame.camera.distortion = doubles_of(distortion);
  if (!GST_VALUE_HOLDS_ARRAY(distortion) || frame.camera.distortion.size() != gst_value_array_get_size(distortion))
    malformed(s, LFTAG_META_FIELD_DISTORTION, "is not an array of doubles");
  frame.markers = read_list(s, LFTAG_META_FIELD_MARKERS, LFTAG_TRUTH_STRUCTURE_NAME, truth_from_structure);
  return frame;
}

}  // namespace lftag::gst
