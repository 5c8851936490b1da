/* SPDX-License-Identifier: LGPL-2.1-or-later */
/**
 * SECTION:element-lftagdetect
 * @title: lftagdetect
 *
 * Finds LFTag fiducial markers in video, decodes their ids exactly (up to 124
 * bits for 8x8) and estimates their 6-DoF poses. It runs on the luma plane of
 * GRAY8 and 8-bit planar or semi-planar YUV frames without copying it, on the
 * luma of packed 4:2:2 YUV (YUY2, UYVY, YVYU) and of 10-bit I420_10LE and
 * P010_10LE taken out into an 8-bit plane, and on luma computed from RGB frames
 * (BT.601 weights), at any size and stride.
 *
 * Unless #GstLFTagDetect:overlay is set the pixels are not touched and the frame
 * is mapped read-only, so a frame shared with another branch of a tee is not
 * copied: only the buffer's metadata changes. Every frame gets:
 *
 * - an LFTagMeta, the authoritative record: a GstCustomMeta (see lftag-meta.h)
 *   whose structure holds the analysed frame's "width" and "height",
 *   "analysed" (FALSE when the frame was passed on without detection: late, see
 *   #GstLFTagDetect:late-frames, or unreadable) and "detections", an array of
 *   "lftag/detection" structures (empty when nothing was found). Queue, tee,
 *   videoconvert, encoders and decoders keep it as it is; videoscale moves its
 *   points and size to the scaled frame (poses do not change); videocrop and
 *   videobox drop it. It replaces an LFTagMeta the buffer already carried.
 * - one GstVideoRegionOfInterestMeta per detection: roi_type "lftag", ids
 *   numbered on from the buffer's other regions, the bounding box of the outer
 *   corners clipped to the frame, and a param structure "lftag" with the fields
 *   of the detection. GStreamer 1.22's videoconvert and videoscale keep the
 *   boxes (scaled) but drop the params.
 *
 #GstLFTagDetect:messages says which frames post an element message "lftag"
 * (shown by gst-launch-1.0 -m): every frame with markers (with-markers, the
 * default), a frame whose set of markers differs from the frame before's
 * (on-change, also when the last marker leaves), every frame (every-frame) or
 * none. The message holds, in this order:
 *
 * - "timestamp" (#GstClockTime): the buffer's presentation timestamp
 * - "stream-time" (#GstClockTime): its stream time
 * - "running-time" (#GstClockTime): its running time
 * - "duration" (#GstClockTime): its duration
 * - "ids" (#GstValueArray of strings): "3x3:6789", family and decimal id of each
 *   marker, in the order of "detections"
 * - "centers" (#GstValueArray of points): their centres, rounded to 0.25 px
 * - "appeared", "vanished" (#GstValueArray of strings): ids not in the frame
 *   before, and ids of the frame before that are gone (sorted)
 * - "width", "height" (#gint): the analysed frame
 * - "track-ids" (#GstValueArray of guint64), "track-states" (#GstValueArray of
 *   strings, "measured" or "predicted"): only with #GstLFTagDetect:tracking, the
 *   track of each marker, in the order of "ids"
 * - "detections" (#GstValueArray of #GstStructure): as in the LFTagMeta; only
 *   with #GstLFTagDetect:message-detections (about 2.3 KB a marker: a message
 *   with four markers is 0.4 KB without them, 9.7 KB with them)
 *
 * The fields of each "lftag/detection" structure (family, id, key points,
 * centroids, corners, pose, the decoding's quality measures and the pose's other
 * solution), with their types and units, are documented once, in lftag-meta.h,
 * which also names each of them with a #define.
 *
 * With #GstLFTagDetect:tracking each marker is tracked by its family and id: its
 * detection gets the track's fields (track-id, track-state, track-age, first-seen,
 * last-seen, pose-flipped; lftag-meta.h), and a marker missed in a frame stays in the
 * meta, region metas and messages as "predicted" (moved by the track's
 * constant-velocity model) until #GstLFTagDetect:lost-after seconds have passed, so
 * that on-change messages post when a track starts or is lost. A tracked marker the
 * search misses (blurred, shaken) is first read where its track predicts it, from the
 * grey levels under the predicted outline, and taken only with the track's id; with
 * #GstLFTagDetect:full-detection-interval N, only every Nth frame is searched in full
 * and the frames between only read the tracked markers. With
 * #GstLFTagDetect:smoothing a One Euro filter's pose is published beside the raw one.
 *
 * Poses need the camera: #GstLFTagDetect:calibration-file (OpenCV YAML, XML or
 * JSON, scaled to the frame when it records its own frame size) or
 * #GstLFTagDetect:fx and friends. Without either, markers are still found and
 * decoded, poses assume a default camera (fx = fy = frame width, centred) and
 * are marked "calibrated" FALSE, and the element warns once per stream when a
 * metric pose is wanted (axes drawn, or tag-size set). "Not set" is a value no
 * camera has: 0 for fx and fy, -1 for cx and cy (which take 0 as the first pixel
 * column or row, not as the centre). fy, cx, cy and distortion count only with
 * fx, and the element warns when it ignores one that is set.
 *
 * ## Example launch lines
 * |[
 * gst-launch-1.0 -m lftagtestsrc count=3 num-buffers=90 ! lftagdetect ! fakesink
 * ]| Prints an "lftag" message for every frame of synthetic video.
 * |[
 * gst-launch-1.0 v4l2src ! videoconvert ! lftagdetect families=4x4 \
 *     calibration-file=camera.yml tag-size=0.05 overlay=outline+id+axes ! \
 *     videoconvert ! autovideosink
 * ]| A calibrated webcam with outlines, ids and axes drawn.
 * |[
 * gst-launch-1.0 filesrc location=recording.mp4 ! decodebin ! videoconvert ! \
 *     lftagdetect overlay=outline+id ! videoconvert ! vp8enc ! webmmux ! \
 *     filesink location=annotated.webm
 * ]| A recorded video annotated into a WebM file.
 * |[
 * gst-launch-1.0 -m lftagtestsrc count=3 ! lftagdetect tracking=true lost-after=0.3 \
 *     messages=on-change ! fakesink
 * ]| A message when a marker's track starts and when it is lost.
 */
#include "gstlftagdetect.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gst/video/video.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <lftag/detector.hpp>
#include <lftag/draw.hpp>
#include <lftag/trace.hpp>
#include <lftag/tracker.hpp>

#include "detectmessages.h"
#include "detectmetas.h"
#include "detectoverlay.h"
#include "elementcamera.h"
#include "elementtunables.h"
#include "metaconversion.h"
#include "propertystate.h"
#include "tunables.hpp"

GST_DEBUG_CATEGORY_STATIC(gst_lftag_detect_debug);
#define GST_CAT_DEFAULT gst_lftag_detect_debug

enum {
  PROP_0,
  PROP_FAMILIES,
  PROP_TAG_SIZE,
  PROP_CAMERA, /* lftag::gst::kCameraProperties ids: fx, fy, cx, cy, calibration-file, distortion */
  PROP_OVERLAY = PROP_CAMERA + lftag::gst::kCameraProperties,
  PROP_MESSAGES,
  PROP_MESSAGE_DETECTIONS,
  PROP_TUNABLE, /* lftag::io::kTunables ids, the detector's parameters in lftag::io::tunables() order */
  PROP_LATE_FRAMES = PROP_TUNABLE + lftag::io::kTunables,
  PROP_TRACKING,
  PROP_LOST_AFTER,
  PROP_SMOOTHING,
  PROP_SMOOTHING_MIN_CUTOFF,
  PROP_SMOOTHING_BETA,
  PROP_FULL_DETECTION_INTERVAL,
  PROP_IDS,
};

