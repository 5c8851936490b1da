/* SPDX-License-Identifier: LGPL-2.1-or-later */
/**
 * SECTION:element-lftagtestsrc
 * @title: lftagtestsrc
 *
 * Renders synthetic camera video of LFTag markers moving along smooth 6-DoF paths:
 * each marker keeps to its own cell of the frame while it drifts, comes closer and
 * recedes (4:1 in distance), spins and tilts by up to 40 degrees about each in-plane
 * axis. Frames are rendered by exact projection with anti-aliasing, optionally with
 * motion blur, noise, uneven light or a photo behind the markers. The video is a
 * function of time and the seed: the same settings give the same frames.
 *
 * Every frame carries the ground truth as an LFTagTruthMeta (a GstCustomMeta; see
 * lftag-meta.h for its fields): the camera, and per marker its family, id, pose, key
 * points, blob centroids and centres, outer corners, whether it is wholly in view and
 * its size in pixels. The meta has no tags, so it survives videoconvert and videoscale
 * (its coordinates stay in the rendered frame's pixels).
 *
 * The camera is the calibration file's, else fx, fy, cx and cy, else the default
 * camera (fx = fy = frame width, centred). "Not set" is a value no camera has: 0
 * for fx and fy, -1 for cx and cy (0 is the first pixel column or row).
 *
 * Without caps from downstream it produces 640x480 GRAY8 at 30 frames per second
 * (or the calibration's own frame size); in other formats a frame is exactly what
 * videoconvert makes of the grey one.
 *
 * ## Example launch lines
 * |[
 * gst-launch-1.0 lftagtestsrc count=3 ! videoconvert ! autovideosink
 * ]| Three random 3x3 markers on screen.
 * |[
 * gst-launch-1.0 lftagtestsrc family=4x4 ids=6789,12,0x3f motion-blur=0.5 noise=3 \
 *     num-buffers=300 ! video/x-raw,width=1280,height=720 ! videoconvert ! \
 *     vp8enc ! webmmux ! filesink location=markers.webm
 * ]| Ten seconds of three 4x4 markers with motion blur and noise, as VP8.
 * |[
 * gst-launch-1.0 lftagtestsrc calibration-file=camera.yml background=photo \
 *     background-location=street.jpg is-live=true ! videoconvert ! autovideosink
 * ]| A live source seen through a calibrated (distorting) camera, over a photo.
 */
#include "gstlftagtestsrc.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include <gst/video/video.h>
#include <opencv2/imgcodecs.hpp>

#include <lftag/image_file.hpp>
#include <lftag/render.hpp>
#include <lftag/tag_id.hpp>

#include "elementcamera.h"
#include "markermotion.h"
#include "metaconversion.h"
#include "propertystate.h"

GST_DEBUG_CATEGORY_STATIC(gst_lftag_test_src_debug);
#define GST_CAT_DEFAULT gst_lftag_test_src_debug

enum {
  PROP_0,
  PROP_FAMILY,
  PROP_IDS,
  PROP_COUNT,
  PROP_TAG_SIZE,
  PROP_SPEED,
  PROP_MOTION_BLUR,
  PROP_NOISE,
  PROP_BACKGROUND,
  PROP_BACKGROUND_LOCATION,
  PROP_CAMERA, /* lftag::gst::kCameraProperties ids: fx, fy, cx, cy, calibration-file */
  PROP_SEED = PROP_CAMERA + lftag::gst::kCameraProperties,
  PROP_IS_LIVE,
};

#define DEFAULT_PROP_FAMILY 3
#define DEFAULT_PROP_IDS nullptr
#define DEFAULT_PROP_COUNT 0
#define DEFAULT_PROP_TAG_SIZE 0.1
#define DEFAULT_PROP_SPEED 1.0
#define DEFAULT_PROP_MOTION_BLUR 0.0
#define DEFAULT_PROP_NOISE 0.0
#define DEFAULT_PROP_BACKGROUND GST_LFTAG_TEST_SRC_BACKGROUND_FLAT
#define DEFAULT_PROP_BACKGROUND_LOCATION nullptr
#define DEFAULT_PROP_SEED 0
#define DEFAULT_PROP_IS_LIVE FALSE

#define MAX_MARKERS 64
#define MAX_SUBFRAMES 16
#define DEFAULT_WIDTH 640
#define DEFAULT_HEIGHT 480
#define DEFAULT_FPS_N 30
#define DEFAULT_FPS_D 1

#define TEST_SRC_FORMATS                                                          \
  "{ GRAY8, I420, YV12, NV12, NV21, Y42B, Y444, RGB, BGR, "                       \
  "RGBx, BGRx, xRGB, xBGR, RGBA, BGRA, ARGB, ABGR, YUY2, UYVY, YVYU, I420_10LE, " \
  "P010_10LE }"

static GstStaticPadTemplate src_template =
    GST_STATIC_PAD_TEMPLATE("src", GST_PAD_SRC, GST_PAD_ALWAYS,
                            GST_STATIC_CAPS("video/x-raw, format = (string) " TEST_SRC_FORMATS ", "
                                            "width = (int) [ 1, 16384 ], height = (int) [ 1, 16384 ], "
                                            "framerate = (fraction) [ 1/2147483647, 2147483647/1 ]"));

