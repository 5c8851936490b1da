// SPDX-License-Identifier: LGPL-2.1-or-later
// The metas: registration (the truth without tags, the detections tagged for videoscale,
// which moves their points), exact round trips of detections and truth
// (through the buffer, copies and the text form), the public C helpers, and errors.
#include <cmath>
#include <stdexcept>
#include <string>

#include <gst/video/video.h>

#include "metaconversion.h"
// Last: check's macros (fail...) clash with names in the C++ library.
#include "check-main.h"

namespace {

using lftag::Camera;
using lftag::Detection;
using lftag::Family;
using lftag::MarkerTruth;
using lftag::SceneMarker;
using lftag::TagId;

// A detection with a different value in every field.
Detection make_detection(int n, TagId id, double base) {
  Detection d;
  d.family = Family(n);
  d.id = id;
  for (int i = 0; i < n * n; ++i) d.centroids.emplace_back(base + i, base - i / 3.0);
  for (int i = 0; i < 4; ++i) {
    d.keypoints[i] = {base + 10 * i + 0.125, base + 0.1 * i};
    d.corners[i] = {base - 7 * i, base + 1.0 / (i + 3)};
  }
  d.center = {base + 0.5, base + 0.25};
  d.rvec = {0.1, -0.2, 0.3 + base};
  d.tvec = {-0.01, 0.02, 1.5 + base};
  d.tag_size = 0.16;
  d.calibrated = n % 2 == 0;
  d.decode_error = 1.25e-4 * n;
  d.worst_cell = 0.015 * n;
  d.noise_margin = 2.5 + n;
  d.edge_score = 42.5 + n;
  d.reprojection_error = 0.03 * n;
  d.alternative_rvec = {-0.1, 0.2, 0.3 + base};
  d.alternative_tvec = {0.01, -0.02, 1.5 + 2 * base};
  d.alternative_reprojection_error = 0.05 * n;
  d.ambiguity_ratio = n > 0 ? 5.0 / 3.0 : 0.0;
  return d;
}

void expect_equal(const Detection& a, const Detection& b) {
  fail_unless(a.family == b.family);
  fail_unless(a.id == b.id, "id %s != %s", a.id.to_decimal().c_str(), b.id.to_decimal().c_str());
  fail_unless(a.centroids == b.centroids);
  fail_unless(a.keypoints == b.keypoints);
  fail_unless(a.corners == b.corners);
  fail_unless(a.center == b.center);
  fail_unless(a.rvec == b.rvec && a.tvec == b.tvec);
  fail_unless(a.tag_size == b.tag_size && a.calibrated == b.calibrated);
  fail_unless(a.decode_error == b.decode_error && a.edge_score == b.edge_score);
  fail_unless(a.worst_cell == b.worst_cell);
  fail_unless(a.noise_margin == b.noise_margin);
  fail_unless(a.reprojection_error == b.reprojection_error);
  fail_unless(a.alternative_rvec == b.alternative_rvec && a.alternative_tvec == b.alternative_tvec);
  fail_unless(a.alternative_reprojection_error == b.alternative_reprojection_error);
  fail_unless(a.ambiguity_ratio == b.ambiguity_ratio);
}

void expect_equal(const MarkerTruth& a, const MarkerTruth& b) {
  fail_unless(a.family == b.family && a.id == b.id);
  fail_unless(a.keypoints == b.keypoints && a.centers == b.centers && a.centroids == b.centroids);
  fail_unless(a.corners == b.corners && a.center == b.center);
  fail_unless(a.rvec == b.rvec && a.tvec == b.tvec && a.tag_size == b.tag_size);
  fail_unless(a.fully_visible == b.fully_visible && a.edge_px == b.edge_px);
}

const TagId kBigId = TagId(0x5, 0x0123456789abcdefull);  // 6x6: 67 bits

std::vector<Detection> some_detections() {
  return {make_detection(3, 6789, 100.5), make_detection(6, kBigId, 200.25),
          make_detection(8, Family(8).max_id(), 12.0)};
}

Camera some_camera() {
  Camera c = Camera::pinhole(500, 510, 319.5, 241, 640, 480);
  c.distortion = {-0.1, 0.02, 0.001, -0.002, 0.0};
  return c;
}

std::vector<MarkerTruth> some_truth(const Camera& camera) {
  std::vector<MarkerTruth> truth;
  SceneMarker m;
  m.family = Family(4);
  m.id = 123456;
  m.tag_size = 0.2;
  m.rvec = {0.3, -0.2, 0.5};
  m.tvec = {0.05, -0.02, 1.2};
  truth.push_back(lftag::make_truth(camera, m));
  m.family = Family(7);
  m.id = TagId(0x3fffffffull, 0x42);
  m.tvec = {5, 0, 1};  // far outside the frame
  truth.push_back(lftag::make_truth(camera, m));
  return truth;
}

const GstStructure* meta_structure(GstBuffer* buffer, const char* name) {
  const GstStructure* s = lftag_meta_get_structure(buffer, name);
  fail_unless(s != nullptr, "no %s on the buffer", name);
  return s;
}

const GstStructure* item(const GstStructure* s, const char* field, guint i) {
  const GValue* list = gst_structure_get_value(s, field);
  fail_unless(list && GST_VALUE_HOLDS_ARRAY(list) && i < gst_value_array_get_size(list));
  return gst_value_get_structure(gst_value_array_get_value(list, i));
}

}  // namespace