#define DEFAULT_PROP_FAMILIES "3x3,4x4"
#define DEFAULT_PROP_TAG_SIZE 0.1
#define DEFAULT_PROP_OVERLAY 0
#define DEFAULT_PROP_MESSAGES GST_LFTAG_DETECT_MESSAGES_WITH_MARKERS
#define DEFAULT_PROP_MESSAGE_DETECTIONS FALSE
#define DEFAULT_PROP_LATE_FRAMES GST_LFTAG_DETECT_LATE_FRAMES_ANALYSE
#define DEFAULT_PROP_TRACKING FALSE
#define DEFAULT_PROP_FULL_DETECTION_INTERVAL 1
/* The tracker's own parameters default to the library's (TrackerParams), the detector's
 * to lftag::io::front_end_defaults(). */

#define DETECT_FORMATS                                                            \
  "{ GRAY8, I420, YV12, NV12, NV21, Y42B, Y444, RGB, BGR, "                       \
  "RGBx, BGRx, xRGB, xBGR, RGBA, BGRA, ARGB, ABGR, YUY2, UYVY, YVYU, I420_10LE, " \
  "P010_10LE }"

static GstStaticPadTemplate sink_template =
    GST_STATIC_PAD_TEMPLATE("sink", GST_PAD_SINK, GST_PAD_ALWAYS, GST_STATIC_CAPS(GST_VIDEO_CAPS_MAKE(DETECT_FORMATS)));

static GstStaticPadTemplate src_template =
    GST_STATIC_PAD_TEMPLATE("src", GST_PAD_SRC, GST_PAD_ALWAYS, GST_STATIC_CAPS(GST_VIDEO_CAPS_MAKE(DETECT_FORMATS)));

#define GST_TYPE_LFTAG_DETECT_OVERLAY (gst_lftag_detect_overlay_get_type())
static GType gst_lftag_detect_overlay_get_type(void) {
  static const GFlagsValue values[] = {
      {GST_LFTAG_DETECT_OVERLAY_OUTLINE, "The outer border of each marker", "outline"},
      {GST_LFTAG_DETECT_OVERLAY_ID, "Family and id beside the marker (under it)", "id"},
      {GST_LFTAG_DETECT_OVERLAY_AXES, "Axes: x red, y green, z blue, one tag size long", "axes"},
      {0, nullptr, nullptr},
  };
  static const GType type = g_flags_register_static("GstLFTagDetectOverlay", values);
  return type;
}

#define GST_TYPE_LFTAG_DETECT_LATE_FRAMES (gst_lftag_detect_late_frames_get_type())
static GType gst_lftag_detect_late_frames_get_type(void) {
  static const GEnumValue values[] = {
      {GST_LFTAG_DETECT_LATE_FRAMES_ANALYSE, "Analyse every frame, however late", "analyse"},
      {GST_LFTAG_DETECT_LATE_FRAMES_SKIP, "Pass late frames on unanalysed, their meta saying so", "skip"},
      {0, nullptr, nullptr},
  };
  static const GType type = g_enum_register_static("GstLFTagDetectLateFrames", values);
  return type;
}

namespace {

using lftag::Camera;
using lftag::Detection;
using lftag::Family;

/* Everything the detector is built from but the calibration. */
struct DetectorSettings {
  lftag::DetectorParams params; /* no camera: it is the frame's */
  lftag::PinholeSettings pinhole;

  bool operator==(const DetectorSettings& o) const { return params == o.params && pinhole == o.pinhole; }
  bool operator!=(const DetectorSettings& o) const { return !(*this == o); }
};

/* What the properties say; guarded by the object lock. */
struct Settings {
  lftag::DetectorParams detector = lftag::io::front_end_defaults(); /* families, tag size, the tunables */
  lftag::gst::CameraSettings camera;
  std::string families_text = DEFAULT_PROP_FAMILIES;
  std::string ids_text;      /* as set; empty: every id */
  bool tag_size_set = false; /* a metric pose was asked for */
  /* A refused value (lftag::gst::refuse_value), until a good value clears it. */
  std::string families_error, ids_error;
  guint overlay = DEFAULT_PROP_OVERLAY;
  GstLFTagDetectMessages messages = DEFAULT_PROP_MESSAGES;
  bool message_detections = DEFAULT_PROP_MESSAGE_DETECTIONS;
  GstLFTagDetectLateFrames late_frames = DEFAULT_PROP_LATE_FRAMES;
  bool tracking = DEFAULT_PROP_TRACKING;
  guint full_detection_interval = DEFAULT_PROP_FULL_DETECTION_INTERVAL;
  lftag::TrackerParams tracker;

  Settings() { detector.families = Family::parse_list(DEFAULT_PROP_FAMILIES); }
  DetectorSettings detector_settings() const { return {detector, camera.pinhole}; }
};

/* Per-stream state, used by the streaming thread only (start, stop, caps and
 * buffers are serialised). */
struct State {
  std::optional<Camera> calibration; /* start() */
  cv::Mat1f luma_weights;            /* set_info(): packed formats, per byte of a pixel */
  double luma_scale = 0;             /* set_info(): 16-bit luma planes, to 8 bits */
  cv::Mat1b luma;                    /* packed and 16-bit formats: reused */
  lftag::gst::DetectOverlay overlay;
  bool ask_downstream = true;      /* whether it takes overlay compositions */
  bool attach_composition = false; /* its answer: attach, else blend */
  std::optional<lftag::Detector> detector;
  DetectorSettings built;                   /* the detector's settings */
  std::optional<DetectorSettings> rejected; /* the last set that failed, until one succeeds */
  bool warned_uncalibrated = false;
  lftag::gst::DetectMessages messages;
  guint64 analysed = 0, skipped = 0;     /* frames, for QoS messages */
  bool warned_budget = false;            /* the first frame the budget cut */
  bool warned_layout = false;            /* the first frame whose planes lie outside its memory */
  bool warned_deadline = false;          /* the first frame the deadline cut */
  std::optional<lftag::Tracker> tracker; /* with tracking: the stream's tracks */
  double track_time = 0;                 /* seconds: the last tracked frame's time */
  guint unsearched = 0;                  /* with tracking: frames since the last full search */
};

/* Downstream's latest QoS report: frames due before `earliest` (running time) are
 * late. Written by the src pad's event handler, read by the streaming thread. */
struct Lateness {
  GstClockTime earliest;
  gdouble proportion;
};

lftag::DetectorParams detector_params(const DetectorSettings& s, const Camera& camera) {
  lftag::DetectorParams p = s.params;
  p.camera = camera;
  return p;
}

/* The luma of a packed format as one weight per byte of a pixel: BT.601 for RGB (0 for
 * x and A), 1 for the Y byte of packed 4:2:2 YUV (a pixel is then two bytes, Y and U or
 * V). Empty for formats whose plane 0 is the luma itself. */
cv::Mat1f luma_weights(const GstVideoFormatInfo* finfo) {
  if (GST_VIDEO_FORMAT_INFO_IS_RGB(finfo)) {
    const float rgb[3] = {0.299f, 0.587f, 0.114f};
    cv::Mat1f weights(1, GST_VIDEO_FORMAT_INFO_PSTRIDE(finfo, 0), 0.0f);
    for (int c = 0; c < 3; ++c) weights(0, GST_VIDEO_FORMAT_INFO_POFFSET(finfo, c)) = rgb[c];
    return weights;
  }
  if (GST_VIDEO_FORMAT_INFO_PSTRIDE(finfo, 0) == 2 && GST_VIDEO_FORMAT_INFO_DEPTH(finfo, 0) == 8) {
    cv::Mat1f weights(1, 2, 0.0f);
    weights(0, GST_VIDEO_FORMAT_INFO_POFFSET(finfo, 0)) = 1.0f;
    return weights;
  }
  return {};
}

/* The factor from a 16-bit luma plane to 8 bits (10 significant bits, shifted up or
 * not); 0 for 8-bit luma. */
double luma_scale(const GstVideoFormatInfo* finfo) {
  if (GST_VIDEO_FORMAT_INFO_DEPTH(finfo, 0) <= 8) return 0;
  const int bits = GST_VIDEO_FORMAT_INFO_DEPTH(finfo, 0) + GST_VIDEO_FORMAT_INFO_SHIFT(finfo, 0);
  return 1.0 / double(1 << (bits - 8));
}

}  // namespace