#define GST_TYPE_LFTAG_TEST_SRC_FAMILY (gst_lftag_test_src_family_get_type())
static GType gst_lftag_test_src_family_get_type(void) {
  static const GEnumValue values[] = {
      {2, "2x2 (16 ids)", "2x2"},    {3, "3x3 (16,384 ids)", "3x3"}, {4, "4x4 (268,435,456 ids)", "4x4"},
      {5, "5x5 (2^46 ids)", "5x5"},  {6, "6x6 (2^68 ids)", "6x6"},   {7, "7x7 (2^94 ids)", "7x7"},
      {8, "8x8 (2^124 ids)", "8x8"}, {0, nullptr, nullptr},
  };
  static const GType type = g_enum_register_static("GstLFTagTestSrcFamily", values);
  return type;
}

#define GST_TYPE_LFTAG_TEST_SRC_BACKGROUND (gst_lftag_test_src_background_get_type())
static GType gst_lftag_test_src_background_get_type(void) {
  static const GEnumValue values[] = {
      {GST_LFTAG_TEST_SRC_BACKGROUND_FLAT, "Uniform grey, evenly lit", "flat"},
      {GST_LFTAG_TEST_SRC_BACKGROUND_GRADIENT,
       "Uniform grey, the light varying by +-30 % across the frame (markers too)", "gradient"},
      {GST_LFTAG_TEST_SRC_BACKGROUND_PHOTO, "The image file in background-location", "photo"},
      {0, nullptr, nullptr},
  };
  static const GType type = g_enum_register_static("GstLFTagTestSrcBackground", values);
  return type;
}

namespace {

using lftag::Camera;
using lftag::Family;
using lftag::TagId;

/* What the properties say; guarded by the object lock. */
struct Settings {
  int family = DEFAULT_PROP_FAMILY;
  std::string ids_text;
  /* Refused values (lftag::gst::refuse_value), until a good value clears them. */
  std::string ids_error;
  std::vector<TagId> ids;
  guint count = DEFAULT_PROP_COUNT;
  double tag_size = DEFAULT_PROP_TAG_SIZE;
  double speed = DEFAULT_PROP_SPEED;
  double motion_blur = DEFAULT_PROP_MOTION_BLUR;
  double noise = DEFAULT_PROP_NOISE;
  GstLFTagTestSrcBackground background = DEFAULT_PROP_BACKGROUND;
  std::string background_location;
  lftag::gst::CameraSettings camera; /* no distortion: the scenes are drawn without a lens */
  guint seed = DEFAULT_PROP_SEED;
};

/* The settings the markers' paths are made from. */
struct MotionKey {
  int family;
  std::vector<TagId> ids;
  guint count;
  double tag_size;
  guint seed;
  bool operator==(const MotionKey& o) const {
    return family == o.family && ids == o.ids && count == o.count && tag_size == o.tag_size && seed == o.seed;
  }
};

/* Per-run state, used by the streaming thread (start, stop, caps and seeks are
 * serialised with it). `info` is also read by queries, under the object lock. */
struct State {
  std::optional<Camera> calibration; /* start() */
  cv::Mat photo;                     /* start() */
  GstVideoInfo info{};               /* set_caps() */
  Camera camera;                     /* for the negotiated frame */
  std::optional<lftag::SceneRenderer> renderer;
  GstVideoInfo grey_info{}; /* other formats: render grey, then convert */
  GstBuffer* grey = nullptr;
  GstVideoConverter* converter = nullptr;
  std::optional<MotionKey> motion_key, rejected_key;
  std::optional<lftag::gst::MarkerMotion> motion;
  guint64 n_frames = 0;        /* the next frame; its time is n_frames / fps */
  GstClockTime start_time = 0; /* from a seek before the frame rate was known */

  State() = default;
  State(const State&) = delete;
  State& operator=(const State&) = delete;
  ~State() { release_converter(); }

  void release_converter() {
    if (converter) gst_video_converter_free(converter);
    converter = nullptr;
    if (grey) gst_buffer_unref(grey);
    grey = nullptr;
  }
};

GstClockTime frame_time(const GstVideoInfo& info, guint64 n) {
  return gst_util_uint64_scale(n, GST_VIDEO_INFO_FPS_D(&info) * GST_SECOND, GST_VIDEO_INFO_FPS_N(&info));
}

/* One id per marker. Throws, naming the problem, when an id is not in the family. */
std::vector<TagId> resolve_ids(const Settings& s) {
  const Family family(s.family);
  const std::size_t count = s.count ? s.count : std::max<std::size_t>(s.ids.size(), 1);
  if (s.ids.empty()) return lftag::gst::random_ids(family, count, s.seed);
  std::vector<TagId> ids;
  for (std::size_t i = 0; i < count; ++i) {
    const TagId id = s.ids[i % s.ids.size()];
    family.require(id);
    ids.push_back(id);
  }
  return ids;
}

}  // namespace

struct _GstLFTagTestSrc {
  GstPushSrc parent;

  Settings* settings;
  State* state;
};

