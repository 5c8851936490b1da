// SPDX-License-Identifier: LGPL-2.1-or-later
// lftag annotate: a video through a GStreamer pipeline, decoded by uridecodebin, the markers
// found and drawn by lftagdetect, their JSON Lines written by lftagpublish, re-encoded into
// a new video file:
//
//   uridecodebin ! queue ! videoconvert ! lftagdetect ! [lftagpublish] ! queue
//     ! videoconvert ! capsfilter ! ENCODER ! MUXER ! filesink      (or fakesink)
//
// Files are written as NAME.part and renamed when the stream has ended, so a failed or
// interrupted run leaves no file that looks complete. A damaged input (decoder errors,
// frames missing, timestamps out of order, a file cut short) is annotated as far as it
// decodes, with a warning for each problem and their counts in the summary; --strict makes
// it exit status 3.
#include <unistd.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <glib-unix.h>
#include <gst/gst.h>
#include <gst/pbutils/pbutils.h>
#include <gst/video/video.h>

#include "../commands.hpp"
#include "elementtunables.h"
#include "gstplugin.hpp"
#include "lftag-meta.h"
#include "lftag/camera.hpp"
#include "lftag/family.hpp"
#include "timestamps.hpp"

namespace lftag::tools {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------
// Encoders and containers

// What the encoder is told once the frame size and rate are known.
struct Shape {
  int width = 0, height = 0;
  double fps = 0;  // 0: unknown (variable)
  double pixels_per_second() const { return double(width) * height * (fps > 0 && fps < 1000 ? fps : 30.0); }
};

// One encoder of a codec. `setup` runs before the pipeline starts, `configure` when the
// caps arrive (for settings that scale with the frame size and rate).
struct Encoder {
  const char* factory;
  const char* package;  // Debian 12
  void (*setup)(GstElement*);
  void (*configure)(GstElement*, const Shape&);
};

struct Codec {
  const char* name;
  std::vector<Encoder> encoders;  // the first one installed is used
};

void set(GstElement* e, const char* property, const std::string& value) {
  gst_util_set_object_arg(G_OBJECT(e), property, value.c_str());
}

// H.264 by x264 at constant quality (CRF 20: close to the source to the eye; the bit rate
// follows the picture), fast preset; the bit rate only caps peaks (0.6 bit per pixel).
const Encoder kX264{"x264enc", "gstreamer1.0-plugins-ugly",
                    [](GstElement* e) {
                      set(e, "pass", "qual");
                      set(e, "quantizer", "20");
                      set(e, "speed-preset", "veryfast");
                    },
                    [](GstElement* e, const Shape& s) {
                      const double kbps = std::clamp(0.6 * s.pixels_per_second() / 1000, 2000.0, 200000.0);
                      g_object_set(e, "bitrate", guint(kbps), nullptr);
                    }};
// Bit-rate encoders: 0.15 bit per pixel (720p at 30 fps: 4.1 Mb/s).
const Encoder kOpenH264{"openh264enc", "gstreamer1.0-plugins-bad", nullptr, [](GstElement* e, const Shape& s) {
                          g_object_set(e, "bitrate", guint(std::min(0.15 * s.pixels_per_second(), 2e9)), nullptr);
                        }};
const Encoder kAvH264{"avenc_h264", "gstreamer1.0-libav", nullptr, [](GstElement* e, const Shape& s) {
                        g_object_set(e, "bitrate", gint(std::min(0.15 * s.pixels_per_second(), 2e9)), nullptr);
                      }};
// libvpx scales its bit rate with the frame size and rate itself (bits-per-pixel, when
// target-bitrate is 0); real-time speed, and no coarse quantiser that makes blocks.
void vpx_setup(GstElement* e, const char* bits_per_pixel) {
  set(e, "target-bitrate", "0");
  set(e, "bits-per-pixel", bits_per_pixel);
  set(e, "deadline", "1");
  set(e, "cpu-used", "8");
  set(e, "max-quantizer", "44");
  set(e, "threads", std::to_string(std::max(1u, std::min(8u, g_get_num_processors()))));
}
const Encoder kVp8{"vp8enc", "gstreamer1.0-plugins-good", [](GstElement* e) { vpx_setup(e, "0.15"); }, nullptr};
const Encoder kVp9{"vp9enc", "gstreamer1.0-plugins-good",
                   [](GstElement* e) {
                     vpx_setup(e, "0.1");
                     set(e, "cpu-used", "8");
                     set(e, "row-mt", "true");
                   },
                   nullptr};
const Encoder kJpeg{"jpegenc", "gstreamer1.0-plugins-good", [](GstElement* e) { set(e, "quality", "90"); }, nullptr};

const Codec kH264{"H.264", {kX264, kOpenH264, kAvH264}};
const Codec kVP8{"VP8", {kVp8}};
const Codec kVP9{"VP9", {kVp9}};
const Codec kMJPEG{"Motion JPEG", {kJpeg}};

struct Container {
  std::vector<const char*> extensions;
  const char* muxer;
  const char* package;
  std::vector<const Codec*> codecs;  // the first with an installed encoder is used
};

const std::vector<Container>& containers() {
  static const std::vector<Container> all = {
      {{".mp4", ".m4v"}, "mp4mux", "gstreamer1.0-plugins-good", {&kH264}},
      {{".mov"}, "qtmux", "gstreamer1.0-plugins-good", {&kH264}},
      {{".mkv"}, "matroskamux", "gstreamer1.0-plugins-good", {&kH264, &kVP8, &kVP9}},
      {{".webm"}, "webmmux", "gstreamer1.0-plugins-good", {&kVP8, &kVP9}},
      {{".avi"}, "avimux", "gstreamer1.0-plugins-good", {&kMJPEG}},
  };
  return all;
}

bool installed(const char* factory) {
  GstElementFactory* f = gst_element_factory_find(factory);
  if (f) gst_object_unref(f);
  return f != nullptr;
}

struct Output {
  const Container* container = nullptr;
  const Codec* codec = nullptr;
  const Encoder* encoder = nullptr;
};

// Throws std::invalid_argument for an unknown extension (an option error) and
// std::runtime_error, saying what to install, when no encoder or muxer is there.
Output choose_output(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  std::string known;
  for (const Container& c : containers())
    for (const char* e : c.extensions) known += std::string(known.empty() ? "" : ", ") + e;
  for (const Container& c : containers()) {
    if (std::find(c.extensions.begin(), c.extensions.end(), ext) == c.extensions.end()) continue;
    if (!installed(c.muxer))
      throw std::runtime_error(std::string("no ") + c.muxer + " to write " + ext + " files: install " + c.package);
    for (const Codec* codec : c.codecs)
      for (const Encoder& e : codec->encoders)
        if (installed(e.factory)) return {&c, codec, &e};
    std::string want;
    for (const Codec* codec : c.codecs)
      for (const Encoder& e : codec->encoders)
        want += std::string(want.empty() ? "" : ", or ") + e.package + " (" + e.factory + ", " + codec->name + ")";
    // The fallback only when it would work.
    const bool webm = ext != ".webm" && installed("webmmux") && installed(kVp8.factory);
    throw std::runtime_error("no encoder for " + ext + " files: install " + want +
                             (webm ? ", or write a .webm file (VP8)" : std::string()));
  }
  throw std::invalid_argument("cannot tell the video type of '" + path + "' from its extension: use one of " + known);
}

// ---------------------------------------------------------------------------
// Decoders

// Debian 12's decoders of the common video codecs, by media type.
struct Decoder {
  const char* media_type;
  const char* factory;
  const char* package;
};
const std::vector<Decoder>& decoders() {
  static const std::vector<Decoder> all = {
      {"video/x-h264", "avdec_h264", "gstreamer1.0-libav"},
      {"video/x-h264", "openh264dec", "gstreamer1.0-plugins-bad"},
      {"video/x-h265", "avdec_h265", "gstreamer1.0-libav"},
      {"video/x-vp8", "vp8dec", "gstreamer1.0-plugins-good"},
      {"video/x-vp9", "vp9dec", "gstreamer1.0-plugins-good"},
      {"video/x-av1", "dav1ddec", "gstreamer1.0-plugins-bad"},
      {"video/x-av1", "avdec_av1", "gstreamer1.0-libav"},
      {"image/jpeg", "jpegdec", "gstreamer1.0-plugins-good"},
      {"video/mpeg", "avdec_mpeg4", "gstreamer1.0-libav"},
      {"video/mpeg", "mpeg2dec", "gstreamer1.0-plugins-ugly"},
      {"video/x-theora", "theoradec", "gstreamer1.0-plugins-base"},
  };
  return all;
}

// What to install for streams of `caps` (caps strings) that GStreamer found no decoder
// for: only packages whose decoder is not there (gst_element_factory_find), since
// suggesting one that is installed would not help.
std::string decoder_hint(const std::vector<std::string>& caps) {
  std::vector<std::string> want;
  bool known = false;
  for (const std::string& c : caps) {
    const std::string type = c.substr(0, c.find(','));
    for (const Decoder& d : decoders()) {
      if (type != d.media_type) continue;
      known = true;
      const std::string item = std::string(d.package) + " (" + d.factory + ")";
      if (!installed(d.factory) && std::find(want.begin(), want.end(), item) == want.end()) want.push_back(item);
    }
  }
  if (known && want.empty()) return "its decoders are installed but none accepts this stream (LFTAG_DEBUG=1 shows it)";
  if (want.empty()) return "install gstreamer1.0-libav (most formats), or gstreamer1.0-plugins-bad";
  std::string text = "install ";
  for (std::size_t i = 0; i < want.size(); ++i) text += (i ? ", or " : "") + want[i];
  return text;
}

// ---------------------------------------------------------------------------
// The run

struct Options : DetectorOptions {
  std::string input, output, jsonl, overlay;
  bool quiet = false, strict = false;
  bool tracking = false;
  double lost_after = 0.5;  // lftagdetect's lost-after default (lftag::TrackerParams)
  bool smoothing = false;
  unsigned full_detection_interval = 1;  // lftagdetect's default: every frame searched
};

// "outline,id,axes" (or with '+', or "none") as the overlay property's flags.
std::string overlay_flags(const std::string& text) {
  std::string out;
  std::string item;
  std::istringstream in(text);
  while (std::getline(in, item, text.find('+') != std::string::npos ? '+' : ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (item == "none" && text.find_first_of(",+") == std::string::npos) return "";
    if (item != "outline" && item != "id" && item != "axes")
      throw std::invalid_argument("--overlay: unknown item '" + item + "': use outline, id and axes, or none");
    out += (out.empty() ? "" : "+") + item;
  }
  if (out.empty()) throw std::invalid_argument("--overlay: use outline, id and axes, or none");
  return out;
}

std::string clock_text(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const long s = std::lround(seconds);
  char text[32];
  if (s >= 3600)
    std::snprintf(text, sizeof text, "%ld:%02ld:%02ld", s / 3600, s / 60 % 60, s % 60);
  else
    std::snprintf(text, sizeof text, "%ld:%02ld", s / 60, s % 60);
  return text;
}

// A file written as NAME.part and renamed NAME when complete; removed otherwise.
struct PartFile {
  std::string path;  // empty: none
  std::string part() const { return path + ".part"; }
  // Creates NAME.part now, so that an unwritable place fails before any decoding.
  void check_writable() const {
    if (path.empty()) return;
    FILE* f = std::fopen(part().c_str(), "w");
    if (!f) throw std::runtime_error("cannot write '" + path + "': " + g_strerror(errno));
    std::fclose(f);
  }
  void commit() const {
    if (path.empty()) return;
    std::error_code error;
    fs::rename(part(), path, error);
    if (error) throw std::runtime_error("cannot write '" + path + "': " + error.message());
  }
  void discard() const {
    if (path.empty()) return;
    std::error_code ignored;
    fs::remove(part(), ignored);
  }
};

class Annotator {
 public:
  Annotator(const Options& o, bool tag_size_given) : o_(o), tag_size_given_(tag_size_given) {}
  ~Annotator();
  // The exit status.
  int run();

 private:
  void build();
  GstElement* make(const char* factory, const char* package);
  void on_pad_added(GstPad* pad);
  GstPadProbeReturn on_buffer(GstBuffer* buffer);
  void on_decoded(GstPadProbeInfo* info);
  void report_damage(const char* kind, std::int64_t missing, const std::string& text);
  void count_damage(const GstStructure* s);
  void check_end();
  std::string damage_text() const;
  bool on_message(GstMessage* message);
  void progress(bool final);
  void fail(const std::string& why);
  void print_line(const std::string& line);
  void summary(double seconds);

  const Options& o_;
  const bool tag_size_given_;
  Output out_;
  PartFile video_, jsonl_;
  GstElement* pipeline_ = nullptr;
  GstElement* decode_ = nullptr;
  GstElement* first_ = nullptr;  // where the decoded video goes in
  GstElement* encoder_ = nullptr;
  GMainLoop* loop_ = nullptr;
  int status_ = 0;
  std::string error_;
  std::vector<std::string> missing_;       // decoders and demuxers GStreamer said it lacks
  std::vector<std::string> missing_caps_;  // the streams they were for
  bool video_linked_ = false;
  bool tty_ = false, progress_shown_ = false;
  int last_tenth_ = -1;
  std::chrono::steady_clock::time_point start_, last_line_;

  // Filled in the streaming thread.
  std::atomic<std::uint64_t> frames_{0};
  std::atomic<std::int64_t> first_pts_{-1}, position_{-1};  // ns; position from the first frame
  std::mutex seen_lock_;
  // The decoded stream, as it reaches the pipeline (under damage_lock_).
  std::mutex damage_lock_;
  TimestampWatch watch_;
  GstSegment segment_;
  bool decoded_any_ = false;
  // Damage found, counted in the main thread.
  std::uint64_t decoder_errors_ = 0, gaps_ = 0, missing_frames_ = 0, backwards_ = 0, cut_frames_ = 0;
  int damage_shown_ = 0;
  std::map<std::pair<std::string, std::string>, std::uint64_t> seen_;  // (family, id) -> frames
};

Annotator::~Annotator() {
  if (pipeline_) {
    gst_element_set_state(pipeline_, GST_STATE_NULL);
    gst_object_unref(pipeline_);
  }
  if (loop_) g_main_loop_unref(loop_);
}

GstElement* Annotator::make(const char* factory, const char* package) {
  GstElement* e = gst_element_factory_make(factory, nullptr);
  if (!e) throw std::runtime_error(std::string("GStreamer has no ") + factory + ": install " + package);
  gst_bin_add(GST_BIN(pipeline_), e);
  return e;
}

void Annotator::build() {
  pipeline_ = gst_pipeline_new("annotate");
  decode_ = make("uridecodebin", "gstreamer1.0-plugins-base");
  std::string uri = o_.input;
  if (!gst_uri_is_valid(uri.c_str())) {
    GError* error = nullptr;
    gchar* file_uri = gst_filename_to_uri(o_.input.c_str(), &error);
    if (!file_uri) {
      const std::string why = error->message;
      g_error_free(error);
      throw std::runtime_error("cannot read '" + o_.input + "': " + why);
    }
    uri = file_uri;
    g_free(file_uri);
  }
  g_object_set(decode_, "uri", uri.c_str(), nullptr);
  g_signal_connect(decode_, "pad-added", G_CALLBACK(+[](GstElement*, GstPad* pad, gpointer self) {
                     static_cast<Annotator*>(self)->on_pad_added(pad);
                   }),
                   this);
  // Every stream is there: without a video stream nothing would ever end.
  g_signal_connect(decode_, "no-more-pads", G_CALLBACK(+[](GstElement* decode, gpointer) {
                     gst_element_post_message(decode, gst_message_new_application(
                                                          GST_OBJECT(decode), gst_structure_new_empty("no-more-pads")));
                   }),
                   nullptr);

  GstElement* queue = make("queue", "gstreamer1.0-plugins-base (core)");
  GstElement* convert = make("videoconvert", "gstreamer1.0-plugins-base");
  GstElement* detect = make("lftagdetect", "the lftag plugin");
  first_ = queue;
  gst_element_link_many(queue, convert, detect, nullptr);
  // The decoded frames as they come out of the decoder: their timestamps and flags tell
  // of damage in the file.
  gst_segment_init(&segment_, GST_FORMAT_TIME);
  GstPad* decoded = gst_element_get_static_pad(queue, "sink");
  gst_pad_add_probe(
      decoded, GstPadProbeType(GST_PAD_PROBE_TYPE_BUFFER | GST_PAD_PROBE_TYPE_EVENT_DOWNSTREAM),
      [](GstPad*, GstPadProbeInfo* info, gpointer self) {
        static_cast<Annotator*>(self)->on_decoded(info);
        return GST_PAD_PROBE_OK;
      },
      this, nullptr);
  gst_object_unref(decoded);

  // The detector, as `lftag detect` would be set up.
  const PinholeSettings& pin = o_.pinhole;
  const bool camera = !o_.calibration.empty() || pin.fx.has_value();
  std::string overlay = o_.overlay.empty() ? (camera ? "outline+id+axes" : "outline+id") : overlay_flags(o_.overlay);
  if (o_.output.empty()) overlay.clear();  // nothing is drawn that nobody sees
  set(detect, "families", o_.families);
  if (!o_.ids.empty()) set(detect, "ids", o_.ids);
  set(detect, "messages", "none");
  set(detect, "overlay", overlay.empty() ? "0" : overlay);
  lftag::gst::set_tunable_properties(G_OBJECT(detect), o_.params);
  if (o_.tracking)
    g_object_set(detect, "tracking", TRUE, "lost-after", o_.lost_after, "smoothing", gboolean(o_.smoothing),
                 "full-detection-interval", guint(o_.full_detection_interval), nullptr);
  if (!o_.calibration.empty()) g_object_set(detect, "calibration-file", o_.calibration.c_str(), nullptr);
  // Only the options given: the element's own "not set" (0 for fx and fy, -1 for cx and
  // cy) never stands for a value.
  if (pin.fx) g_object_set(detect, "fx", *pin.fx, "fy", pin.fy.value_or(*pin.fx), nullptr);
  if (pin.cx) g_object_set(detect, "cx", *pin.cx, nullptr);
  if (pin.cy) g_object_set(detect, "cy", *pin.cy, nullptr);
  if (tag_size_given_) g_object_set(detect, "tag-size", o_.tag_size, nullptr);

  GstPad* pad = gst_element_get_static_pad(detect, "src");
  gst_pad_add_probe(
      pad, GST_PAD_PROBE_TYPE_BUFFER,
      [](GstPad*, GstPadProbeInfo* info, gpointer self) {
        return static_cast<Annotator*>(self)->on_buffer(GST_PAD_PROBE_INFO_BUFFER(info));
      },
      this, nullptr);
  gst_object_unref(pad);

  GstElement* last = detect;
  if (!o_.jsonl.empty()) {
    GstElement* publish = make("lftagpublish", "the lftag plugin");
    g_object_set(publish, "location", o_.jsonl == "-" ? "-" : jsonl_.part().c_str(), nullptr);
    // "frame" is the frame's index in the file, after a gap too.
    set(publish, "frame-numbers", "stream-time");
    gst_element_link(last, publish);
    last = publish;
  }

  if (o_.output.empty()) {
    GstElement* sink = make("fakesink", "gstreamer1.0-plugins-base (core)");
    g_object_set(sink, "sync", FALSE, nullptr);
    gst_element_link(last, sink);
    return;
  }
  GstElement* encode_queue = make("queue", "gstreamer1.0-plugins-base (core)");
  GstElement* convert_out = make("videoconvert", "gstreamer1.0-plugins-base");
  GstElement* filter = make("capsfilter", "gstreamer1.0-plugins-base (core)");
  // 4:2:0, which every player decodes (x264 would pick 4:4:4 for RGB input).
  GstCaps* caps = gst_caps_from_string("video/x-raw,format=I420");
  g_object_set(filter, "caps", caps, nullptr);
  gst_caps_unref(caps);
  encoder_ = make(out_.encoder->factory, out_.encoder->package);
  if (out_.encoder->setup) out_.encoder->setup(encoder_);
  GstElement* mux = make(out_.container->muxer, out_.container->package);
  GstElement* sink = make("filesink", "gstreamer1.0-plugins-base (core)");
  g_object_set(sink, "location", video_.part().c_str(), nullptr);
  if (!gst_element_link_many(last, encode_queue, convert_out, filter, encoder_, mux, sink, nullptr))
    throw std::runtime_error(std::string("cannot link ") + out_.encoder->factory + " to " + out_.container->muxer);

  if (out_.encoder->configure) {
    GstPad* sinkpad = gst_element_get_static_pad(encoder_, "sink");
    gst_pad_add_probe(
        sinkpad, GST_PAD_PROBE_TYPE_EVENT_DOWNSTREAM,
        [](GstPad*, GstPadProbeInfo* info, gpointer self) {
          GstEvent* event = GST_PAD_PROBE_INFO_EVENT(info);
          GstVideoInfo vinfo;
          if (GST_EVENT_TYPE(event) == GST_EVENT_CAPS) {
            GstCaps* caps = nullptr;
            gst_event_parse_caps(event, &caps);
            if (gst_video_info_from_caps(&vinfo, caps)) {
              auto* a = static_cast<Annotator*>(self);
              Shape shape{GST_VIDEO_INFO_WIDTH(&vinfo), GST_VIDEO_INFO_HEIGHT(&vinfo),
                          vinfo.fps_d > 0 ? double(vinfo.fps_n) / vinfo.fps_d : 0.0};
              a->out_.encoder->configure(a->encoder_, shape);
            }
          }
          return GST_PAD_PROBE_OK;
        },
        this, nullptr);
    gst_object_unref(sinkpad);
  }
}

// The decoded streams: the first video stream is annotated, the rest run into fakesinks.
void Annotator::on_pad_added(GstPad* pad) {
  GstCaps* caps = gst_pad_get_current_caps(pad);
  if (!caps) caps = gst_pad_query_caps(pad, nullptr);
  const bool video = caps && gst_caps_get_size(caps) > 0 &&
                     g_str_has_prefix(gst_structure_get_name(gst_caps_get_structure(caps, 0)), "video/");
  if (caps) gst_caps_unref(caps);
  if (video && !video_linked_) {
    GstPad* sinkpad = gst_element_get_static_pad(first_, "sink");
    video_linked_ = gst_pad_link(pad, sinkpad) == GST_PAD_LINK_OK;
    gst_object_unref(sinkpad);
    return;
  }
  GstElement* sink = gst_element_factory_make("fakesink", nullptr);
  g_object_set(sink, "sync", FALSE, "async", FALSE, nullptr);
  gst_bin_add(GST_BIN(pipeline_), sink);
  gst_element_sync_state_with_parent(sink);
  GstPad* sinkpad = gst_element_get_static_pad(sink, "sink");
  gst_pad_link(pad, sinkpad);
  gst_object_unref(sinkpad);
}

GstPadProbeReturn Annotator::on_buffer(GstBuffer* buffer) {
  if (GST_BUFFER_PTS_IS_VALID(buffer)) {
    const auto pts = std::int64_t(GST_BUFFER_PTS(buffer));
    if (first_pts_ < 0) first_pts_ = pts;
    position_ = pts - first_pts_;
  }
  if (const GstStructure* s = lftag_meta_get_structure(buffer, LFTAG_META_NAME)) {
    const GValue* list = gst_structure_get_value(s, LFTAG_META_FIELD_DETECTIONS);
    std::lock_guard<std::mutex> lock(seen_lock_);
    for (guint i = 0; list && i < gst_value_array_get_size(list); ++i) {
      const GstStructure* d = gst_value_get_structure(gst_value_array_get_value(list, i));
      const char* family = gst_structure_get_string(d, LFTAG_FIELD_FAMILY);
      const char* id = gst_structure_get_string(d, LFTAG_FIELD_ID_STRING);
      if (family && id) ++seen_[{family, id}];
    }
  }
  ++frames_;
  return GST_PAD_PROBE_OK;
}

// "1:02.345": where in the video a problem is.
std::string position_text(std::int64_t ns) {
  if (ns < 0) return "?";
  const double s = double(ns) / GST_SECOND;
  char text[32];
  std::snprintf(text, sizeof text, "%ld:%06.3f", long(s) / 60, std::fmod(s, 60.0));
  return text;
}

// In the streaming thread: each decoded frame's stream time, checked for gaps and order; a
// frame marked DISCONT after the first is one the decoder (or the demuxer) resumed at
// after damaged data. What is found goes to the main thread as an application message.
void Annotator::on_decoded(GstPadProbeInfo* info) {
  std::lock_guard<std::mutex> lock(damage_lock_);
  if (info->type & GST_PAD_PROBE_TYPE_EVENT_DOWNSTREAM) {
    GstEvent* event = GST_PAD_PROBE_INFO_EVENT(info);
    if (GST_EVENT_TYPE(event) == GST_EVENT_SEGMENT) {
      const GstSegment* segment = nullptr;
      gst_event_parse_segment(event, &segment);
      gst_segment_copy_into(segment, &segment_);
    } else if (GST_EVENT_TYPE(event) == GST_EVENT_CAPS) {
      GstCaps* caps = nullptr;
      gst_event_parse_caps(event, &caps);
      int n = 0, d = 1;
      if (caps && gst_caps_get_size(caps) > 0 &&
          !gst_structure_get_fraction(gst_caps_get_structure(caps, 0), "framerate", &n, &d))
        n = 0;
      watch_.set_rate(n, d);
    }
    return;
  }
  GstBuffer* buffer = GST_PAD_PROBE_INFO_BUFFER(info);
  if (!GST_BUFFER_PTS_IS_VALID(buffer) || segment_.format != GST_FORMAT_TIME) return;
  const GstClockTime stream_time = gst_segment_to_stream_time(&segment_, GST_FORMAT_TIME, GST_BUFFER_PTS(buffer));
  if (!GST_CLOCK_TIME_IS_VALID(stream_time)) return;
  const auto t = std::int64_t(stream_time);
  const auto duration = GST_BUFFER_DURATION_IS_VALID(buffer) ? std::int64_t(GST_BUFFER_DURATION(buffer)) : -1;
  const auto frame = [this](std::int64_t at) {
    return watch_.has_rate() ? " (frame " + std::to_string(watch_.index(at)) + ")" : std::string();
  };
  if (decoded_any_ && GST_BUFFER_FLAG_IS_SET(buffer, GST_BUFFER_FLAG_DISCONT))
    report_damage(
        "decoder", 0,
        "damaged data in '" + o_.input + "': decoding resumed at " + position_text(t) + frame(t) + " after an error");
  decoded_any_ = true;
  const std::optional<TimestampWatch::Finding> found = watch_.frame(t, duration);
  if (!found) return;
  if (found->kind == TimestampWatch::Kind::kGap) {
    const std::string frames = std::to_string(found->missing) + (found->missing == 1 ? " frame" : " frames");
    report_damage("gap", found->missing,
                  frames + " missing in '" + o_.input + "' between " + position_text(found->previous) +
                      frame(found->previous) + " and " + position_text(t) + frame(t) + " (a gap in the timestamps)");
  } else {
    report_damage("backwards", 0,
                  "the frame at " + position_text(t) + frame(t) + " in '" + o_.input +
                      "' does not come after the one before it (" + position_text(found->previous) +
                      "): its timestamp repeats or goes back");
  }
}

// From either thread: one damage warning, counted and printed in the main thread.
void Annotator::report_damage(const char* kind, std::int64_t missing, const std::string& text) {
  gst_element_post_message(
      pipeline_,
      gst_message_new_application(
          GST_OBJECT(pipeline_), gst_structure_new("lftag-damage", "kind", G_TYPE_STRING, kind, "missing", G_TYPE_INT64,
                                                   missing, "text", G_TYPE_STRING, text.c_str(), nullptr)));
}

void Annotator::count_damage(const GstStructure* s) {
  const std::string kind = gst_structure_get_string(s, "kind");
  gint64 missing = 0;
  gst_structure_get_int64(s, "missing", &missing);
  if (kind == "decoder") ++decoder_errors_;
  if (kind == "gap") ++gaps_, missing_frames_ += std::uint64_t(missing);
  if (kind == "backwards") ++backwards_;
  if (kind == "end") cut_frames_ += std::uint64_t(missing);
  // A badly damaged file would bury the progress in warnings: the first ones are shown,
  // all are counted.
  constexpr int kShown = 20;
  if (++damage_shown_ <= kShown)
    print_line("lftag annotate: warning: " + std::string(gst_structure_get_string(s, "text")));
  if (damage_shown_ == kShown) print_line("lftag annotate: warning: further damage is counted, not shown");
}

// At EOS: a stream that ends before the duration its container gives (a file cut short,
// or whose end is unreadable). The video stream's duration, not the longest stream's.
void Annotator::check_end() {
  GstPad* pad = gst_element_get_static_pad(first_, "sink");
  gint64 duration = -1;
  if (!gst_pad_peer_query_duration(pad, GST_FORMAT_TIME, &duration)) duration = -1;
  gst_object_unref(pad);
  std::lock_guard<std::mutex> lock(damage_lock_);
  const std::optional<TimestampWatch::Finding> found = watch_.end(duration);
  if (!found) return;
  const std::string frames = std::to_string(found->missing) + (found->missing == 1 ? " frame" : " frames");
  GstStructure* s = gst_structure_new(
      "lftag-damage", "kind", G_TYPE_STRING, "end", "missing", G_TYPE_INT64, gint64(found->missing), "text",
      G_TYPE_STRING,
      ("'" + o_.input + "' ends at " + position_text(found->previous) + ", before the " + position_text(duration) +
       " its container gives: " + frames + " missing (the file is cut short or its end is damaged)")
          .c_str(),
      nullptr);
  count_damage(s);
  gst_structure_free(s);
}

// "2 decoder errors, 1 gap (10 frames missing)", or empty for an intact input.
std::string Annotator::damage_text() const {
  std::string text;
  const auto add = [&text](std::uint64_t n, const char* one, const char* many, const std::string& more = "") {
    if (n == 0) return;
    text += (text.empty() ? "" : ", ") + std::to_string(n) + " " + (n == 1 ? one : many) + more;
  };
  add(decoder_errors_, "decoder error", "decoder errors");
  add(gaps_, "timestamp gap", "timestamp gaps",
      " (" + std::to_string(missing_frames_) + (missing_frames_ == 1 ? " frame" : " frames") + " missing)");
  add(backwards_, "timestamp out of order", "timestamps out of order");
  add(cut_frames_, "frame missing at the end", "frames missing at the end");
  return text;
}

void Annotator::fail(const std::string& why) {
  if (status_ == 0) {
    status_ = 1;
    error_ = why;
  }
  g_main_loop_quit(loop_);
}

// A line of its own, below the progress line if one is shown.
void Annotator::print_line(const std::string& line) {
  if (progress_shown_) std::cerr << "\r\033[K";
  std::cerr << line << "\n" << std::flush;
  progress_shown_ = false;
}

bool Annotator::on_message(GstMessage* message) {
  switch (GST_MESSAGE_TYPE(message)) {
    case GST_MESSAGE_ERROR: {
      GError* error = nullptr;
      gchar* debug = nullptr;
      gst_message_parse_error(message, &error, &debug);
      std::string why = error->message;
      while (!why.empty() && (why.back() == '.' || why.back() == '\n')) why.pop_back();
      const bool from_decoder =
          GST_MESSAGE_SRC(message) && gst_object_has_as_ancestor(GST_MESSAGE_SRC(message), GST_OBJECT(decode_));
      if (!missing_.empty()) {
        // What to install first; the stream's caps only after it, with LFTAG_DEBUG.
        std::string what;
        for (const std::string& m : missing_) what += (what.empty() ? "" : ", ") + m;
        why = "cannot decode '" + o_.input + "': GStreamer has no " + what + ": " + decoder_hint(missing_caps_);
      } else if (from_decoder || error->domain == GST_STREAM_ERROR) {
        why = "cannot decode '" + o_.input + "': " + why;
      }
      if (debug && g_getenv("LFTAG_DEBUG")) why += std::string(" (") + debug + ")";
      g_error_free(error);
      g_free(debug);
      fail(why);
      break;
    }
    case GST_MESSAGE_WARNING: {
      GError* error = nullptr;
      gchar* debug = nullptr;
      gst_message_parse_warning(message, &error, &debug);
      const bool from_decoder =
          GST_MESSAGE_SRC(message) && gst_object_has_as_ancestor(GST_MESSAGE_SRC(message), GST_OBJECT(decode_));
      const bool no_decoder = g_error_matches(error, GST_STREAM_ERROR, GST_STREAM_ERROR_CODEC_NOT_FOUND) ||
                              g_error_matches(error, GST_CORE_ERROR, GST_CORE_ERROR_MISSING_PLUGIN);
      if (no_decoder) {
        // A stream without a decoder: the error that follows when it is the video says
        // what to install; another stream (audio) is not used anyway.
        if (g_getenv("LFTAG_DEBUG")) print_line("lftag annotate: " + std::string(error->message));
      } else if (from_decoder) {
        // The demuxer or decoder met damaged data and went on.
        GstStructure* s = gst_structure_new("lftag-damage", "kind", G_TYPE_STRING, "decoder", "missing", G_TYPE_INT64,
                                            gint64(0), "text", G_TYPE_STRING,
                                            ("decoding '" + o_.input + "': " + error->message).c_str(), nullptr);
        count_damage(s);
        gst_structure_free(s);
      } else {
        print_line("lftag annotate: warning: " + std::string(error->message));
      }
      g_error_free(error);
      g_free(debug);
      break;
    }
    case GST_MESSAGE_ELEMENT:
      if (gst_is_missing_plugin_message(message)) {
        gchar* description = gst_missing_plugin_message_get_description(message);
        missing_.push_back(description ? description : "decoder");
        g_free(description);
        // "gstreamer|1.0|app|description|decoder-CAPS"
        gchar* detail = gst_missing_plugin_message_get_installer_detail(message);
        const std::string text = detail ? detail : "";
        g_free(detail);
        const std::size_t at = text.rfind("|decoder-");
        if (at != std::string::npos) missing_caps_.push_back(text.substr(at + 9));
      }
      break;
    case GST_MESSAGE_APPLICATION:
      if (gst_message_has_name(message, "no-more-pads") && !video_linked_)
        fail("'" + o_.input + "' has no video stream");
      if (gst_message_has_name(message, "lftag-damage")) count_damage(gst_message_get_structure(message));
      break;
    case GST_MESSAGE_EOS:
      if (!video_linked_) {
        fail("'" + o_.input + "' has no video stream");
      } else {
        check_end();
        g_main_loop_quit(loop_);
      }
      break;
    default: break;
  }
  return true;
}

// On a terminal a line redrawn in place; elsewhere (a log, a pipe) a plain line every
// tenth of the way, no more often than every 5 s, and nothing for a short run.
void Annotator::progress(bool final) {
  if (o_.quiet) return;
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const std::uint64_t frames = frames_;
  gint64 duration = -1;
  if (!gst_element_query_duration(pipeline_, GST_FORMAT_TIME, &duration)) duration = -1;
  const std::int64_t position = position_;
  double fraction = duration > 0 && position >= 0 ? std::clamp(double(position) / duration, 0.0, 1.0) : -1;
  if (final) fraction = 1;
  const double fps = elapsed > 0 ? frames / elapsed : 0;

  std::ostringstream line;
  if (fraction >= 0) line << std::setw(3) << int(fraction * 100) << " %  ";
  line << frames << " frames  " << std::fixed << std::setprecision(1) << fps << " fps  ";
  if (final)
    line << clock_text(elapsed);
  else if (fraction > 0.005)
    line << clock_text(elapsed * (1 - fraction) / fraction) << " left";
  else
    line << clock_text(elapsed);

  if (tty_) {
    std::cerr << "\r\033[K" << line.str() << (final ? "\n" : "") << std::flush;
    progress_shown_ = !final;
    return;
  }
  if (final || fraction < 0) return;
  const int tenth = int(fraction * 10);
  const double since = std::chrono::duration<double>(std::chrono::steady_clock::now() - last_line_).count();
  if (tenth > last_tenth_ && since >= 5) {
    std::cerr << line.str() << "\n" << std::flush;
    last_tenth_ = tenth;
    last_line_ = std::chrono::steady_clock::now();
  }
}

void Annotator::summary(double seconds) {
  if (o_.quiet) return;
  const std::uint64_t frames = frames_;
  std::cerr << "lftag annotate: " << frames << " frames in " << std::fixed << std::setprecision(1) << seconds << " s ("
            << (seconds > 0 ? frames / seconds : 0.0) << " frames per second)\n";
  std::lock_guard<std::mutex> lock(seen_lock_);
  if (seen_.empty()) {
    std::cerr << "  no markers found\n";
  } else {
    // By family, then id in numeric order.
    std::vector<std::pair<std::pair<std::string, std::string>, std::uint64_t>> rows(seen_.begin(), seen_.end());
    std::sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) {
      const auto& [fa, ia] = a.first;
      const auto& [fb, ib] = b.first;
      return fa != fb ? fa < fb : ia.size() != ib.size() ? ia.size() < ib.size() : ia < ib;
    });
    const std::size_t shown = std::min<std::size_t>(rows.size(), 20);
    std::cerr << "  " << rows.size() << (rows.size() == 1 ? " marker" : " markers") << " (frames seen in):";
    for (std::size_t i = 0; i < shown; ++i)
      std::cerr << (i ? "," : "") << " " << rows[i].first.first << " " << rows[i].first.second << " (" << rows[i].second
                << ")";
    if (shown < rows.size()) std::cerr << " and " << rows.size() - shown << " more";
    std::cerr << "\n";
  }
  const std::string damage = damage_text();
  if (!damage.empty()) std::cerr << "  damaged input: " << damage << "\n";
  if (!o_.output.empty())
    std::cerr << "  wrote " << o_.output << " (" << out_.codec->name << " by " << out_.encoder->factory << ")\n";
  if (!o_.jsonl.empty() && o_.jsonl != "-") std::cerr << "  wrote " << o_.jsonl << "\n";
  std::cerr << std::flush;
}

