// SPDX-License-Identifier: LGPL-2.1-or-later
// Long runs: markers moving in lftagtestsrc video through lftagdetect with the overlay,
// for many frames, with the resident memory sampled; then many NULL -> PLAYING -> NULL
// cycles of the same pipeline. Fails when memory grows past a bound after warm-up, when a
// frame is lost, or when the detector stops finding markers.
//
//   soak [--frames N] [--width W] [--height H] [--cycles N] [--max-growth-mb MB]
//
// scripts/soak.sh runs the long version (100,000 frames at 1280x720, 1,000 cycles); the
// test suite a short one.
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <string>
#include <vector>

#include <gst/gst.h>

#include "lftag-meta.h"

namespace {

struct Options {
  long frames = 100000, cycles = 1000;
  int width = 1280, height = 720;
  double max_growth_mb = 4;
};

double resident_mb() {
  long pages_total = 0, pages_resident = 0;
  std::ifstream("/proc/self/statm") >> pages_total >> pages_resident;
  return double(pages_resident) * double(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

std::string launch_line(const Options& o, long frames) {
  return "lftagtestsrc num-buffers=" + std::to_string(frames) +
         " count=4 ids=6789,42,0x1f2e,1000 speed=2 ! video/x-raw,format=I420,width=" + std::to_string(o.width) +
         ",height=" + std::to_string(o.height) +
         " ! lftagdetect families=3x3,4x4 overlay=outline+id+axes fx=" + std::to_string(o.width) +
         " ! fakesink name=sink sync=false";
}

// Runs `pipeline` to EOS; false (with the message printed) on an error.
bool run_to_eos(GstElement* pipeline) {
  if (gst_element_set_state(pipeline, GST_STATE_PLAYING) == GST_STATE_CHANGE_FAILURE) {
    std::fprintf(stderr, "soak: the pipeline cannot start\n");
    return false;
  }
  GstBus* bus = gst_element_get_bus(pipeline);
  GstMessage* m =
      gst_bus_timed_pop_filtered(bus, GST_CLOCK_TIME_NONE, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR));
  bool ok = GST_MESSAGE_TYPE(m) == GST_MESSAGE_EOS;
  if (!ok) {
    GError* error = nullptr;
    gst_message_parse_error(m, &error, nullptr);
    std::fprintf(stderr, "soak: %s\n", error->message);
    g_error_free(error);
  }
  gst_message_unref(m);
  gst_object_unref(bus);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  return ok;
}

struct FrameCount {
  std::atomic<long> frames{0}, with_meta{0}, detections{0};
  std::mutex lock;
  std::vector<std::pair<long, double>> samples;  // frame, resident MB
  long every = 1000;
};

GstPadProbeReturn count_frame(GstPad*, GstPadProbeInfo* info, gpointer data) {
  auto* count = static_cast<FrameCount*>(data);
  GstBuffer* buffer = GST_PAD_PROBE_INFO_BUFFER(info);
  const long n = ++count->frames;
  if (const GstStructure* s = lftag_meta_get_structure(buffer, LFTAG_META_NAME)) {
    ++count->with_meta;
    const GValue* d = gst_structure_get_value(s, LFTAG_META_FIELD_DETECTIONS);
    if (d) count->detections += long(gst_value_array_get_size(d));
  }
  if (n % count->every == 0) {
    std::lock_guard<std::mutex> guard(count->lock);
    count->samples.emplace_back(n, resident_mb());
  }
  return GST_PAD_PROBE_OK;
}

// Growth from the level after warm-up (the largest of the first fifth of the samples,
// when buffers and caches have been made) to the largest of the last fifth.
double growth_after_warm_up(const std::vector<double>& mb) {
  const std::size_t fifth = std::max<std::size_t>(1, mb.size() / 5);
  double warm = 0, late = 0;
  for (std::size_t i = 0; i < fifth; ++i) warm = std::max(warm, mb[i]);
  for (std::size_t i = mb.size() - fifth; i < mb.size(); ++i) late = std::max(late, mb[i]);
  return late - warm;
}

bool soak_frames(const Options& o) {
  if (o.frames <= 0) return true;
  GError* error = nullptr;
  GstElement* pipeline = gst_parse_launch(launch_line(o, o.frames).c_str(), &error);
  if (!pipeline) {
    std::fprintf(stderr, "soak: %s\n", error->message);
    return false;
  }
  FrameCount count;
  count.every = std::max(1L, o.frames / 100);
  GstElement* sink = gst_bin_get_by_name(GST_BIN(pipeline), "sink");
  GstPad* pad = gst_element_get_static_pad(sink, "sink");
  gst_pad_add_probe(pad, GST_PAD_PROBE_TYPE_BUFFER, count_frame, &count, nullptr);
  gst_object_unref(pad);
  gst_object_unref(sink);
  const gint64 start = g_get_monotonic_time();
  const bool ok = run_to_eos(pipeline);
  const double seconds = double(g_get_monotonic_time() - start) / 1e6;
  gst_object_unref(pipeline);

  std::vector<double> mb;
  std::printf("frames  resident MB\n");
  for (const auto& [frame, resident] : count.samples) {
    mb.push_back(resident);
    if (frame % (count.every * 10) == 0) std::printf("%7ld  %.1f\n", frame, resident);
  }
  const double growth = mb.size() >= 2 ? growth_after_warm_up(mb) : 0;
  std::printf(
      "%ld frames %dx%d in %.0f s (%.0f fps), %ld with LFTagMeta, %.2f markers a frame; "
      "memory after warm-up %+.1f MB (bound %.1f)\n",
      count.frames.load(), o.width, o.height, seconds, count.frames / seconds, count.with_meta.load(),
      double(count.detections) / std::max(1L, count.frames.load()), growth, o.max_growth_mb);
  bool pass = ok;
  if (count.frames != o.frames || count.with_meta != o.frames) {
    std::fprintf(stderr, "soak: %ld of %ld frames came out, %ld with a meta\n", count.frames.load(), o.frames,
                 count.with_meta.load());
    pass = false;
  }
  if (double(count.detections) < 2.0 * double(o.frames)) {  // four markers move in the frame
    std::fprintf(stderr, "soak: too few markers found (%ld)\n", count.detections.load());
    pass = false;
  }
  if (growth > o.max_growth_mb) {
    std::fprintf(stderr, "soak: memory grew %.1f MB after warm-up\n", growth);
    pass = false;
  }
  return pass;
}

bool soak_state_cycles(const Options& o) {
  if (o.cycles <= 0) return true;
  Options small = o;
  small.width = 320, small.height = 240;
  std::vector<double> mb;
  const gint64 start = g_get_monotonic_time();
  for (long i = 0; i < o.cycles; ++i) {
    // A new pipeline each time half of the cycles, the same one re-run the other half.
    GstElement* pipeline = gst_parse_launch(launch_line(small, 3).c_str(), nullptr);
    const int runs = i % 2 ? 1 : 2;
    for (int r = 0; r < runs; ++r)
      if (!run_to_eos(pipeline)) {
        gst_object_unref(pipeline);
        return false;
      }
    gst_object_unref(pipeline);
    if ((i + 1) % std::max(1L, o.cycles / 100) == 0) mb.push_back(resident_mb());
  }
  const double growth = mb.size() >= 2 ? growth_after_warm_up(mb) : 0;
  std::printf("%ld NULL -> PLAYING -> NULL cycles in %.0f s; memory after warm-up %+.1f MB (bound %.1f)\n", o.cycles,
              double(g_get_monotonic_time() - start) / 1e6, growth, o.max_growth_mb);
  if (growth > o.max_growth_mb) {
    std::fprintf(stderr, "soak: memory grew %.1f MB over the state cycles\n", growth);
    return false;
  }
  return true;
}

bool parse(int argc, char** argv, Options& o) {
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    char* end = nullptr;
    const double v = std::strtod(argv[i + 1], &end);
    if (*end || !(v >= 0 && v <= 1e9)) return false;
    if (name == "--frames")
      o.frames = long(v);
    else if (name == "--cycles")
      o.cycles = long(v);
    else if (name == "--width")
      o.width = int(v);
    else if (name == "--height")
      o.height = int(v);
    else if (name == "--max-growth-mb")
      o.max_growth_mb = v;
    else
      return false;
  }
  return argc % 2 == 1 && o.width >= 16 && o.height >= 16;
}

}  // namespace

int main(int argc, char** argv) {
  gst_init(&argc, &argv);
  Options o;
  if (!parse(argc, argv, o)) {
    std::fprintf(stderr, "usage: soak [--frames N] [--width W] [--height H] [--cycles N] [--max-growth-mb MB]\n");
    return 2;
  }
  const bool ok = soak_frames(o) && soak_state_cycles(o);
  gst_deinit();
  return ok ? 0 : 1;
}
