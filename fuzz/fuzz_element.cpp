// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: lftagdetect's input as an application, a camera driver or another
// element may send it, through a GstHarness: caps of every format of its sink template
// at any size up to 256 x 256, buffers with and without a GstVideoMeta whose strides and
// offsets may lie (larger than the memory, past its end, negative), buffers too short or
// too long and split into several memories, upstream metas to replace, the overlay on
// or off (blended, or attached when downstream takes compositions), and the properties
// (families, also refused ones, deadline, messages, late-frames with a QoS event, the
// camera) changed while it plays. The element must never crash, read or write outside a buffer,
// post an error or log a critical, and every buffer must come out, with an LFTagMeta of
// the caps' size; a frame whose layout is true, in one memory, and not late, is analysed.
//
// The input format is element_input.hpp's (make_corpus writes the seeds).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <gst/check/gstharness.h>
#include <gst/video/video.h>

#include "check.hpp"
#include "element_input.hpp"
#include "gst_fuzz.hpp"
#include "lftag-meta.h"
#include "metaconversion.h"

using lftag::fuzz::check;
using lftag::fuzz::Reader;
namespace input = lftag::fuzz::element;

namespace {

std::vector<GstVideoFormat> formats;  // input::kFormats

// The formats lftagdetect's sink pad takes, from its template (DETECT_FORMATS), must be
// those the input names: else the target would miss a format, or fail on one.
void check_formats() {
  std::vector<std::string> listed;
  GstElementFactory* factory = gst_element_factory_find("lftagdetect");
  check(factory != nullptr, "no lftagdetect factory");
  for (const GList* t = gst_element_factory_get_static_pad_templates(factory); t; t = t->next) {
    auto* pad = static_cast<GstStaticPadTemplate*>(t->data);
    if (pad->direction != GST_PAD_SINK) continue;
    GstCaps* caps = gst_static_caps_get(&pad->static_caps);
    const GValue* list = gst_structure_get_value(gst_caps_get_structure(caps, 0), "format");
    for (guint i = 0; list && i < gst_value_list_get_size(list); ++i)
      listed.push_back(g_value_get_string(gst_value_list_get_value(list, i)));
    gst_caps_unref(caps);
  }
  gst_object_unref(factory);
  const std::vector<std::string> expected(std::begin(input::kFormats), std::end(input::kFormats));
  if (listed != expected) {
    std::fprintf(stderr, "lftagdetect's sink formats are not element_input.hpp's kFormats:");
    for (const std::string& f : listed) std::fprintf(stderr, " %s", f.c_str());
    std::fprintf(stderr, "\n");
    std::abort();
  }
  for (const char* name : input::kFormats) formats.push_back(gst_video_format_from_string(name));
}

GstVideoInfo read_caps(Reader& in) {
  const GstVideoFormat format = formats[in.u8() % formats.size()];
  const guint width = 1 + in.u16() % input::kMaxSide, height = 1 + in.u16() % input::kMaxSide;
  GstVideoInfo info;
  gst_video_info_set_format(&info, format, width, height);
  info.fps_n = 30;
  info.fps_d = 1;
  return info;
}

void set_caps(GstHarness* h, const GstVideoInfo& info) { gst_harness_set_src_caps(h, gst_video_info_to_caps(&info)); }

// Bytes [from, from + size) of a buffer that repeats `pattern` (or, without one, a ramp),
// in a block of exactly `size` bytes, malloc'd, so that AddressSanitizer sees the first
// byte past it.
GstMemory* memory(gsize from, gsize size, const std::uint8_t* pattern, std::size_t pattern_size) {
  auto* data = static_cast<guint8*>(g_malloc(size));
  if (pattern_size == 0) {
    for (gsize i = 0; i < size; ++i) data[i] = guint8((from + i) * 7);
  } else {
    for (gsize i = 0; i < size;) {
      const gsize at = (from + i) % pattern_size, n = std::min<gsize>(size - i, pattern_size - at);
      std::memcpy(data + i, pattern + at, n);
      i += n;
    }
  }
  return gst_memory_new_wrapped(GstMemoryFlags(0), data, size, 0, size, data, g_free);
}

// Metas an upstream element might have left, which lftagdetect replaces: an LFTagMeta
// and regions of interest, of lftag and of another analyser.
void add_upstream_metas(GstBuffer* buffer) {
  lftag::gst::add_detection_meta(buffer, 7, 5, {lftag::Detection{}});
  gst_buffer_add_video_region_of_interest_meta(buffer, "lftag", 1, 2, 3, 4);
  gst_buffer_add_video_region_of_interest_meta(buffer, "face", 0, 0, 8, 8)->id = 41;
}

// One buffer of the stream. Returns whether its layout is the caps' own (or a padded
// one that a true video meta announces) in one memory that holds it: such a frame
// must be analysed.
GstBuffer* make_buffer(Reader& in, unsigned flags, const GstVideoInfo& caps, bool* true_layout) {
  GstVideoInfo layout = caps;
  const bool meta = flags & input::kMeta;
  if (meta) {
    // Padding GStreamer itself would allocate (gst_video_info_align): announced by the meta.
    GstVideoAlignment align;
    gst_video_alignment_reset(&align);
    align.padding_right = in.u8() % 16;
    align.padding_bottom = in.u8() % 4;
    const std::uint8_t stride_align = in.u8();
    for (guint p = 0; p < GST_VIDEO_MAX_PLANES; ++p) align.stride_align[p] = (1u << (stride_align % 7)) - 1;
    check(gst_video_info_align(&layout, &align), "gst_video_info_align failed");
  }
  gint stride[GST_VIDEO_MAX_PLANES];
  gsize offset[GST_VIDEO_MAX_PLANES];
  bool lied = false;
  gint meta_width = caps.width, meta_height = caps.height;
  for (guint p = 0; p < GST_VIDEO_MAX_PLANES; ++p) stride[p] = layout.stride[p], offset[p] = layout.offset[p];
  if (meta) {
    for (guint p = 0; p < GST_VIDEO_INFO_N_PLANES(&layout); ++p) {
      const std::uint8_t kind = in.u8();
      const std::uint32_t v = in.u32();
      switch (kind % 8) {
        case input::kStrideOff: stride[p] += std::int16_t(v); break;  // a few bytes off, either way
        case input::kStrideNegative: stride[p] = -std::max(1, std::abs(stride[p])); break;
        case input::kStrideAny: stride[p] = gint(v); break;  // anything, a gigabyte included
        case input::kOffsetOff: offset[p] += v % 65536; break;
        case input::kOffsetAny: offset[p] = v; break;  // past the buffer's end, most likely
        case input::kBothOff:
          stride[p] += std::int16_t(v);
          offset[p] += v >> 16;
          break;
        default: break;  // the truth
      }
      lied |= stride[p] != layout.stride[p] || offset[p] != layout.offset[p];
    }
    // A meta may describe a larger frame than the caps (GStreamer allows it).
    const std::uint8_t extra = in.u8();
    meta_width += extra & 3;
    meta_height += (extra >> 2) & 3;
    lied |= meta_width != caps.width || meta_height != caps.height;
  }
  const gsize needed = GST_VIDEO_INFO_SIZE(&layout);
  gsize size = needed;
  const std::uint8_t size_kind = in.u8();
  const std::uint32_t size_value = in.u32();
  switch (size_kind % 4) {
    case input::kShort: size = needed - std::min<gsize>(size_value % (needed + 1), needed - 1); break;
    case input::kLong: size = needed + size_value % 4096; break;
    case input::kAny: size = 1 + size_value % (2 * needed); break;
    default: break;
  }
  std::vector<gsize> cuts;
  if (flags & input::kSplit)
    for (int n = 1 + in.u8() % 3; n > 0; --n) cuts.push_back(1 + in.u16() % size);
  cuts.push_back(size);
  std::sort(cuts.begin(), cuts.end());
  cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  const std::uint8_t* pattern = nullptr;
  const std::size_t pattern_size = in.take(in.u16(), &pattern);

  GstBuffer* buffer = gst_buffer_new();
  gsize from = 0;
  for (gsize cut : cuts) {
    gst_buffer_append_memory(buffer, memory(from, cut - from, pattern, pattern_size));
    from = cut;
  }
  if (meta)
    gst_buffer_add_video_meta_full(buffer, GST_VIDEO_FRAME_FLAG_NONE, GST_VIDEO_INFO_FORMAT(&caps), meta_width,
                                   meta_height, GST_VIDEO_INFO_N_PLANES(&caps), offset, stride);
  if (flags & input::kUpstreamMetas) add_upstream_metas(buffer);
  // Without a meta a frame is mapped whole (its memories merged), so only its size counts.
  *true_layout = !lied && size >= needed && (!meta || cuts.size() == 1);
  return buffer;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  lftag::fuzz::start_gstreamer();
  check_formats();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Reader in(data, size);
  GstVideoInfo caps = read_caps(in);
  const std::uint8_t settings = in.u8(), families = in.u8(), deadline = in.u8(), window = in.u8();
  const int buffers = 1 + in.u8() % 4;

  GstElement* element = GST_ELEMENT(gst_object_ref_sink(gst_element_factory_make("lftagdetect", nullptr)));
  GstBus* bus = gst_bus_new();
  gst_element_set_bus(element, bus);
  guint overlay = settings & (input::kOverlayOutline | input::kOverlayId | input::kOverlayAxes);
  std::string family_list;
  for (int n = 2; n <= 8; ++n)
    if (families & (1 << (n - 2)))
      family_list += (family_list.empty() ? "" : ",") + std::to_string(n) + "x" + std::to_string(n);
  const bool late_frames = settings & input::kLateFrames;
  g_object_set(element, "overlay", overlay, "second-look", gboolean(!(settings & input::kNoSecondLook)), "messages",
               (settings >> input::kMessagesShift) & 3, "late-frames", gint(late_frames), "deadline",
               0.25 * (1 + deadline % 16), "threshold-window", 2 + window % 63, nullptr);
  if (!family_list.empty()) g_object_set(element, "families", family_list.c_str(), nullptr);

  // Plays at once (the harness starts a filter), then negotiates the caps.
  GstHarness* h = gst_harness_new_with_element(element, "sink", "src");
  if (settings & input::kCompositions)
    gst_harness_add_propose_allocation_meta(h, GST_VIDEO_OVERLAY_COMPOSITION_META_API_TYPE, nullptr);
  set_caps(h, caps);
  if (late_frames)  // downstream says the frames are late, up to some time
    gst_harness_push_upstream_event(
        h, gst_event_new_qos(GST_QOS_TYPE_UNDERFLOW, 0.5, GstClockTimeDiff(in.u16()) * GST_MSECOND,
                             GstClockTime(in.u8()) * 10 * GST_MSECOND));

  for (int i = 0; i < buffers; ++i) {
    const std::uint8_t flags = in.u8();
    if (flags & input::kNewCaps) {
      caps = read_caps(in);
      set_caps(h, caps);
    }
    if (flags & input::kFamiliesText) {  // anything, refused (a warning) or not
      const std::string text = in.text();
      g_object_set(element, "families", text.c_str(), nullptr);
    }
    // A camera that does not fit the frame is refused with a warning once a detector
    // exists (before the first frame it would be an error, and the stream would stop).
    if ((flags & input::kCamera) && i > 0) {
      const double fx = in.u16() / 4.0, fy = in.u16() / 4.0, cx = in.u16() / 16.0 - 1, cy = in.u16() / 16.0 - 1;
      const double tag_size = 0.01 * (1 + in.u8());
      const std::string distortion = in.text();
      g_object_set(element, "fx", fx, "fy", fy, "cx", cx, "cy", cy, "tag-size", tag_size, "distortion",
                   distortion.c_str(), nullptr);
    }
    if (flags & input::kFlipOverlay) g_object_set(element, "overlay", overlay ^= 7, nullptr);
    bool true_layout = false;
    GstBuffer* buffer = make_buffer(in, flags, caps, &true_layout);
    if (!(flags & input::kNoTimestamp)) {
      GST_BUFFER_PTS(buffer) = GstClockTime(i) * 33 * GST_MSECOND;
      GST_BUFFER_DURATION(buffer) = 33 * GST_MSECOND;
    }
    check(gst_harness_push(h, buffer) == GST_FLOW_OK, "a buffer was refused");
    GstBuffer* out = gst_harness_try_pull(h);
    check(out != nullptr, "a buffer did not come out");
    const auto meta = lftag::gst::read_detection_meta(out);
    check(meta.has_value(), "a buffer came out without its LFTagMeta");
    check(meta->width == GST_VIDEO_INFO_WIDTH(&caps) && meta->height == GST_VIDEO_INFO_HEIGHT(&caps),
          "an LFTagMeta of another size than the caps'");
    check(meta->analysed || !true_layout || late_frames, "a frame of a true layout was not analysed");
    gst_buffer_unref(out);
  }

  while (GstMessage* m = gst_bus_pop(bus)) {
    if (GST_MESSAGE_TYPE(m) == GST_MESSAGE_ERROR) {
      GError* error = nullptr;
      gchar* debug = nullptr;
      gst_message_parse_error(m, &error, &debug);
      std::fprintf(stderr, "error message: %s (%s)\n", error->message, debug ? debug : "");
      std::abort();
    }
    gst_message_unref(m);
  }
  gst_harness_teardown(h);
  gst_element_set_bus(element, nullptr);
  gst_object_unref(bus);
  gst_object_unref(element);
  return 0;
}