static void gst_lftag_test_src_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec);
static void gst_lftag_test_src_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec);
static void gst_lftag_test_src_finalize(GObject* object);

static gboolean gst_lftag_test_src_start(GstBaseSrc* bsrc);
static gboolean gst_lftag_test_src_stop(GstBaseSrc* bsrc);
static GstCaps* gst_lftag_test_src_fixate(GstBaseSrc* bsrc, GstCaps* caps);
static gboolean gst_lftag_test_src_set_caps(GstBaseSrc* bsrc, GstCaps* caps);
static gboolean gst_lftag_test_src_decide_allocation(GstBaseSrc* bsrc, GstQuery* query);
static void gst_lftag_test_src_get_times(GstBaseSrc* bsrc, GstBuffer* buffer, GstClockTime* start, GstClockTime* end);
static gboolean gst_lftag_test_src_is_seekable(GstBaseSrc* bsrc);
static gboolean gst_lftag_test_src_do_seek(GstBaseSrc* bsrc, GstSegment* segment);
static gboolean gst_lftag_test_src_query(GstBaseSrc* bsrc, GstQuery* query);
static GstFlowReturn gst_lftag_test_src_fill(GstPushSrc* psrc, GstBuffer* buffer);

#define gst_lftag_test_src_parent_class parent_class
G_DEFINE_TYPE(GstLFTagTestSrc, gst_lftag_test_src, GST_TYPE_PUSH_SRC);
GST_ELEMENT_REGISTER_DEFINE(lftagtestsrc, "lftagtestsrc", GST_RANK_NONE, GST_TYPE_LFTAG_TEST_SRC);

static void gst_lftag_test_src_class_init(GstLFTagTestSrcClass* klass) {
  GObjectClass* gobject_class = G_OBJECT_CLASS(klass);
  GstElementClass* element_class = GST_ELEMENT_CLASS(klass);
  GstBaseSrcClass* basesrc_class = GST_BASE_SRC_CLASS(klass);
  GstPushSrcClass* pushsrc_class = GST_PUSH_SRC_CLASS(klass);
  const auto playing = GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_PLAYING);
  const auto ready = GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_READY);

  GST_DEBUG_CATEGORY_INIT(gst_lftag_test_src_debug, "lftagtestsrc", 0, "LFTag synthetic video source");

  gobject_class->set_property = gst_lftag_test_src_set_property;
  gobject_class->get_property = gst_lftag_test_src_get_property;
  gobject_class->finalize = gst_lftag_test_src_finalize;

  g_object_class_install_property(gobject_class, PROP_FAMILY,
                                  g_param_spec_enum("family", "Family", "Marker family of every marker",
                                                    GST_TYPE_LFTAG_TEST_SRC_FAMILY, DEFAULT_PROP_FAMILY, playing));
  g_object_class_install_property(
      gobject_class, PROP_IDS,
      g_param_spec_string("ids", "Ids",
                          "Marker ids, comma-separated without spaces, decimal or 0x-hexadecimal, ranges such as "
                          "0-11 allowed, at most 64. Marker i shows the i-th id, the list repeating "
                          "when count is larger. Unset: random ids drawn with the seed. An id "
                          "outside the family fails the start (later: a warning, markers unchanged)",
                          DEFAULT_PROP_IDS, playing));
  g_object_class_install_property(gobject_class, PROP_COUNT,
                                  g_param_spec_uint("count", "Count",
                                                    "Number of markers, each moving in its own cell of the frame "
                                                    "(0: one per id in ids, or one when ids is unset)",
                                                    0, MAX_MARKERS, DEFAULT_PROP_COUNT, playing));
  g_object_class_install_property(
      gobject_class, PROP_TAG_SIZE,
      g_param_spec_double("tag-size", "Tag size",
                          "Outer edge of the black border in metres: the metric scale of the "
                          "truth poses (markers fill the same part of the frame at any size)",
                          0.001, 100.0, DEFAULT_PROP_TAG_SIZE, playing));
  g_object_class_install_property(
      gobject_class, PROP_SPEED,
      g_param_spec_double("speed", "Speed",
                          "How fast the markers move along their paths: 1 is a calm hand-held "
                          "motion (each marker crosses its cell in a few seconds), 0 keeps them still",
                          0.0, 20.0, DEFAULT_PROP_SPEED, ready));
  g_object_class_install_property(
      gobject_class, PROP_MOTION_BLUR,
      g_param_spec_double("motion-blur", "Motion blur",
                          "Fraction of the frame interval the shutter stays open: moving markers "
                          "smear along their paths, rendered as the mean of up to 16 sub-frames (0: sharp)",
                          0.0, 1.0, DEFAULT_PROP_MOTION_BLUR, playing));
  g_object_class_install_property(
      gobject_class, PROP_NOISE,
      g_param_spec_double("noise", "Noise", "Standard deviation of Gaussian pixel noise in grey levels (0: none)", 0.0,
                          100.0, DEFAULT_PROP_NOISE, playing));
  g_object_class_install_property(
      gobject_class, PROP_BACKGROUND,
      g_param_spec_enum("background", "Background", "What lies behind the markers", GST_TYPE_LFTAG_TEST_SRC_BACKGROUND,
                        DEFAULT_PROP_BACKGROUND, ready));
  g_object_class_install_property(gobject_class, PROP_BACKGROUND_LOCATION,
                                  g_param_spec_string("background-location", "Background location",
                                                      "Image file (any format OpenCV reads) behind the markers when "
                                                      "background=photo, scaled to cover the frame",
                                                      DEFAULT_PROP_BACKGROUND_LOCATION, ready));
  lftag::gst::install_camera_properties(
      gobject_class, PROP_CAMERA, ready,
      {"Horizontal focal length in pixels. 0 (the default) is \"not set\": the default camera, fx = fy = frame "
       "width, a 53 degree field of view, centred",
       "OpenCV camera calibration (YAML, XML or JSON with camera_matrix and distortion_coefficients, or "
       "cameraMatrix and distCoeffs) used instead of fx, fy, cx, cy; scaled to the frame when it records "
       "image_width and image_height, which are then the default frame size"},
      false);
  g_object_class_install_property(
      gobject_class, PROP_SEED,
      g_param_spec_uint("seed", "Seed",
                        "Seed of the paths, the random ids and the noise: the same seed and "
                        "settings give the same video",
                        0, G_MAXUINT, DEFAULT_PROP_SEED, playing));
  g_object_class_install_property(
      gobject_class, PROP_IS_LIVE,
      g_param_spec_boolean("is-live", "Is live",
                           "Act as a live source: frames follow the pipeline clock at the frame rate",
                           DEFAULT_PROP_IS_LIVE, ready));

  gst_element_class_set_static_metadata(element_class, "LFTag test source", "Source/Video",
                                        "Renders LFTag markers moving along smooth 6-DoF paths, with the ground truth "
                                        "attached to every frame as an LFTagTruthMeta",
                                        LFTAG_AUTHOR);
  gst_element_class_add_static_pad_template(element_class, &src_template);

  basesrc_class->start = GST_DEBUG_FUNCPTR(gst_lftag_test_src_start);
  basesrc_class->stop = GST_DEBUG_FUNCPTR(gst_lftag_test_src_stop);
  basesrc_class->fixate = GST_DEBUG_FUNCPTR(gst_lftag_test_src_fixate);
  basesrc_class->set_caps = GST_DEBUG_FUNCPTR(gst_lftag_test_src_set_caps);
  basesrc_class->decide_allocation = GST_DEBUG_FUNCPTR(gst_lftag_test_src_decide_allocation);
  basesrc_class->get_times = GST_DEBUG_FUNCPTR(gst_lftag_test_src_get_times);
  basesrc_class->is_seekable = GST_DEBUG_FUNCPTR(gst_lftag_test_src_is_seekable);
  basesrc_class->do_seek = GST_DEBUG_FUNCPTR(gst_lftag_test_src_do_seek);
  basesrc_class->query = GST_DEBUG_FUNCPTR(gst_lftag_test_src_query);
  pushsrc_class->fill = GST_DEBUG_FUNCPTR(gst_lftag_test_src_fill);

  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_TEST_SRC_FAMILY, GstPluginAPIFlags(0));
  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_TEST_SRC_BACKGROUND, GstPluginAPIFlags(0));

  /* So that applications find the meta by name as soon as the element exists. */
  lftag::gst::truth_meta_info();
}