struct _GstLFTagDetect {
  GstVideoFilter parent;

  Settings* settings;
  State* state;
  Lateness lateness;       /* under the object lock */
  gint downstream_changed; /* atomic: a reconfigure event came from downstream */
};

static void gst_lftag_detect_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec);
static void gst_lftag_detect_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec);
static void gst_lftag_detect_finalize(GObject* object);

static gboolean gst_lftag_detect_start(GstBaseTransform* trans);
static gboolean gst_lftag_detect_stop(GstBaseTransform* trans);
static GstFlowReturn gst_lftag_detect_transform_ip(GstBaseTransform* trans, GstBuffer* buffer);
static gboolean gst_lftag_detect_src_event(GstBaseTransform* trans, GstEvent* event);
static gboolean gst_lftag_detect_set_info(GstVideoFilter* filter, GstCaps* incaps, GstVideoInfo* in_info,
                                          GstCaps* outcaps, GstVideoInfo* out_info);

#define gst_lftag_detect_parent_class parent_class
G_DEFINE_TYPE(GstLFTagDetect, gst_lftag_detect, GST_TYPE_VIDEO_FILTER);
GST_ELEMENT_REGISTER_DEFINE(lftagdetect, "lftagdetect", GST_RANK_NONE, GST_TYPE_LFTAG_DETECT);

static void gst_lftag_detect_class_init(GstLFTagDetectClass* klass) {
  GObjectClass* gobject_class = G_OBJECT_CLASS(klass);
  GstElementClass* element_class = GST_ELEMENT_CLASS(klass);
  GstBaseTransformClass* trans_class = GST_BASE_TRANSFORM_CLASS(klass);
  GstVideoFilterClass* filter_class = GST_VIDEO_FILTER_CLASS(klass);
  const auto playing = GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_PLAYING);
  /* Static: GCC 12 takes the empty optional camera of a local one for uninitialised
   * (-Wmaybe-uninitialized) when class_init inlines its destructor. */
  static const lftag::DetectorParams defaults = lftag::io::front_end_defaults();

  GST_DEBUG_CATEGORY_INIT(gst_lftag_detect_debug, "lftagdetect", 0, "LFTag marker detector");

  gobject_class->set_property = gst_lftag_detect_set_property;
  gobject_class->get_property = gst_lftag_detect_get_property;
  gobject_class->finalize = gst_lftag_detect_finalize;

  g_object_class_install_property(
      gobject_class, PROP_FAMILIES,
      g_param_spec_string("families", "Families",
                          "Marker families to detect, comma-separated, from 2x2 to 8x8 (for "
                          "example 3x3,4x4,6x6); every family costs a little time. Unset: the default",
                          DEFAULT_PROP_FAMILIES, playing));
  g_object_class_install_property(
      gobject_class, PROP_IDS,
      g_param_spec_string("ids", "Ids",
                          "The ids in use, comma-separated, with ranges (for example 0-49,100): a marker read as "
                          "another id is not reported, so that someone else's marker, or a misreading that "
                          "lands outside the ids printed, never reaches the meta or the messages. Each must be "
                          "an id of one of the families. Unset or empty: every id",
                          nullptr, playing));
  g_object_class_install_property(
      gobject_class, PROP_TAG_SIZE,
      g_param_spec_double("tag-size", "Tag size",
                          "Outer edge of the markers' black border in metres: the scale of the "
                          "poses (tvec) and of the drawn axes. Metric only with a calibrated camera",
                          0.001, 100.0, DEFAULT_PROP_TAG_SIZE, playing));
  lftag::gst::install_camera_properties(
      gobject_class, PROP_CAMERA, playing,
      {"Horizontal focal length in pixels, for poses. 0 (the default) is \"not set\": poses then assume fx = fy = "
       "frame width, centred, and are marked uncalibrated",
       "OpenCV camera calibration (YAML, XML or JSON with camera_matrix and distortion_coefficients, as OpenCV's "
       "calibration samples write, or cameraMatrix and distCoeffs, as cameracalibrate writes). Used instead of fx, "
       "fy, cx, cy and distortion; scaled to the frame when it records image_width and image_height, which must "
       "then have the frame's shape"},
      true);
  g_object_class_install_property(
      gobject_class, PROP_OVERLAY,
      g_param_spec_flags("overlay", "Overlay",
                         "What to draw onto the frames, anti-aliased, scaled to the frame size "
                         "(for example outline+id+axes). Drawing writes to the frame (a copy when "
                         "it is shared); with nothing to draw the pixels are left untouched",
                         GST_TYPE_LFTAG_DETECT_OVERLAY, DEFAULT_PROP_OVERLAY, playing));
  g_object_class_install_property(
      gobject_class, PROP_MESSAGES,
      g_param_spec_enum("messages", "Messages",
                        "Which frames post an element message \"lftag\" (timestamps, ids and centres; "
                        "the full detections with message-detections): with-markers, on-change (the "
                        "set of ids changed), every-frame or none",
                        GST_TYPE_LFTAG_DETECT_MESSAGES, DEFAULT_PROP_MESSAGES, playing));
  g_object_class_install_property(
      gobject_class, PROP_MESSAGE_DETECTIONS,
      g_param_spec_boolean("message-detections", "Message detections",
                           "Also put the full detections (the LFTagMeta's: keypoints, centroids, corners, "
                           "poses, about 2.3 KB a marker) at the end of each \"lftag\" message; by default "
                           "a message holds the timestamps, ids, centres, appeared, vanished and frame size only",
                           DEFAULT_PROP_MESSAGE_DETECTIONS, playing));
  lftag::gst::install_tunable_properties(gobject_class, PROP_TUNABLE, defaults, playing);
  g_object_class_install_property(
      gobject_class, PROP_LATE_FRAMES,
      g_param_spec_enum("late-frames", "Late frames",
                        "What to do with a frame that a synchronised sink reports late (QoS): "
                        "analyse it anyway, or pass it on unanalysed (its LFTagMeta has "
                        "\"analysed\" FALSE, and a QoS message counts it). No frame is ever dropped",
                        GST_TYPE_LFTAG_DETECT_LATE_FRAMES, DEFAULT_PROP_LATE_FRAMES, playing));
  static const lftag::TrackerParams track_defaults;
  g_object_class_install_property(
      gobject_class, PROP_TRACKING,
      g_param_spec_boolean("tracking", "Tracking",
                           "Track each marker (by family and id) from frame to frame: the meta, JSON and "
                           "messages then carry its track (track-id, track-state, track-age, first-seen, "
                           "last-seen), a marker missed in a frame stays in them as \"predicted\" (moved by "
                           "the track's constant-velocity model) until lost-after has passed, and an ambiguous "
                           "pose takes the solution the track's evidence over its frames favours. Switching it off "
                           "ends every track",
                           DEFAULT_PROP_TRACKING, playing));
  g_object_class_install_property(
      gobject_class, PROP_LOST_AFTER,
      g_param_spec_double("lost-after", "Lost after (s)",
                          "With tracking: seconds of buffer time a marker may go undetected and still be "
                          "reported, as predicted; once longer unseen its track is lost (on-change messages "
                          "then post it as vanished) and the marker seen again starts a new track. 0: lost in "
                          "the first frame it is missed",
                          0.0, 3600.0, track_defaults.lost_after, playing));
  g_object_class_install_property(
      gobject_class, PROP_SMOOTHING,
      g_param_spec_boolean("smoothing", "Smoothing",
                           "With tracking: a One Euro filter on each track's pose, published as smoothed-rvec "
                           "and smoothed-tvec beside the raw rvec and tvec (see smoothing-min-cutoff and "
                           "smoothing-beta)",
                           track_defaults.smoothing, playing));
  g_object_class_install_property(
      gobject_class, PROP_SMOOTHING_MIN_CUTOFF,
      g_param_spec_double("smoothing-min-cutoff", "Smoothing minimum cutoff (Hz)",
                          "The One Euro filter's cutoff frequency for a still marker, in hertz: lower smooths "
                          "more and lags more (about 1 / (2 pi cutoff) seconds: 0.16 s at 1 Hz)",
                          0.001, 1000.0, track_defaults.min_cutoff, playing));
  g_object_class_install_property(
      gobject_class, PROP_SMOOTHING_BETA,
      g_param_spec_double("smoothing-beta", "Smoothing beta",
                          "How fast the One Euro filter's cutoff rises with the marker's speed (hertz per "
                          "metre per second of translation, per unit quaternion per second of rotation): "
                          "higher lags less behind a moving marker. 0: a fixed cutoff",
                          0.0, 1e6, track_defaults.beta, playing));
  g_object_class_install_property(
      gobject_class, PROP_FULL_DETECTION_INTERVAL,
      g_param_spec_uint("full-detection-interval", "Full detection interval",
                        "With tracking: search the whole frame for markers every this many frames, and in "
                        "between only read the tracked markers where their tracks predict them (a small "
                        "fraction of a search's cost; new markers are then found at the next full search). A "
                        "frame with no tracked marker is always searched. 1: every frame is searched, and "
                        "tracked markers the search misses are still read where predicted",
                        1, G_MAXINT, DEFAULT_PROP_FULL_DETECTION_INTERVAL, playing));

  gst_element_class_set_static_metadata(element_class, "LFTag detector", "Filter/Analyzer/Video",
                                        "Finds LFTag fiducial markers, decodes their ids and estimates their poses. "
                                        "Every frame gets an LFTagMeta (each marker's family, id, key points, corners, "
                                        "centroids and pose) and a region-of-interest meta per marker; frames with "
                                        "markers post an \"lftag\" element message with the same detections; an "
                                        "optional overlay draws outlines, ids and axes",
                                        LFTAG_AUTHOR);
  gst_element_class_add_static_pad_template(element_class, &sink_template);
  gst_element_class_add_static_pad_template(element_class, &src_template);

  trans_class->start = GST_DEBUG_FUNCPTR(gst_lftag_detect_start);
  trans_class->stop = GST_DEBUG_FUNCPTR(gst_lftag_detect_stop);
  /* Our own in-place transform: GstVideoFilter's maps every frame writable. */
  trans_class->transform_ip = GST_DEBUG_FUNCPTR(gst_lftag_detect_transform_ip);
  trans_class->src_event = GST_DEBUG_FUNCPTR(gst_lftag_detect_src_event);
  filter_class->set_info = GST_DEBUG_FUNCPTR(gst_lftag_detect_set_info);

  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_DETECT_OVERLAY, GstPluginAPIFlags(0));
  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_DETECT_LATE_FRAMES, GstPluginAPIFlags(0));
  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_DETECT_MESSAGES, GstPluginAPIFlags(0));

  /* So that applications find the meta by name as soon as the element exists. */
  lftag::gst::detection_meta_info();
}