GST_START_TEST(test_registration) {
  for (const GstMetaInfo* info : {lftag::gst::detection_meta_info(), lftag::gst::truth_meta_info()}) {
    fail_unless(info != nullptr);
    fail_unless(gst_meta_info_is_custom(info));
  }
  // The truth has no tags: every element that copies metas keeps it as it is.
  const gchar* const* tags = gst_meta_api_type_get_tags(lftag::gst::truth_meta_info()->api);
  fail_unless(tags == nullptr || tags[0] == nullptr, "a tag would make some elements drop the truth");
  // The detections have "video" and "size", as region metas: videoscale asks them to scale.
  const GType api = lftag::gst::detection_meta_info()->api;
  tags = gst_meta_api_type_get_tags(api);
  fail_unless(tags != nullptr && g_strv_length(const_cast<gchar**>(tags)) == 2);
  fail_unless(gst_meta_api_type_has_tag(api, g_quark_from_string(GST_META_TAG_VIDEO_STR)) &&
              gst_meta_api_type_has_tag(api, g_quark_from_string(GST_META_TAG_VIDEO_SIZE_STR)));
  fail_unless(gst_meta_get_info(LFTAG_META_NAME) == lftag::gst::detection_meta_info());
  fail_unless(gst_meta_get_info(LFTAG_TRUTH_META_NAME) == lftag::gst::truth_meta_info());
  // Asking again registers nothing new.
  fail_unless(lftag::gst::truth_meta_info() == gst_meta_get_info(LFTAG_TRUTH_META_NAME));
}
GST_END_TEST;