int Annotator::run() {
  if (!o_.output.empty()) {
    out_ = choose_output(o_.output);
    video_.path = o_.output;
  }
  if (!o_.jsonl.empty() && o_.jsonl != "-") jsonl_.path = o_.jsonl;
  // SIGTERM (what timeout, systemd and docker send) stops the run as Ctrl-C does: the
  // .part files removed, nothing left that looks complete. Caught from before the first
  // .part file is made; handled once the main loop runs.
  struct Interrupt {
    Annotator* self;
    int signal;
    int* caught;
  };
  int caught = 0;
  Interrupt on_int{this, SIGINT, &caught}, on_term{this, SIGTERM, &caught};
  const auto stop = [](gpointer data) -> gboolean {
    const auto* interrupt = static_cast<Interrupt*>(data);
    if (*interrupt->caught == 0) *interrupt->caught = interrupt->signal;
    g_main_loop_quit(interrupt->self->loop_);
    return G_SOURCE_CONTINUE;
  };
  const guint sigint = g_unix_signal_add(SIGINT, stop, &on_int);
  const guint sigterm = g_unix_signal_add(SIGTERM, stop, &on_term);
  try {
    video_.check_writable();
    jsonl_.check_writable();
    build();
  } catch (...) {
    g_source_remove(sigint);
    g_source_remove(sigterm);
    video_.discard();
    jsonl_.discard();
    throw;
  }

  loop_ = g_main_loop_new(nullptr, FALSE);
  GstBus* bus = gst_element_get_bus(pipeline_);
  const guint watch = gst_bus_add_watch(
      bus,
      [](GstBus*, GstMessage* m, gpointer self) -> gboolean { return static_cast<Annotator*>(self)->on_message(m); },
      this);
  gst_object_unref(bus);
  tty_ = isatty(STDERR_FILENO);
  start_ = last_line_ = std::chrono::steady_clock::now();
  const guint timer = g_timeout_add(
      tty_ ? 250 : 1000,
      [](gpointer self) -> gboolean {
        static_cast<Annotator*>(self)->progress(false);
        return G_SOURCE_CONTINUE;
      },
      this);

  if (gst_element_set_state(pipeline_, GST_STATE_PLAYING) == GST_STATE_CHANGE_FAILURE) {
    // The bus says why (a file that cannot be opened, a calibration that does not load).
    GstBus* b = gst_element_get_bus(pipeline_);
    while (GstMessage* m = gst_bus_pop(b)) {
      on_message(m);
      gst_message_unref(m);
    }
    gst_object_unref(b);
    if (status_ == 0) fail("the pipeline did not start");
  } else {
    g_main_loop_run(loop_);
  }
  g_source_remove(timer);
  g_source_remove(sigint);
  g_source_remove(sigterm);
  g_source_remove(watch);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  // Closes the files (the muxer wrote its index at EOS).
  gst_element_set_state(pipeline_, GST_STATE_NULL);

  if (caught != 0 || status_ != 0) {
    video_.discard();
    jsonl_.discard();
    if (progress_shown_) std::cerr << "\r\033[K";
    if (caught != 0) {
      std::cerr << "lftag annotate: interrupted (" << (caught == SIGTERM ? "SIGTERM" : "SIGINT")
                << "); nothing written\n";
      return 128 + caught;  // the shell's status for a process the signal stopped
    }
    std::cerr << "lftag annotate: " << error_ << "\n";
    return status_;
  }
  progress(true);
  try {
    video_.commit();
    jsonl_.commit();
  } catch (...) {
    video_.discard();
    jsonl_.discard();
    throw;
  }
  summary(seconds);
  const std::string damage = damage_text();
  if (o_.strict && !damage.empty()) {
    // The files are written all the same: every frame that decoded is in them.
    std::cerr << "lftag annotate: '" << o_.input << "' is damaged (" << damage << "): exit status 3 (--strict)\n";
    return 3;
  }
  return 0;
}

}  // namespace