static void gst_lftag_detect_init(GstLFTagDetect* self) {
  self->settings = new Settings();
  self->state = new State();
  /* Never passthrough (metadata is added to every buffer), always in place. */
  gst_base_transform_set_passthrough(GST_BASE_TRANSFORM(self), FALSE);
  gst_base_transform_set_in_place(GST_BASE_TRANSFORM(self), TRUE);
  /* GstVideoFilter drops frames that QoS reports late: an analyser must not lose
   * them from its results. Late frames are handled by the late-frames property. */
  gst_base_transform_set_qos_enabled(GST_BASE_TRANSFORM(self), FALSE);
  self->lateness = {GST_CLOCK_TIME_NONE, 1.0};
}

static void gst_lftag_detect_finalize(GObject* object) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(object);

  delete self->settings;
  delete self->state;

  G_OBJECT_CLASS(parent_class)->finalize(object);
}

/* The camera property or tunable a property id is, if it is one. */
static std::optional<lftag::gst::CameraProperty> camera_property(guint prop_id) {
  if (prop_id < PROP_CAMERA || prop_id >= PROP_CAMERA + lftag::gst::kCameraProperties) return std::nullopt;
  return lftag::gst::CameraProperty(prop_id - PROP_CAMERA);
}

static const lftag::io::Tunable* tunable(guint prop_id) {
  if (prop_id < PROP_TUNABLE || prop_id >= PROP_TUNABLE + lftag::io::kTunables) return nullptr;
  return &lftag::io::tunables()[prop_id - PROP_TUNABLE];
}