static void gst_lftag_test_src_init(GstLFTagTestSrc* self) {
  self->settings = new Settings();
  self->state = new State();
  gst_base_src_set_format(GST_BASE_SRC(self), GST_FORMAT_TIME);
  gst_base_src_set_live(GST_BASE_SRC(self), DEFAULT_PROP_IS_LIVE);
}

static void gst_lftag_test_src_finalize(GObject* object) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(object);

  delete self->settings;
  delete self->state;

  G_OBJECT_CLASS(parent_class)->finalize(object);
}

static void gst_lftag_test_src_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(object);
  std::vector<TagId> ids;

  if (!lftag::gst::property_settable_now(GST_ELEMENT(self), pspec)) return;
  if (prop_id >= PROP_CAMERA && prop_id < PROP_SEED) {
    lftag::gst::set_camera_property(GST_ELEMENT(self), self->settings->camera,
                                    lftag::gst::CameraProperty(prop_id - PROP_CAMERA), value);
    return;
  }
  switch (prop_id) {
    case PROP_IS_LIVE: /* takes the object lock itself */
      gst_base_src_set_live(GST_BASE_SRC(self), g_value_get_boolean(value));
      return;
    case PROP_IDS: /* parsed outside the lock; bad text changes nothing */
      try {
        const gchar* text = g_value_get_string(value);
        if (text && *text) ids = lftag::parse_id_list(text, MAX_MARKERS);
      } catch (const std::exception& e) {
        const std::string refusal =
            lftag::gst::refuse_value(GST_ELEMENT(self), "ids", g_value_get_string(value), e.what());
        GST_OBJECT_LOCK(self);
        self->settings->ids_error = refusal;
        GST_OBJECT_UNLOCK(self);
        return;
      }
      break;
    default: break;
  }

  GST_OBJECT_LOCK(self);
  Settings& s = *self->settings;
  switch (prop_id) {
    case PROP_FAMILY: s.family = g_value_get_enum(value); break;
    case PROP_IDS:
      s.ids_error.clear();
      s.ids_text = ids.empty() ? "" : g_value_get_string(value);
      s.ids = std::move(ids);
      break;
    case PROP_COUNT: s.count = g_value_get_uint(value); break;
    case PROP_TAG_SIZE: s.tag_size = g_value_get_double(value); break;
    case PROP_SPEED: s.speed = g_value_get_double(value); break;
    case PROP_MOTION_BLUR: s.motion_blur = g_value_get_double(value); break;
    case PROP_NOISE: s.noise = g_value_get_double(value); break;
    case PROP_BACKGROUND: s.background = GstLFTagTestSrcBackground(g_value_get_enum(value)); break;
    case PROP_BACKGROUND_LOCATION:
      s.background_location = g_value_get_string(value) ? g_value_get_string(value) : "";
      break;
    case PROP_SEED: s.seed = g_value_get_uint(value); break;
    default: G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec); break;
  }
  GST_OBJECT_UNLOCK(self);
}