GST_START_TEST(test_detections_round_trip) {
  GstBuffer* buffer = gst_buffer_new();
  const std::vector<Detection> detections = some_detections();
  lftag::gst::add_detection_meta(buffer, 1920, 1080, detections);

  const auto frame = lftag::gst::read_detection_meta(buffer);
  fail_unless(frame.has_value());
  fail_unless_equals_int(frame->width, 1920);
  fail_unless_equals_int(frame->height, 1080);
  fail_unless_equals_int(frame->detections.size(), detections.size());
  for (std::size_t i = 0; i < detections.size(); ++i) expect_equal(frame->detections[i], detections[i]);
  fail_if(lftag::gst::read_truth_meta(buffer).has_value(), "detections are not truth");
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_track_fields_round_trip) {
  GstBuffer* buffer = gst_buffer_new();
  const std::vector<Detection> detections = some_detections();
  std::vector<lftag::TrackInfo> tracks(detections.size());
  for (std::size_t i = 0; i < tracks.size(); ++i) {
    lftag::TrackInfo& t = tracks[i];
    t.id = 5 + i;
    t.state = i % 2 ? lftag::TrackState::predicted : lftag::TrackState::measured;
    t.first_seen = 1.25 + i;
    t.last_seen = 2.5 + i;
    t.time = 3.0 + i;
    t.flipped = i == 0;
    t.smoothed = i == 1;
    t.smoothed_rvec = {0.5, -0.25, 0.125};
    t.smoothed_tvec = {0.01, 0.02, 1.75};
  }
  lftag::gst::add_detection_meta(buffer, 640, 480, detections, true, &tracks);
  const auto frame = lftag::gst::read_detection_meta(buffer);
  fail_unless(frame.has_value());
  fail_unless_equals_int(frame->tracks.size(), detections.size());
  for (std::size_t i = 0; i < detections.size(); ++i) {
    expect_equal(frame->detections[i], detections[i]);  // the detection's own fields unchanged
    fail_unless(frame->tracks[i].has_value());
    const lftag::TrackInfo& t = *frame->tracks[i];
    fail_unless_equals_uint64(t.id, tracks[i].id);
    fail_unless(t.state == tracks[i].state && t.flipped == tracks[i].flipped && t.smoothed == tracks[i].smoothed);
    fail_unless(t.first_seen == tracks[i].first_seen && t.last_seen == tracks[i].last_seen);
    fail_unless(std::abs(t.age() - tracks[i].age()) < 1e-12);
    if (t.smoothed)
      fail_unless(t.smoothed_rvec == tracks[i].smoothed_rvec && t.smoothed_tvec == tracks[i].smoothed_tvec);
  }
  gst_buffer_unref(buffer);

  // Without tracks: no track fields, and none read.
  buffer = gst_buffer_new();
  lftag::gst::add_detection_meta(buffer, 640, 480, detections);
  const GstStructure* s = lftag_meta_get_structure(buffer, LFTAG_META_NAME);
  const GstStructure* first =
      gst_value_get_structure(gst_value_array_get_value(gst_structure_get_value(s, "detections"), 0));
  fail_if(gst_structure_has_field(first, LFTAG_FIELD_TRACK_ID));
  const auto plain = lftag::gst::read_detection_meta(buffer);
  for (const auto& t : plain->tracks) fail_if(t.has_value());
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_id_fields) {
  GstBuffer* buffer = gst_buffer_new();
  lftag::gst::add_detection_meta(buffer, 640, 480, some_detections());
  const GstStructure* s = meta_structure(buffer, LFTAG_META_NAME);

  guint64 id;
  const GstStructure* small = item(s, LFTAG_META_FIELD_DETECTIONS, 0);
  fail_unless(gst_structure_has_name(small, LFTAG_DETECTION_STRUCTURE_NAME));
  fail_unless_equals_string(gst_structure_get_string(small, LFTAG_FIELD_FAMILY), "3x3");
  fail_unless(gst_structure_get_uint64(small, LFTAG_FIELD_ID, &id));
  fail_unless_equals_uint64(id, 6789);
  fail_unless_equals_string(gst_structure_get_string(small, LFTAG_FIELD_ID_STRING), "6789");

  // 67 bits: no integer field, and the decimal string is exact.
  const GstStructure* big = item(s, LFTAG_META_FIELD_DETECTIONS, 1);
  fail_if(gst_structure_has_field(big, LFTAG_FIELD_ID));
  fail_unless_equals_string(gst_structure_get_string(big, LFTAG_FIELD_ID_STRING), "92315705897764244975");

  const GstStructure* max = item(s, LFTAG_META_FIELD_DETECTIONS, 2);
  fail_unless_equals_string(gst_structure_get_string(max, LFTAG_FIELD_ID_STRING),
                            "21267647932558653966460912964485513215");  // 2^124 - 1
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_truth_round_trip) {
  const Camera camera = some_camera();
  const std::vector<MarkerTruth> truth = some_truth(camera);
  fail_unless(truth[0].fully_visible && !truth[1].fully_visible);
  GstBuffer* buffer = gst_buffer_new();
  lftag::gst::add_truth_meta(buffer, camera, truth);

  const auto frame = lftag::gst::read_truth_meta(buffer);
  fail_unless(frame.has_value());
  fail_unless_equals_int(frame->camera.width, 640);
  fail_unless_equals_int(frame->camera.height, 480);
  fail_unless(frame->camera.fx == camera.fx && frame->camera.fy == camera.fy);
  fail_unless(frame->camera.cx == camera.cx && frame->camera.cy == camera.cy);
  fail_unless(frame->camera.distortion == camera.distortion);
  fail_unless_equals_int(frame->markers.size(), truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) expect_equal(frame->markers[i], truth[i]);
  fail_if(lftag::gst::read_detection_meta(buffer).has_value(), "truth is not detections");

  // The centre is the truth's, the projection of the marker frame's origin.
  const GstStructure* marker = item(meta_structure(buffer, LFTAG_TRUTH_META_NAME), LFTAG_META_FIELD_MARKERS, 0);
  fail_unless(gst_structure_has_name(marker, LFTAG_TRUTH_STRUCTURE_NAME));
  double x, y;
  fail_unless(lftag_structure_get_point(marker, LFTAG_FIELD_CENTER, -1, &x, &y));
  fail_unless(x == truth[0].center.x && y == truth[0].center.y);
  const cv::Point2d centre = camera.project({cv::Point3d(0, 0, 0)}, truth[0].rvec, truth[0].tvec)[0];
  fail_unless(cv::norm(cv::Point2d(x, y) - centre) < 1e-9);
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_public_helpers) {
  GstBuffer* buffer = gst_buffer_new();
  fail_unless(lftag_meta_get_structure(buffer, LFTAG_META_NAME) == nullptr);
  const std::vector<Detection> detections = some_detections();
  lftag::gst::add_detection_meta(buffer, 640, 480, detections);

  const GstStructure* d = item(meta_structure(buffer, LFTAG_META_NAME), LFTAG_META_FIELD_DETECTIONS, 1);
  double x, y;
  for (int i = 0; i < 4; ++i) {
    fail_unless(lftag_structure_get_point(d, LFTAG_FIELD_KEYPOINTS, i, &x, &y));
    fail_unless(x == detections[1].keypoints[i].x && y == detections[1].keypoints[i].y);
  }
  fail_unless(lftag_structure_get_point(d, LFTAG_FIELD_CENTROIDS, 35, &x, &y));
  fail_unless(x == detections[1].centroids[35].x && y == detections[1].centroids[35].y);
  fail_if(lftag_structure_get_point(d, LFTAG_FIELD_CENTROIDS, 36, &x, &y), "6x6 has 36 centroids");
  fail_if(lftag_structure_get_point(d, LFTAG_FIELD_RVEC, -1, &x, &y), "rvec is not a point");
  fail_if(lftag_structure_get_point(d, "no-such-field", 0, &x, &y));
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_copies_and_text) {
  GstBuffer* buffer = gst_buffer_new();
  const Camera camera = some_camera();
  const std::vector<MarkerTruth> truth = some_truth(camera);
  lftag::gst::add_truth_meta(buffer, camera, truth);
  lftag::gst::add_detection_meta(buffer, 640, 480, some_detections());

  // A buffer copy carries both metas, as equal structures.
  GstBuffer* copy = gst_buffer_copy(buffer);
  for (const char* name : {LFTAG_META_NAME, LFTAG_TRUTH_META_NAME})
    fail_unless(gst_structure_is_equal(meta_structure(copy, name), meta_structure(buffer, name)));

  // The text form (gst-launch -m, logs) reads back exactly.
  gchar* text = gst_structure_to_string(meta_structure(buffer, LFTAG_TRUTH_META_NAME));
  GstStructure* parsed = gst_structure_from_string(text, nullptr);
  fail_unless(parsed != nullptr, "cannot parse %s", text);
  GstBuffer* reparsed = gst_buffer_new();
  GstStructure* target = gst_custom_meta_get_structure(gst_buffer_add_custom_meta(reparsed, LFTAG_TRUTH_META_NAME));
  gst_structure_foreach(
      parsed,
      [](GQuark field, const GValue* value, gpointer target) -> gboolean {
        gst_structure_id_set_value(static_cast<GstStructure*>(target), field, value);
        return TRUE;
      },
      target);
  const auto frame = lftag::gst::read_truth_meta(reparsed);
  fail_unless(frame.has_value() && frame->markers.size() == truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) expect_equal(frame->markers[i], truth[i]);

  g_free(text);
  gst_structure_free(parsed);
  gst_buffer_unref(reparsed);
  gst_buffer_unref(copy);
  gst_buffer_unref(buffer);
}
GST_END_TEST;