static void gst_lftag_detect_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(object);
  if (!lftag::gst::property_settable_now(GST_ELEMENT(self), pspec)) return;
  if (const auto which = camera_property(prop_id)) {
    lftag::gst::set_camera_property(GST_ELEMENT(self), self->settings->camera, *which, value);
    return;
  }

  /* A text value is parsed outside the lock by `parse`. One that does not parse is refused
   * on the bus (a warning now, while playing; an error when the element starts, for a
   * value set before it had a bus), remembered in `error` until a good value clears it,
   * and the setting stays as it was. */
  const auto parsed = [&](const char* name, std::string Settings::*error, const auto& parse) {
    const gchar* text = g_value_get_string(value);
    try {
      parse(text);
      return true;
    } catch (const std::exception& e) {
      const std::string refusal = lftag::gst::refuse_value(GST_ELEMENT(self), name, text, e.what());
      GST_OBJECT_LOCK(self);
      self->settings->*error = refusal;
      GST_OBJECT_UNLOCK(self);
      return false;
    }
  };
  std::vector<Family> families;
  std::string families_text;
  std::vector<lftag::TagId> ids;
  /* "3x3, 4X4" is read as 3x3,4x4; unset, the default. */
  if (prop_id == PROP_FAMILIES && !parsed("families", &Settings::families_error, [&](const gchar* text) {
        families = Family::parse_list(text ? text : DEFAULT_PROP_FAMILIES);
        for (const Family& f : families) families_text += (families_text.empty() ? "" : ",") + f.name();
      }))
    return;
  /* Unset or empty: every id. An id of no family searched fails when the detector is built. */
  if (prop_id == PROP_IDS && !parsed("ids", &Settings::ids_error, [&](const gchar* text) {
        if (text && *text) ids = lftag::parse_id_list(text);
      }))
    return;

  GST_OBJECT_LOCK(self);
  Settings& s = *self->settings;
  if (const lftag::io::Tunable* t = tunable(prop_id)) {
    lftag::gst::set_tunable(*t, value, s.detector);
    GST_OBJECT_UNLOCK(self);
    return;
  }
  switch (prop_id) {
    case PROP_FAMILIES:
      s.families_text = families_text;
      s.families_error.clear();
      s.detector.families = std::move(families);
      break;
    case PROP_IDS: {
      const gchar* text = g_value_get_string(value);
      s.ids_text = text ? text : "";
      s.ids_error.clear();
      s.detector.ids = std::move(ids);
      break;
    }
    case PROP_TAG_SIZE:
      s.detector.tag_size = g_value_get_double(value);
      s.tag_size_set = true;
      break;
    case PROP_OVERLAY: s.overlay = g_value_get_flags(value); break;
    case PROP_MESSAGES: s.messages = GstLFTagDetectMessages(g_value_get_enum(value)); break;
    case PROP_MESSAGE_DETECTIONS: s.message_detections = g_value_get_boolean(value); break;
    case PROP_LATE_FRAMES: s.late_frames = GstLFTagDetectLateFrames(g_value_get_enum(value)); break;
    case PROP_TRACKING: s.tracking = g_value_get_boolean(value); break;
    case PROP_LOST_AFTER: s.tracker.lost_after = g_value_get_double(value); break;
    case PROP_SMOOTHING: s.tracker.smoothing = g_value_get_boolean(value); break;
    case PROP_SMOOTHING_MIN_CUTOFF: s.tracker.min_cutoff = g_value_get_double(value); break;
    case PROP_SMOOTHING_BETA: s.tracker.beta = g_value_get_double(value); break;
    case PROP_FULL_DETECTION_INTERVAL: s.full_detection_interval = g_value_get_uint(value); break;
    default: G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec); break;
  }
  GST_OBJECT_UNLOCK(self);
}

static void gst_lftag_detect_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(object);

  GST_OBJECT_LOCK(self);
  const Settings& s = *self->settings;
  if (const auto which = camera_property(prop_id)) {
    lftag::gst::get_camera_property(s.camera, *which, value);
  } else if (const lftag::io::Tunable* t = tunable(prop_id)) {
    lftag::gst::get_tunable(*t, s.detector, value);
  } else {
    switch (prop_id) {
      case PROP_FAMILIES: g_value_set_string(value, s.families_text.c_str()); break;
      case PROP_IDS: g_value_set_string(value, s.ids_text.empty() ? nullptr : s.ids_text.c_str()); break;
      case PROP_TAG_SIZE: g_value_set_double(value, s.detector.tag_size); break;
      case PROP_OVERLAY: g_value_set_flags(value, s.overlay); break;
      case PROP_MESSAGES: g_value_set_enum(value, s.messages); break;
      case PROP_MESSAGE_DETECTIONS: g_value_set_boolean(value, s.message_detections); break;
      case PROP_LATE_FRAMES: g_value_set_enum(value, s.late_frames); break;
      case PROP_TRACKING: g_value_set_boolean(value, s.tracking); break;
      case PROP_LOST_AFTER: g_value_set_double(value, s.tracker.lost_after); break;
      case PROP_SMOOTHING: g_value_set_boolean(value, s.tracker.smoothing); break;
      case PROP_SMOOTHING_MIN_CUTOFF: g_value_set_double(value, s.tracker.min_cutoff); break;
      case PROP_SMOOTHING_BETA: g_value_set_double(value, s.tracker.beta); break;
      case PROP_FULL_DETECTION_INTERVAL: g_value_set_uint(value, s.full_detection_interval); break;
      default: G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec); break;
    }
  }
  GST_OBJECT_UNLOCK(self);
}

static Settings gst_lftag_detect_settings(GstLFTagDetect* self) {
  GST_OBJECT_LOCK(self);
  Settings s = *self->settings;
  GST_OBJECT_UNLOCK(self);
  return s;
}

/* Loads the calibration, so that a bad file fails the state change. */
static gboolean gst_lftag_detect_start(GstBaseTransform* trans) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(trans);
  const Settings s = gst_lftag_detect_settings(self);
  State& st = *self->state;

  st.calibration.reset();
  st.detector.reset();
  st.warned_uncalibrated = false;
  st.analysed = st.skipped = 0;
  GST_OBJECT_LOCK(self);
  self->lateness = {GST_CLOCK_TIME_NONE, 1.0};
  GST_OBJECT_UNLOCK(self);
  st.messages.reset();
  st.tracker.reset();
  st.unsearched = 0;
  if (!lftag::gst::no_refused_values(GST_ELEMENT(self), {&s.families_error, &s.ids_error, &s.camera.distortion_error,
                                                         &s.camera.cx_error, &s.camera.cy_error}))
    return FALSE;
  st.warned_budget = false;
  st.warned_layout = false;
  st.warned_deadline = false;
  if (s.camera.calibration_file.empty()) return TRUE;

  if (!lftag::gst::load_calibration(GST_ELEMENT(self), s.camera.calibration_file, st.calibration)) return FALSE;
  const gchar* path = s.camera.calibration_file.c_str();
  GST_INFO_OBJECT(self, "calibration from %s: fx %g fy %g cx %g cy %g, %dx%d", path, st.calibration->fx,
                  st.calibration->fy, st.calibration->cx, st.calibration->cy, st.calibration->width,
                  st.calibration->height);
  return TRUE;
}

static gboolean gst_lftag_detect_stop(GstBaseTransform* trans) {
  State& st = *GST_LFTAG_DETECT(trans)->state;

  st.calibration.reset();
  st.detector.reset();
  st.luma.release();
  st.overlay.reset();
  st.ask_downstream = true;
  st.tracker.reset();
  return TRUE;
}

static gboolean gst_lftag_detect_set_info(GstVideoFilter* filter, GstCaps*, GstVideoInfo* in_info, GstCaps*,
                                          GstVideoInfo*) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(filter);
  const Settings s = gst_lftag_detect_settings(self);
  State& st = *self->state;
  const int width = GST_VIDEO_INFO_WIDTH(in_info), height = GST_VIDEO_INFO_HEIGHT(in_info);

  /* A calibration for another shape of frame fails here, not frame after frame. */
  try {
    lftag::gst::frame_camera(s.camera.pinhole, st.calibration, width, height);
  } catch (const std::exception& e) {
    GST_ELEMENT_ERROR(self, CORE, NEGOTIATION,
                      ("Calibration file \"%s\" does not fit %dx%d video: %s.", s.camera.calibration_file.c_str(),
                       width, height, e.what()),
                      (nullptr));
    return FALSE;
  }

  st.detector.reset(); /* its camera is the frame's */
  st.luma_weights = luma_weights(in_info->finfo);
  st.luma_scale = luma_scale(in_info->finfo);
  st.luma.release();
  st.overlay.reset();
  st.ask_downstream = true;
  return TRUE;
}

/* (Re)builds the detector when its settings changed. A change that cannot be
 * honoured is reported once and the detector stays as it was. */