static void gst_lftag_test_src_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(object);
  auto optional_string = [](const std::string& text) { return text.empty() ? nullptr : text.c_str(); };

  if (prop_id == PROP_IS_LIVE) {
    g_value_set_boolean(value, gst_base_src_is_live(GST_BASE_SRC(self)));
    return;
  }

  GST_OBJECT_LOCK(self);
  const Settings& s = *self->settings;
  if (prop_id >= PROP_CAMERA && prop_id < PROP_SEED) {
    lftag::gst::get_camera_property(s.camera, lftag::gst::CameraProperty(prop_id - PROP_CAMERA), value);
    GST_OBJECT_UNLOCK(self);
    return;
  }
  switch (prop_id) {
    case PROP_FAMILY: g_value_set_enum(value, s.family); break;
    case PROP_IDS: g_value_set_string(value, optional_string(s.ids_text)); break;
    case PROP_COUNT: g_value_set_uint(value, s.count); break;
    case PROP_TAG_SIZE: g_value_set_double(value, s.tag_size); break;
    case PROP_SPEED: g_value_set_double(value, s.speed); break;
    case PROP_MOTION_BLUR: g_value_set_double(value, s.motion_blur); break;
    case PROP_NOISE: g_value_set_double(value, s.noise); break;
    case PROP_BACKGROUND: g_value_set_enum(value, s.background); break;
    case PROP_BACKGROUND_LOCATION: g_value_set_string(value, optional_string(s.background_location)); break;
    case PROP_SEED: g_value_set_uint(value, s.seed); break;
    default: G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec); break;
  }
  GST_OBJECT_UNLOCK(self);
}

static Settings gst_lftag_test_src_settings(GstLFTagTestSrc* self) {
  GST_OBJECT_LOCK(self);
  Settings s = *self->settings;
  GST_OBJECT_UNLOCK(self);
  return s;
}

/* Loads the files the settings name, so that a bad one fails the state change. */
static gboolean gst_lftag_test_src_start(GstBaseSrc* bsrc) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(bsrc);
  const Settings s = gst_lftag_test_src_settings(self);
  State& st = *self->state;

  if (!lftag::gst::no_refused_values(GST_ELEMENT(self), {&s.ids_error, &s.camera.cx_error, &s.camera.cy_error}))
    return FALSE;
  try {
    resolve_ids(s);
  } catch (const std::exception& e) {
    GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("Invalid ids: %s.", e.what()), (nullptr));
    return FALSE;
  }

  st.calibration.reset();
  if (!s.camera.calibration_file.empty() &&
      !lftag::gst::load_calibration(GST_ELEMENT(self), s.camera.calibration_file, st.calibration))
    return FALSE;
  const std::string ignored = lftag::gst::ignored_pinhole(s.camera.pinhole, st.calibration.has_value());
  if (!ignored.empty()) GST_ELEMENT_WARNING(self, RESOURCE, SETTINGS, ("%s.", ignored.c_str()), (nullptr));

  st.photo.release();
  if (s.background == GST_LFTAG_TEST_SRC_BACKGROUND_PHOTO) {
    const gchar* path = s.background_location.c_str();
    if (s.background_location.empty()) {
      GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("background=photo needs an image file in background-location."),
                        (nullptr));
      return FALSE;
    }
    // read_grey_image refuses, with its reason, what is not a regular file (a FIFO would
    // block the start), a format or header it cannot check and an image over its limit.
    try {
      st.photo = lftag::read_grey_image(s.background_location);
    } catch (const std::exception& e) {
      if (g_file_test(path, G_FILE_TEST_EXISTS))
        GST_ELEMENT_ERROR(self, RESOURCE, READ, ("background-location: %s.", e.what()), (nullptr));
      else
        GST_ELEMENT_ERROR(self, RESOURCE, NOT_FOUND, ("background-location: %s.", e.what()), (nullptr));
      return FALSE;
    }
  }

  st.n_frames = 0;
  st.start_time = 0;
  return TRUE;
}