GST_START_TEST(test_malformed_rejected) {
  auto rejects = [](GstStructure* s, const char* field) {
    try {
      lftag::gst::detection_from_structure(s);
    } catch (const std::invalid_argument& e) {
      fail_unless(std::string(e.what()).find(field) != std::string::npos, "'%s' does not name %s", e.what(), field);
      gst_structure_free(s);
      return;
    }
    fail("a malformed detection was accepted");
  };
  const Detection d = make_detection(4, 77, 5.0);

  GstStructure* s = lftag::gst::detection_structure(d);
  gst_structure_remove_field(s, LFTAG_FIELD_TVEC);
  rejects(s, LFTAG_FIELD_TVEC);

  s = lftag::gst::detection_structure(d);
  gst_structure_set(s, LFTAG_FIELD_ID, G_TYPE_UINT64, guint64(78), nullptr);
  rejects(s, LFTAG_FIELD_ID);

  s = lftag::gst::detection_structure(d);
  gst_structure_set(s, LFTAG_FIELD_FAMILY, G_TYPE_STRING, "9x9", nullptr);
  rejects(s, LFTAG_FIELD_FAMILY);

  s = lftag::gst::detection_structure(d);
  gst_structure_set(s, LFTAG_FIELD_KEYPOINTS, G_TYPE_DOUBLE, 1.0, nullptr);
  rejects(s, LFTAG_FIELD_KEYPOINTS);

  // The round trip of the untouched structure works.
  s = lftag::gst::detection_structure(d);
  expect_equal(lftag::gst::detection_from_structure(s), d);
  gst_structure_free(s);
}
GST_END_TEST;