static gboolean gst_lftag_detect_update_detector(GstLFTagDetect* self, const Settings& s, const GstVideoInfo* info) {
  State& st = *self->state;

  const DetectorSettings wanted = s.detector_settings();
  if (st.detector && (st.built == wanted || st.rejected == wanted)) return TRUE;
  try {
    const Camera camera = lftag::gst::frame_camera(wanted.pinhole, st.calibration, GST_VIDEO_INFO_WIDTH(info),
                                                   GST_VIDEO_INFO_HEIGHT(info));
    st.detector.emplace(detector_params(wanted, camera));
    st.built = wanted;
    st.rejected.reset();
    const std::string ignored = lftag::gst::ignored_pinhole(wanted.pinhole, st.calibration.has_value());
    if (!ignored.empty()) GST_ELEMENT_WARNING(self, RESOURCE, SETTINGS, ("%s.", ignored.c_str()), (nullptr));
    GST_DEBUG_OBJECT(self, "detector for %s, camera fx %g fy %g cx %g cy %g%s", s.families_text.c_str(), camera.fx,
                     camera.fy, camera.cx, camera.cy, camera.calibrated ? "" : " (default)");
  } catch (const std::exception& e) {
    if (!st.detector) {
      GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("Invalid settings: %s.", e.what()), (nullptr));
      return FALSE;
    }
    GST_ELEMENT_WARNING(self, RESOURCE, SETTINGS,
                        ("Invalid settings: %s; the detector keeps the previous ones.", e.what()), (nullptr));
    st.rejected = wanted;
  }
  return TRUE;
}

/* Whether every plane of a mapped frame lies inside the memory mapped for it. A
 * GstVideoMeta (from appsrc, a camera driver or another element) states its own
 * offsets and strides, and gst_video_frame_map() trusts them: a stride larger than the
 * buffer would make the detector read, and the overlay write, past its end. Explains
 * the first plane that does not fit in `why`. */
static bool gst_lftag_detect_planes_fit(const GstVideoFrame* frame, std::string& why) {
  const GstVideoFormatInfo* finfo = frame->info.finfo;
  for (guint p = 0; p < GST_VIDEO_FRAME_N_PLANES(frame); ++p) {
    /* With a video meta each plane is mapped on its own; without one the buffer is
     * mapped whole into map[0] (and gst_video_frame_map checked its size). */
    const GstMapInfo& map = frame->map[frame->meta ? p : 0];
    const auto* data = static_cast<const guint8*>(frame->data[p]);
    const gint stride = GST_VIDEO_FRAME_PLANE_STRIDE(frame, p);
    /* The bytes one row of the plane spans, and how many rows it has. */
    guint64 row = 0, rows = 0;
    for (guint c = 0; c < GST_VIDEO_FORMAT_INFO_N_COMPONENTS(finfo); ++c) {
      if (GST_VIDEO_FORMAT_INFO_PLANE(finfo, c) != p) continue;
      const guint64 width = GST_VIDEO_FRAME_COMP_WIDTH(frame, c);
      const guint64 sample = (GST_VIDEO_FORMAT_INFO_DEPTH(finfo, c) + GST_VIDEO_FORMAT_INFO_SHIFT(finfo, c) + 7) / 8;
      if (width > 0)
        row = std::max(row, guint64(GST_VIDEO_FORMAT_INFO_POFFSET(finfo, c)) +
                                (width - 1) * guint64(GST_VIDEO_FORMAT_INFO_PSTRIDE(finfo, c)) + sample);
      rows = std::max(rows, guint64(GST_VIDEO_FRAME_COMP_HEIGHT(frame, c)));
    }
    if (rows == 0) continue;
    const guint8* end = map.data + map.size;
    const bool inside = data >= map.data && data <= end;
    if (stride < 0 || guint64(stride) < row || !inside || (rows - 1) * guint64(stride) + row > guint64(end - data)) {
      why = "plane " + std::to_string(p) + " (stride " + std::to_string(stride) + ", " + std::to_string(rows) +
            " rows of " + std::to_string(row) + " bytes) needs more than the " +
            std::to_string(inside ? guint64(end - data) : 0) + " bytes mapped for it";
      return false;
    }
  }
  return true;
}

/* The frame's luma as 8-bit grey: plane 0 itself, or computed from RGB. */
static lftag::ImageView gst_lftag_detect_luma(State& st, GstVideoFrame* frame) {
  const int width = GST_VIDEO_FRAME_WIDTH(frame), height = GST_VIDEO_FRAME_HEIGHT(frame);
  auto* data = static_cast<std::uint8_t*>(GST_VIDEO_FRAME_PLANE_DATA(frame, 0));
  const int stride = GST_VIDEO_FRAME_PLANE_STRIDE(frame, 0);

  if (st.luma_scale > 0) {
    /* Only the luma plane is converted, little-endian as the formats say. */
    const cv::Mat wide(height, width, CV_16UC1, data, std::size_t(stride));
    wide.convertTo(st.luma, CV_8U, st.luma_scale);
    return lftag::ImageView(st.luma);
  }
  if (st.luma_weights.empty()) return lftag::ImageView(data, width, height, stride);
  const cv::Mat packed(height, width, CV_8UC(st.luma_weights.cols), data, std::size_t(stride));
  cv::transform(packed, st.luma, st.luma_weights);
  return lftag::ImageView(st.luma);
}

/* The overlay: attached as a GstVideoOverlayCompositionMeta when downstream said
 * in the allocation query that it draws them (the frame is then not written, and
 * a frame shared with a tee is not copied), blended into the frame otherwise. */
static void gst_lftag_detect_draw(GstLFTagDetect* self, GstBuffer* buffer, const GstVideoInfo* info, const Settings& s,
                                  const Camera& camera, const std::vector<Detection>& detections) {
  State& st = *self->state;
  GstPad* srcpad = GST_BASE_TRANSFORM_SRC_PAD(self);
  if (g_atomic_int_compare_and_exchange(&self->downstream_changed, 1, 0)) st.ask_downstream = true;
  if (st.ask_downstream) {
    GstCaps* caps = gst_pad_get_current_caps(srcpad);
    st.attach_composition = lftag::gst::downstream_takes_compositions(srcpad, caps);
    if (caps) gst_caps_unref(caps);
    st.ask_downstream = false;
    GST_DEBUG_OBJECT(
        self, "the overlay is %s",
        st.attach_composition ? "attached as a GstVideoOverlayCompositionMeta" : "blended into the frames");
  }

  lftag::DrawOptions options;
  options.outline = s.overlay & GST_LFTAG_DETECT_OVERLAY_OUTLINE;
  options.id = s.overlay & GST_LFTAG_DETECT_OVERLAY_ID;
  options.axes = s.overlay & GST_LFTAG_DETECT_OVERLAY_AXES;
  GstVideoOverlayComposition* composition = nullptr;
  try {
    composition =
        st.overlay.compose(GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info), options, camera, detections);
  } catch (const std::exception& e) {
    GST_WARNING_OBJECT(self, "overlay failed: %s", e.what());
    st.overlay.reset(); /* it may hold a half-drawn frame */
    return;
  }
  if (st.attach_composition) {
    lftag::gst::attach_composition(buffer, composition);
  } else {
    GstVideoFrame frame;
    if (gst_video_frame_map(&frame, info, buffer, GST_MAP_READWRITE)) {
      gst_video_overlay_composition_blend(composition, &frame);
      gst_video_frame_unmap(&frame);
    } else {
      GST_WARNING_OBJECT(self, "cannot map %" GST_PTR_FORMAT " to draw on it", buffer);
    }
  }
  gst_video_overlay_composition_unref(composition);
}

/* Remembers downstream's QoS reports (the base class would drop late frames on
 * them, which is switched off), then lets the base class pass them upstream. */