void add_annotate_command(CLI::App& app, int& status) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "annotate",
      "Annotate a video: markers outlined and labelled in a new video file, and their detections in every frame "
      "as JSON Lines. Reads whatever GStreamer decodes; runs the lftag plugin's lftagdetect and lftagpublish.");
  cmd->add_option("input", opt->input, "Video file (or URI) to read: any container and codec GStreamer decodes")
      ->required();
  cmd->add_option("-o,--output", opt->output,
                  "Annotated video to write; its extension picks the format: .mp4, .m4v, .mov (H.264), .mkv "
                  "(H.264, else VP8), .webm (VP8), .avi (Motion JPEG)");
  cmd->add_option("--jsonl", opt->jsonl,
                  "Write the detections of every frame as JSON Lines (\"-\": standard output), keyed by frame "
                  "number and timestamp; each detection as `lftag detect` prints it");
  add_detector_options(cmd, *opt);
  CLI::Option* tag_size = cmd->get_option("--tag-size");
  cmd->add_option("--overlay", opt->overlay,
                  "What to draw: outline, id and axes, comma-separated, or none (default outline,id, and axes "
                  "too when a camera is given by --calibration or --fx)");
  cmd->add_flag("--tracking", opt->tracking,
                "Track each marker from frame to frame (lftagdetect's tracking): every JSON detection gets a "
                "\"track\" (id, state measured or predicted, age, first and last seen), and a marker missed "
                "for a moment is kept as predicted until --lost-after has passed");
  cmd->add_option("--lost-after", opt->lost_after,
                  "With --tracking: seconds a marker may go undetected before its track is lost (default 0.5)")
      ->check(CLI::Range(0.0, 3600.0));
  cmd->add_flag("--smoothing", opt->smoothing,
                "With --tracking: a One Euro filter on each track's pose, written as the track's "
                "\"smoothed_pose\" beside the raw one");
  cmd->add_option("--full-detection-interval", opt->full_detection_interval,
                  "With --tracking: search the whole frame every N frames, and in between only read the tracked "
                  "markers where their tracks predict them (much faster; new markers are found at the next "
                  "full search). Default 1: every frame")
      ->check(CLI::Range(1, 1 << 30));
  cmd->add_flag("-q,--quiet", opt->quiet, "No progress and no summary (errors and warnings only)");
  cmd->add_flag("--strict", opt->strict,
                "Exit with status 3 when the input is damaged (decoder errors, frames missing, timestamps out "
                "of order, a file cut short); the outputs are written all the same");
  cmd->callback([opt, tag_size, &status] {
    const Options& o = *opt;
    try {
      if (o.output.empty() && o.jsonl.empty())
        throw std::invalid_argument("nothing to write: give --output, --jsonl or both");
      DetectorParams checked;
      set_families_and_ids(o, checked);
      if (!o.overlay.empty()) overlay_flags(o.overlay);
      if (!o.tracking && (o.smoothing || o.lost_after != Options().lost_after ||
                          o.full_detection_interval != Options().full_detection_interval))
        throw std::invalid_argument("--lost-after, --smoothing and --full-detection-interval need --tracking");
      if (!o.calibration.empty()) Camera::load(o.calibration);
      check_camera_options(o);
      // lftagdetect's ranges, narrower than the still-image tool's.
      using Range = std::tuple<const char*, std::optional<double>, double, double>;
      for (const auto& [name, value, lo, hi] :
           {Range{"--fx", o.pinhole.fx, 1e-3, 1e6}, Range{"--fy", o.pinhole.fy, 1e-3, 1e6},
            Range{"--cx", o.pinhole.cx, 0.0, 1e6}, Range{"--cy", o.pinhole.cy, 0.0, 1e6},
            Range{"--tag-size", o.tag_size, 1e-3, 100.0}})
        if (value && (*value < lo || *value > hi))
          throw std::invalid_argument(std::string(name) + " must be from " + CLI::detail::to_string(lo) + " to " +
                                      CLI::detail::to_string(hi) + " for video");
      if (!o.output.empty() && !o.jsonl.empty() && fs::absolute(o.output) == fs::absolute(o.jsonl))
        throw std::invalid_argument("--output and --jsonl name the same file");
    } catch (const std::exception& e) {
      std::cerr << "lftag annotate: " << e.what() << "\n";
      status = 2;
      return;
    }
    if (o.input.find("://") == std::string::npos) {
      std::error_code error;
      if (!fs::is_regular_file(o.input, error)) {
        std::cerr << "lftag annotate: cannot read '" << o.input
                  << "': " << (fs::exists(o.input, error) ? "not a file" : "no such file") << "\n";
        status = 1;
        return;
      }
    }
    const std::string no_plugin = init_gstreamer_with_plugin();
    if (!no_plugin.empty()) {
      std::cerr << "lftag annotate: " << no_plugin << "\n";
      status = 1;
      return;
    }
    try {
      Annotator annotator(o, tag_size->count() > 0);
      status = annotator.run();
    } catch (const std::invalid_argument& e) {
      std::cerr << "lftag annotate: " << e.what() << "\n";
      status = 2;
    } catch (const std::exception& e) {
      std::cerr << "lftag annotate: " << e.what() << "\n";
      status = 1;
    }
  });
}

}  // namespace lftag::tools