// The detection meta's transform: a copy is the same meta; a scale moves every point
// edge to edge and sets the frame size, leaving poses alone; another transform, or a
// scale of a meta that cannot be read, copies nothing.
GST_START_TEST(test_detection_meta_transform) {
  GstBuffer* in = gst_buffer_new();
  const std::vector<Detection> detections = some_detections();
  lftag::gst::add_detection_meta(in, 1920, 1080, detections);
  auto* meta = reinterpret_cast<GstMeta*>(gst_buffer_get_custom_meta(in, LFTAG_META_NAME));
  const GstMetaInfo* info = meta->info;

  GstBuffer* copy = gst_buffer_copy(in);
  fail_unless(gst_structure_is_equal(lftag_meta_get_structure(copy, LFTAG_META_NAME),
                                     lftag_meta_get_structure(in, LFTAG_META_NAME)));

  GstVideoInfo big, small;
  gst_video_info_set_format(&big, GST_VIDEO_FORMAT_GRAY8, 1920, 1080);
  gst_video_info_set_format(&small, GST_VIDEO_FORMAT_GRAY8, 480, 360);
  GstVideoMetaTransform scale = {&big, &small};
  GstBuffer* scaled = gst_buffer_new();
  fail_unless(info->transform_func(scaled, meta, in, gst_video_meta_transform_scale_get_quark(), &scale));
  const auto frame = lftag::gst::read_detection_meta(scaled);
  fail_unless(frame.has_value() && frame->width == 480 && frame->height == 360);
  fail_unless_equals_int(frame->detections.size(), detections.size());
  const auto moved = [](cv::Point2d p, cv::Point2d q) {
    return std::abs(p.x - ((q.x + 0.5) / 4 - 0.5)) < 1e-9 && std::abs(p.y - ((q.y + 0.5) / 3 - 0.5)) < 1e-9;
  };
  for (std::size_t k = 0; k < detections.size(); ++k) {
    const Detection &d = frame->detections[k], &o = detections[k];
    fail_unless(moved(d.center, o.center));
    for (std::size_t j = 0; j < 4; ++j)
      fail_unless(moved(d.corners[j], o.corners[j]) && moved(d.keypoints[j], o.keypoints[j]));
    for (std::size_t j = 0; j < o.centroids.size(); ++j) fail_unless(moved(d.centroids[j], o.centroids[j]));
    fail_unless(d.rvec == o.rvec && d.tvec == o.tvec && d.reprojection_error == o.reprojection_error);
  }

  GstBuffer* other = gst_buffer_new();
  fail_if(info->transform_func(other, meta, in, g_quark_from_static_string("lftag-test-other"), nullptr));
  fail_unless(lftag_meta_get_structure(other, LFTAG_META_NAME) == nullptr);

  GstBuffer* bad = gst_buffer_new();
  GstStructure* s = gst_custom_meta_get_structure(gst_buffer_add_custom_meta(bad, LFTAG_META_NAME));
  gst_structure_set(s, LFTAG_META_FIELD_WIDTH, G_TYPE_INT, 1920, LFTAG_META_FIELD_HEIGHT, G_TYPE_INT, 1080, nullptr);
  lftag::gst::set_detections(s, LFTAG_META_FIELD_DETECTIONS, detections);
  gst_structure_remove_field(s, LFTAG_META_FIELD_WIDTH);
  GstBuffer* bad_scaled = gst_buffer_new();
  fail_if(info->transform_func(bad_scaled, reinterpret_cast<GstMeta*>(gst_buffer_get_custom_meta(bad, LFTAG_META_NAME)),
                               bad, gst_video_meta_transform_scale_get_quark(), &scale));
  fail_unless(lftag_meta_get_structure(bad_scaled, LFTAG_META_NAME) == nullptr);

  for (GstBuffer* b : {in, copy, scaled, other, bad, bad_scaled}) gst_buffer_unref(b);
}
GST_END_TEST;

static Suite* metaconversion_suite(void) {
  Suite* s = suite_create("metaconversion");
  TCase* tc = tcase_create("general");
  suite_add_tcase(s, tc);
  tcase_add_test(tc, test_registration);
  tcase_add_test(tc, test_detection_meta_transform);
  tcase_add_test(tc, test_detections_round_trip);
  tcase_add_test(tc, test_track_fields_round_trip);
  tcase_add_test(tc, test_id_fields);
  tcase_add_test(tc, test_truth_round_trip);
  tcase_add_test(tc, test_public_helpers);
  tcase_add_test(tc, test_copies_and_text);
  tcase_add_test(tc, test_malformed_rejected);
  return s;
}

LFTAG_CHECK_MAIN(metaconversion)