static gboolean gst_lftag_detect_src_event(GstBaseTransform* trans, GstEvent* event) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(trans);

  if (GST_EVENT_TYPE(event) == GST_EVENT_QOS) {
    GstQOSType type;
    gdouble proportion;
    GstClockTimeDiff diff;
    GstClockTime timestamp;
    gst_event_parse_qos(event, &type, &proportion, &diff, &timestamp);
    GST_OBJECT_LOCK(self);
    if (GST_CLOCK_TIME_IS_VALID(timestamp)) {
      /* A late frame (diff > 0) means the next ones are late by as much again. */
      self->lateness.earliest = diff > 0
                                    ? timestamp + 2 * GstClockTime(diff)
                                    : GstClockTime(std::max<GstClockTimeDiff>(0, GstClockTimeDiff(timestamp) + diff));
      self->lateness.proportion = proportion;
    }
    GST_OBJECT_UNLOCK(self);
  } else if (GST_EVENT_TYPE(event) == GST_EVENT_FLUSH_START) {
    GST_OBJECT_LOCK(self);
    self->lateness = {GST_CLOCK_TIME_NONE, 1.0};
    GST_OBJECT_UNLOCK(self);
  } else if (GST_EVENT_TYPE(event) == GST_EVENT_RECONFIGURE) {
    /* A new sink may draw compositions where the last one did not, or not. */
    g_atomic_int_set(&self->downstream_changed, 1);
  }
  return GST_BASE_TRANSFORM_CLASS(parent_class)->src_event(trans, event);
}

/* What the per-frame bounds cut in a frame, named by the bound that was hit (the
 * candidate budget, max-candidates; the second looks' bound; lftag::kMaxOutlineReads),
 * with only the counts that are not 0: "held more candidate markers than the
 * per-frame budget allows (max-candidates=1): 2 candidates were skipped, ...". */
static std::string gst_lftag_detect_budget_text(const lftag::DetectionStats& stats,
                                                const lftag::DetectorParams& params) {
  std::vector<std::string> bounds, counts;
  /* A spent candidate budget also stops the second looks. */
  if (stats.skipped_by_budget > 0)
    bounds.push_back("held more candidate markers than the per-frame budget allows (max-candidates=" +
                     std::to_string(params.max_candidates) + ")");
  else if (stats.second_looks_skipped > 0)
    bounds.push_back("needed more second looks than the per-frame bound of " + std::to_string(params.max_second_looks));
  if (stats.outline_reads_skipped > 0)
    bounds.push_back("needed more outline reads than the per-frame bound of " +
                     std::to_string(lftag::kMaxOutlineReads));
  const auto count = [&](std::int64_t n, const char* one, const char* many) {
    if (n > 0) counts.push_back(std::to_string(n) + " " + (n == 1 ? one : many));
  };
  count(stats.skipped_by_budget, "candidate", "candidates");
  count(stats.second_looks_skipped, "second look", "second looks");
  count(stats.outline_reads_skipped, "outline read", "outline reads");
  const auto join = [](const std::vector<std::string>& items, const char* last) {
    std::string out;
    for (std::size_t i = 0; i < items.size(); ++i)
      out += (i == 0 ? "" : i + 1 == items.size() ? last : ", ") + items[i];
    return out;
  };
  const bool one = counts.size() == 1 && counts[0].compare(0, 2, "1 ") == 0;
  return join(bounds, " and ") + ": " + join(counts, " and ") + (one ? " was" : " were") +
         " skipped, the most plausible examined first";
}

/* Whether downstream's last QoS report makes this buffer late. */
static bool gst_lftag_detect_is_late(GstLFTagDetect* self, GstBuffer* buffer, gdouble* proportion,
                                     GstClockTimeDiff* jitter) {
  const GstSegment* segment = &GST_BASE_TRANSFORM(self)->segment;
  if (segment->format != GST_FORMAT_TIME || !GST_BUFFER_PTS_IS_VALID(buffer)) return false;
  const GstClockTime running = gst_segment_to_running_time(segment, GST_FORMAT_TIME, GST_BUFFER_PTS(buffer));
  GST_OBJECT_LOCK(self);
  const Lateness l = self->lateness;
  GST_OBJECT_UNLOCK(self);
  if (!GST_CLOCK_TIME_IS_VALID(running) || !GST_CLOCK_TIME_IS_VALID(l.earliest) || running > l.earliest) return false;
  *proportion = l.proportion;
  *jitter = GstClockTimeDiff(l.earliest) - GstClockTimeDiff(running);
  return true;
}

/* A late frame passed on unanalysed: a meta that says so, and a QoS message
 * counting it, as GStreamer elements report frames they degrade. */
static void gst_lftag_detect_skip_late(GstLFTagDetect* self, GstBuffer* buffer, const GstVideoInfo* info,
                                       gdouble proportion, GstClockTimeDiff jitter) {
  State& st = *self->state;
  ++st.skipped;
  lftag::gst::attach_unanalysed(buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info));

  const GstSegment* segment = &GST_BASE_TRANSFORM(self)->segment;
  const GstClockTime pts = GST_BUFFER_PTS(buffer);
  GstMessage* qos =
      gst_message_new_qos(GST_OBJECT(self), FALSE, gst_segment_to_running_time(segment, GST_FORMAT_TIME, pts),
                          gst_segment_to_stream_time(segment, GST_FORMAT_TIME, pts), pts, GST_BUFFER_DURATION(buffer));
  gst_message_set_qos_values(qos, jitter, proportion, 1000000);
  gst_message_set_qos_stats(qos, GST_FORMAT_BUFFERS, st.analysed, st.skipped);
  gst_element_post_message(GST_ELEMENT(self), qos);
  GST_DEBUG_OBJECT(self, "late by %" GST_STIME_FORMAT ": %" GST_TIME_FORMAT " passed on unanalysed",
                   GST_STIME_ARGS(jitter), GST_TIME_ARGS(pts));
}

/* Tracking, before the detection: the buffer's time for the tracker (its timestamp; one
 * going back, as after a seek, starts over; a gap longer than lost-after loses every
 * track; a buffer without one comes its duration, or 1/30 s, after the last), and what
 * the tracks expect in it: their markers where they predict them, and whether the whole
 * frame is searched (every full-detection-interval frames, and whenever nothing is
 * expected). */
static lftag::FrameHints gst_lftag_detect_hints(GstLFTagDetect* self, const Settings& s, GstBuffer* buffer) {
  State& st = *self->state;
  if (!st.tracker)
    st.tracker.emplace(s.tracker);
  else
    st.tracker->set_params(s.tracker); /* the ranges of the properties are the tracker's */
  double time = st.track_time + 1.0 / 30;
  if (GST_BUFFER_PTS_IS_VALID(buffer))
    time = double(GST_BUFFER_PTS(buffer)) / GST_SECOND;
  else if (GST_BUFFER_DURATION_IS_VALID(buffer))
    time = st.track_time + double(GST_BUFFER_DURATION(buffer)) / GST_SECOND;
  st.track_time = time;
  lftag::FrameHints hints;
  hints.expected = st.tracker->expected(time);
  hints.full_search = hints.expected.empty() || st.unsearched + 1 >= s.full_detection_interval;
  st.unsearched = hints.full_search ? 0 : st.unsearched + 1;
  return hints;
}

/* Tracking, after the detection: the frame's detections become the tracked markers
 * (the measured ones, then the predicted ones), `tracks` their tracks. */
static void gst_lftag_detect_track(GstLFTagDetect* self, std::vector<Detection>& detections,
                                   std::vector<lftag::TrackInfo>& tracks) {
  State& st = *self->state;
  const double time = st.track_time;
  std::vector<lftag::TrackedMarker> markers = st.tracker->update(time, detections);
  for (const lftag::TrackedMarker& m : st.tracker->lost())
    GST_DEBUG_OBJECT(self, "track %" G_GUINT64_FORMAT " (%s) lost at %.3f s, unseen since %.3f s", m.track.id,
                     lftag::gst::marker_key(m.detection.family, m.detection.id).c_str(), time, m.track.last_seen);
  detections.clear();
  tracks.clear();
  for (lftag::TrackedMarker& m : markers) {
    detections.push_back(std::move(m.detection));
    tracks.push_back(m.track);
  }
}