static gboolean gst_lftag_test_src_stop(GstBaseSrc* bsrc) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(bsrc);
  State& st = *self->state;

  GST_OBJECT_LOCK(self);
  st.info = GstVideoInfo{};
  GST_OBJECT_UNLOCK(self);
  st.release_converter();
  st.renderer.reset();
  st.motion.reset();
  st.motion_key.reset();
  st.rejected_key.reset();
  st.calibration.reset();
  st.photo.release();
  return TRUE;
}

static GstCaps* gst_lftag_test_src_fixate(GstBaseSrc* bsrc, GstCaps* caps) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(bsrc);
  const std::optional<Camera>& calibration = self->state->calibration;
  int width = DEFAULT_WIDTH, height = DEFAULT_HEIGHT;

  if (calibration && calibration->width > 0 && calibration->height > 0) {
    width = calibration->width;
    height = calibration->height;
  }
  caps = gst_caps_make_writable(caps);
  GstStructure* s = gst_caps_get_structure(caps, 0);
  gst_structure_fixate_field_nearest_int(s, "width", width);
  gst_structure_fixate_field_nearest_int(s, "height", height);
  gst_structure_fixate_field_nearest_fraction(s, "framerate", DEFAULT_FPS_N, DEFAULT_FPS_D);

  return GST_BASE_SRC_CLASS(parent_class)->fixate(bsrc, caps);
}

static gboolean gst_lftag_test_src_set_caps(GstBaseSrc* bsrc, GstCaps* caps) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(bsrc);
  const Settings s = gst_lftag_test_src_settings(self);
  State& st = *self->state;
  GstVideoInfo info;

  if (!gst_video_info_from_caps(&info, caps)) {
    GST_ERROR_OBJECT(self, "invalid caps %" GST_PTR_FORMAT, caps);
    return FALSE;
  }
  const int width = GST_VIDEO_INFO_WIDTH(&info), height = GST_VIDEO_INFO_HEIGHT(&info);

  /* One renderer per camera: it keeps the per-pixel rays and the background. */
  try {
    lftag::SceneParams params;
    params.camera = lftag::gst::frame_camera(s.camera.pinhole, st.calibration, width, height);
    params.noise_sigma = s.noise;
    if (s.background == GST_LFTAG_TEST_SRC_BACKGROUND_GRADIENT) {
      params.exposure = 0.8; /* keeps the bright side below white */
      params.light_gradient = 0.6;
      params.light_angle_deg = 30;
    } else if (s.background == GST_LFTAG_TEST_SRC_BACKGROUND_PHOTO) {
      params.photo = st.photo;
    }
    st.renderer.emplace(params);
    st.camera = params.camera;
  } catch (const std::exception& e) {
    GST_ELEMENT_ERROR(self, CORE, NEGOTIATION, ("Cannot render %dx%d frames: %s.", width, height, e.what()), (nullptr));
    return FALSE;
  }

  st.release_converter();
  if (GST_VIDEO_INFO_FORMAT(&info) != GST_VIDEO_FORMAT_GRAY8) {
    gst_video_info_set_format(&st.grey_info, GST_VIDEO_FORMAT_GRAY8, width, height);
    /* The converter only changes format: the rest must match. */
    GST_VIDEO_INFO_FPS_N(&st.grey_info) = GST_VIDEO_INFO_FPS_N(&info);
    GST_VIDEO_INFO_FPS_D(&st.grey_info) = GST_VIDEO_INFO_FPS_D(&info);
    GST_VIDEO_INFO_PAR_N(&st.grey_info) = GST_VIDEO_INFO_PAR_N(&info);
    GST_VIDEO_INFO_PAR_D(&st.grey_info) = GST_VIDEO_INFO_PAR_D(&info);
    GST_VIDEO_INFO_INTERLACE_MODE(&st.grey_info) = GST_VIDEO_INFO_INTERLACE_MODE(&info);
    /* No dithering: the same grey always gives the same pixel. */
    GstStructure* config = gst_structure_new("GstVideoConverter", GST_VIDEO_CONVERTER_OPT_DITHER_METHOD,
                                             GST_TYPE_VIDEO_DITHER_METHOD, GST_VIDEO_DITHER_NONE, nullptr);
    st.converter = gst_video_converter_new(&st.grey_info, &info, config);
    st.grey = gst_buffer_new_allocate(nullptr, GST_VIDEO_INFO_SIZE(&st.grey_info), nullptr);
    if (!st.converter || !st.grey) {
      st.release_converter();
      GST_ELEMENT_ERROR(self, CORE, NEGOTIATION, (nullptr), ("cannot convert GRAY8 to %" GST_PTR_FORMAT, caps));
      return FALSE;
    }
  }

  /* A new frame rate continues from the time the next frame would have had. */
  const GstClockTime next = GST_VIDEO_INFO_FPS_N(&st.info) > 0 ? frame_time(st.info, st.n_frames) : st.start_time;
  st.n_frames = gst_util_uint64_scale(next, GST_VIDEO_INFO_FPS_N(&info), GST_VIDEO_INFO_FPS_D(&info) * GST_SECOND);

  GST_OBJECT_LOCK(self);
  st.info = info;
  GST_OBJECT_UNLOCK(self);
  st.motion.reset(); /* the paths depend on the camera */
  st.motion_key.reset();
  st.rejected_key.reset();
  return TRUE;
}

static gboolean gst_lftag_test_src_decide_allocation(GstBaseSrc* bsrc, GstQuery* query) {
  GstCaps* caps;
  GstVideoInfo info;
  GstBufferPool* pool = nullptr;
  guint size, min = 0, max = 0;

  gst_query_parse_allocation(query, &caps, nullptr);
  if (!caps || !gst_video_info_from_caps(&info, caps)) return FALSE;

  const gboolean update = gst_query_get_n_allocation_pools(query) > 0;
  if (update) {
    gst_query_parse_nth_allocation_pool(query, 0, &pool, &size, &min, &max);
    size = MAX(size, (guint)GST_VIDEO_INFO_SIZE(&info));
  } else {
    size = GST_VIDEO_INFO_SIZE(&info);
  }
  /* Only a video pool lays out frames with the strides that a video meta announces. */
  if (pool && !gst_buffer_pool_has_option(pool, GST_BUFFER_POOL_OPTION_VIDEO_META)) gst_clear_object(&pool);
  if (!pool) pool = gst_video_buffer_pool_new();

  GstStructure* config = gst_buffer_pool_get_config(pool);
  gst_buffer_pool_config_set_params(config, caps, size, min, max);
  if (gst_query_find_allocation_meta(query, GST_VIDEO_META_API_TYPE, nullptr))
    gst_buffer_pool_config_add_option(config, GST_BUFFER_POOL_OPTION_VIDEO_META);
  if (!gst_buffer_pool_set_config(pool, config)) {
    GST_ERROR_OBJECT(bsrc, "buffer pool rejected its configuration");
    gst_object_unref(pool);
    return FALSE;
  }

  if (update)
    gst_query_set_nth_allocation_pool(query, 0, pool, size, min, max);
  else
    gst_query_add_allocation_pool(query, pool, size, min, max);
  gst_object_unref(pool);

  return GST_BASE_SRC_CLASS(parent_class)->decide_allocation(bsrc, query);
}

/* A live source waits for the clock to reach each frame's time; otherwise no sync. */
static void gst_lftag_test_src_get_times(GstBaseSrc* bsrc, GstBuffer* buffer, GstClockTime* start, GstClockTime* end) {
  if (!gst_base_src_is_live(bsrc) || !GST_BUFFER_PTS_IS_VALID(buffer)) return;
  *start = GST_BUFFER_PTS(buffer);
  if (GST_BUFFER_DURATION_IS_VALID(buffer)) *end = *start + GST_BUFFER_DURATION(buffer);
}

static gboolean gst_lftag_test_src_is_seekable(GstBaseSrc*) { return TRUE; /* every frame is a function of its time */ }

static gboolean gst_lftag_test_src_do_seek(GstBaseSrc* bsrc, GstSegment* segment) {
  State& st = *GST_LFTAG_TEST_SRC(bsrc)->state;

  if (segment->rate < 0) return FALSE; /* frames are counted forwards only */
  segment->time = segment->start;
  st.start_time = segment->position;
  if (GST_VIDEO_INFO_FPS_N(&st.info) > 0)
    st.n_frames = gst_util_uint64_scale(segment->position, GST_VIDEO_INFO_FPS_N(&st.info),
                                        GST_VIDEO_INFO_FPS_D(&st.info) * GST_SECOND);
  return TRUE;
}

static gboolean gst_lftag_test_src_query(GstBaseSrc* bsrc, GstQuery* query) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(bsrc);

  if (GST_QUERY_TYPE(query) == GST_QUERY_LATENCY) {
    /* A live frame is complete one frame interval after it began. */
    GST_OBJECT_LOCK(self);
    const gint fps_n = GST_VIDEO_INFO_FPS_N(&self->state->info);
    const gint fps_d = GST_VIDEO_INFO_FPS_D(&self->state->info);
    GST_OBJECT_UNLOCK(self);
    if (fps_n <= 0) return FALSE;
    const GstClockTime latency = gst_util_uint64_scale(GST_SECOND, fps_d, fps_n);
    gst_query_set_latency(query, gst_base_src_is_live(bsrc), latency, latency);
    return TRUE;
  }
  return GST_BASE_SRC_CLASS(parent_class)->query(bsrc, query);
}

/* (Re)makes the markers' paths when their settings changed. A change that cannot be
 * honoured (an id outside the family) is reported once and the markers stay. */
static gboolean gst_lftag_test_src_update_motion(GstLFTagTestSrc* self, const Settings& s) {
  State& st = *self->state;
  MotionKey key{s.family, s.ids, s.count, s.tag_size, s.seed};

  if ((st.motion && st.motion_key == key) || (st.motion && st.rejected_key == key)) return TRUE;
  try {
    st.motion.emplace(st.camera, Family(s.family), resolve_ids(s), s.tag_size, s.seed);
    st.motion_key = std::move(key);
  } catch (const std::exception& e) {
    if (!st.motion) {
      GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("Invalid ids: %s.", e.what()), (nullptr));
      return FALSE;
    }
    GST_ELEMENT_WARNING(self, RESOURCE, SETTINGS, ("Invalid ids: %s; the markers stay as they were.", e.what()),
                        (nullptr));
    st.rejected_key = std::move(key);
  }
  return TRUE;
}