static GstFlowReturn gst_lftag_detect_transform_ip(GstBaseTransform* trans, GstBuffer* buffer) {
  GstLFTagDetect* self = GST_LFTAG_DETECT(trans);
  GstVideoInfo* info = &GST_VIDEO_FILTER(self)->in_info;
  State& st = *self->state;
  const Settings s = gst_lftag_detect_settings(self);

  if (GST_VIDEO_INFO_FORMAT(info) == GST_VIDEO_FORMAT_UNKNOWN) {
    GST_ELEMENT_ERROR(self, CORE, NEGOTIATION, (nullptr), ("format wasn't negotiated before the first frame"));
    return GST_FLOW_NOT_NEGOTIATED;
  }
  if (!gst_lftag_detect_update_detector(self, s, info)) return GST_FLOW_ERROR;

  gdouble proportion;
  GstClockTimeDiff jitter;
  if (s.late_frames == GST_LFTAG_DETECT_LATE_FRAMES_SKIP &&
      gst_lftag_detect_is_late(self, buffer, &proportion, &jitter)) {
    gst_lftag_detect_skip_late(self, buffer, info, proportion, jitter);
    return GST_FLOW_OK;
  }

  const Camera& camera = *st.detector->params().camera; /* always given */
  const bool metric = (s.overlay & GST_LFTAG_DETECT_OVERLAY_AXES) || s.tag_size_set;
  if (metric && !camera.calibrated && !st.warned_uncalibrated) {
    GST_ELEMENT_WARNING(self, RESOURCE, SETTINGS,
                        ("No camera calibration: poses assume the default camera (fx = fy = frame "
                         "width, centred) and are marked uncalibrated, so distances and axes are "
                         "not metric. Set calibration-file, or fx, fy, cx and cy."),
                        (nullptr));
    st.warned_uncalibrated = true;
  }

  /* Detection reads the frame only: a shared frame is not copied. */
  GstVideoFrame frame;
  if (!gst_video_frame_map(&frame, info, buffer, GST_MAP_READ)) {
    GST_WARNING_OBJECT(self, "cannot map %" GST_PTR_FORMAT ", passed on unanalysed", buffer);
    lftag::gst::attach_unanalysed(buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info));
    return GST_FLOW_OK;
  }
  std::string why;
  if (!gst_lftag_detect_planes_fit(&frame, why)) {
    gst_video_frame_unmap(&frame);
    if (!st.warned_layout) {
      GST_ELEMENT_WARNING(self, STREAM, FORMAT,
                          ("A frame's video meta describes planes larger than its memory: %s. Such frames are "
                           "passed on unanalysed; this is reported once per stream.",
                           why.c_str()),
                          ("%" GST_PTR_FORMAT, buffer));
      st.warned_layout = true;
    }
    GST_WARNING_OBJECT(self, "%" GST_PTR_FORMAT " passed on unanalysed: %s", buffer, why.c_str());
    lftag::gst::attach_unanalysed(buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info));
    return GST_FLOW_OK;
  }
  if (!s.tracking && st.tracker) {
    GST_DEBUG_OBJECT(self, "tracking switched off: %" G_GSIZE_FORMAT " tracks ended", st.tracker->size());
    st.tracker.reset();
  }
  const lftag::FrameHints hints = s.tracking ? gst_lftag_detect_hints(self, s, buffer) : lftag::FrameHints{};
  std::vector<Detection> detections;
  lftag::DetectionStats stats;
  try {
    detections = st.detector->detect(gst_lftag_detect_luma(st, &frame), hints, &stats);
  } catch (const std::exception& e) {
    gst_video_frame_unmap(&frame);
    GST_WARNING_OBJECT(self, "detection failed on %" GST_PTR_FORMAT ", passed on unanalysed: %s", buffer, e.what());
    lftag::gst::attach_unanalysed(buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info));
    return GST_FLOW_OK;
  }
  gst_video_frame_unmap(&frame);
  ++st.analysed;
  GST_LOG_OBJECT(self,
                 "%" G_GSIZE_FORMAT " markers at %" GST_TIME_FORMAT " (%s; %" G_GINT64_FORMAT " of %" G_GSIZE_FORMAT
                 " tracked markers read where predicted, %" G_GINT64_FORMAT " of them from the grey levels alone)",
                 detections.size(), GST_TIME_ARGS(GST_BUFFER_PTS(buffer)),
                 hints.full_search ? "searched" : "not searched", stats.expected_found, hints.expected.size(),
                 stats.expected_measured);
  if (stats.unlisted > 0)
    GST_DEBUG_OBJECT(self,
                     "%" G_GINT64_FORMAT " markers at %" GST_TIME_FORMAT " read as ids not in \"ids\": not reported",
                     stats.unlisted, GST_TIME_ARGS(GST_BUFFER_PTS(buffer)));
  if ((stats.skipped_by_budget > 0 || stats.second_looks_skipped > 0 || stats.outline_reads_skipped > 0) &&
      !st.warned_budget) {
    const std::string text = gst_lftag_detect_budget_text(stats, st.detector->params());
    GST_ELEMENT_WARNING(self, STREAM, FAILED,
                        ("The frame at %" GST_TIME_FORMAT " %s. Markers may be missed in such frames; this is "
                         "reported once per stream.",
                         GST_TIME_ARGS(GST_BUFFER_PTS(buffer)), text.c_str()),
                        ("%" G_GINT64_FORMAT " candidates, %" G_GINT64_FORMAT " second looks and %" G_GINT64_FORMAT
                         " outline reads skipped",
                         stats.skipped_by_budget, stats.second_looks_skipped, stats.outline_reads_skipped));
    st.warned_budget = true;
  }
  if (stats.past_deadline > 0 && !st.warned_deadline) {
    GST_ELEMENT_WARNING(
        self, STREAM, FAILED,
        ("The frame at %" GST_TIME_FORMAT " took longer than its deadline (deadline=%g ms): the search "
         "beyond the frame's own candidates (which were all examined) was cut short. Far or blurred "
         "markers may be missed in such frames; raise deadline, or set it to 0 for none. This is "
         "reported once per stream.",
         GST_TIME_ARGS(GST_BUFFER_PTS(buffer)), s.detector.deadline_ms),
        ("%" G_GINT64_FORMAT " second looks, border proposals, candidates in them and outline reads skipped",
         stats.skipped_by_deadline));
    st.warned_deadline = true;
  }

  std::vector<lftag::TrackInfo> tracks;
  if (s.tracking) gst_lftag_detect_track(self, detections, tracks);
  const std::vector<lftag::TrackInfo>* tracked = s.tracking ? &tracks : nullptr;

  lftag::gst::attach_detections(buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info), detections, tracked);

  if (s.overlay && !detections.empty()) gst_lftag_detect_draw(self, buffer, info, s, camera, detections);

  if (GstMessage* message =
          st.messages.frame(GST_OBJECT(self), s.messages, s.message_detections, GST_BASE_TRANSFORM(self)->segment,
                            buffer, GST_VIDEO_INFO_WIDTH(info), GST_VIDEO_INFO_HEIGHT(info), detections, tracked))
    gst_element_post_message(GST_ELEMENT(self), message);
  return GST_FLOW_OK;
}