/* The linear grey frame at time t along the paths, without noise. Motion blur
 * averages sub-frames across the exposure (which lasts `exposure` along the paths),
 * close enough that no corner moves more than a pixel between two. */
static cv::Mat1f gst_lftag_test_src_render(const State& st, double t, double exposure) {
  int steps = 1;
  if (exposure > 0) {
    const double shift = st.motion->max_corner_shift(t - exposure / 2, t + exposure / 2);
    steps = std::clamp(int(std::ceil(shift)), 1, MAX_SUBFRAMES);
  }
  cv::Mat1f sum;
  for (int i = 0; i < steps; ++i) {
    const double ti = t + exposure * ((i + 0.5) / steps - 0.5);
    std::vector<lftag::SceneTarget> targets;
    for (const lftag::SceneMarker& m : st.motion->at(ti)) targets.push_back(lftag::to_target(m));
    cv::Mat1f image = st.renderer->render_linear(targets);
    if (sum.empty())
      sum = image;
    else
      sum += image;
  }
  if (steps > 1) sum /= steps;
  return sum;
}

static cv::Mat grey_plane(GstVideoFrame* frame) {
  return cv::Mat(GST_VIDEO_FRAME_HEIGHT(frame), GST_VIDEO_FRAME_WIDTH(frame), CV_8UC1,
                 GST_VIDEO_FRAME_PLANE_DATA(frame, 0), std::size_t(GST_VIDEO_FRAME_PLANE_STRIDE(frame, 0)));
}

/* Writes the grey frame into the buffer, converting it if needed. */
static gboolean gst_lftag_test_src_write(GstLFTagTestSrc* self, const cv::Mat1b& image, GstBuffer* buffer) {
  State& st = *self->state;
  GstVideoFrame frame, grey;

  if (!gst_video_frame_map(&frame, &st.info, buffer, GST_MAP_WRITE)) return FALSE;
  if (!st.converter) {
    cv::Mat plane = grey_plane(&frame);
    image.copyTo(plane);
  } else if (gst_video_frame_map(&grey, &st.grey_info, st.grey, GST_MAP_READWRITE)) {
    cv::Mat plane = grey_plane(&grey);
    image.copyTo(plane);
    gst_video_converter_frame(st.converter, &grey, &frame);
    gst_video_frame_unmap(&grey);
  } else {
    gst_video_frame_unmap(&frame);
    return FALSE;
  }
  gst_video_frame_unmap(&frame);
  return TRUE;
}

static GstFlowReturn gst_lftag_test_src_fill(GstPushSrc* psrc, GstBuffer* buffer) {
  GstLFTagTestSrc* self = GST_LFTAG_TEST_SRC(psrc);
  State& st = *self->state;

  if (!st.renderer) {
    GST_ELEMENT_ERROR(self, CORE, NEGOTIATION, (nullptr), ("format wasn't negotiated before the first frame"));
    return GST_FLOW_NOT_NEGOTIATED;
  }
  const Settings s = gst_lftag_test_src_settings(self);
  if (!gst_lftag_test_src_update_motion(self, s)) return GST_FLOW_ERROR;

  const GstClockTime pts = frame_time(st.info, st.n_frames);
  const GstClockTime next = frame_time(st.info, st.n_frames + 1);
  /* Time along the paths. */
  const double t = s.speed * double(pts) / GST_SECOND;
  const double exposure = s.speed * s.motion_blur * double(next - pts) / GST_SECOND;

  std::vector<lftag::MarkerTruth> truth;
  try {
    /* The renderer adds the noise, so a new noise level needs a new renderer. */
    if (st.renderer->params().noise_sigma != s.noise) {
      lftag::SceneParams params = st.renderer->params();
      params.noise_sigma = s.noise;
      st.renderer.emplace(params);
    }
    const cv::Mat1b image =
        st.renderer->quantize(gst_lftag_test_src_render(st, t, exposure), lftag::gst::mix_seed(s.seed, pts));
    if (!gst_lftag_test_src_write(self, image, buffer)) {
      GST_ELEMENT_ERROR(self, RESOURCE, WRITE, (nullptr), ("could not map the output buffer"));
      return GST_FLOW_ERROR;
    }
    for (const lftag::SceneMarker& m : st.motion->at(t)) truth.push_back(lftag::make_truth(st.camera, m));
  } catch (const std::exception& e) {
    GST_ELEMENT_ERROR(self, STREAM, FAILED, (nullptr), ("rendering failed: %s", e.what()));
    return GST_FLOW_ERROR;
  }
  lftag::gst::add_truth_meta(buffer, st.camera, truth);

  GST_BUFFER_PTS(buffer) = pts;
  GST_BUFFER_DTS(buffer) = pts;
  GST_BUFFER_DURATION(buffer) = next - pts;
  GST_BUFFER_OFFSET(buffer) = st.n_frames;
  GST_BUFFER_OFFSET_END(buffer) = st.n_frames + 1;
  st.n_frames++;
  return GST_FLOW_OK;
}
