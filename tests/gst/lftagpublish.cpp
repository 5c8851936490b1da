// SPDX-License-Identifier: LGPL-2.1-or-later
// lftagpublish: one JSON line per buffer with an LFTagMeta, matching the meta (the same
// JSON as `lftag detect`) and the buffer's timestamps; to a file or the standard output;
// append; an unwritable location fails the start; which metas survive encoders, decoders
// and muxers; a warning when there is no meta; a failed write leaves whole lines only and
// says which frame is lost; a file deleted, moved or replaced while written is an error;
// at EOS, when stopped mid-stream and after an error downstream every frame received is
// in the file, whole, and the file is closed.
// lftagdetect runs with deadline=0: its deadline's warning, which a loaded or sanitized
// machine can post, is not the subject here and would spoil the warning counts.
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <glib/gstdio.h>
#include <gst/check/gstharness.h>
#include <nlohmann/json.hpp>

#include "detection_json.hpp"
#include "errors.hpp"
#include "frames.hpp"
#include "metaconversion.h"
// Last: check's macros (fail...) clash with names in the C++ library.
#include "check-main.h"

namespace {

struct Seen {
  GstClockTime pts, dts, duration;
  GstStructure* meta;  // may be null
};

struct Run {
  std::vector<Seen> buffers;  // as they reached the sink
  std::vector<GstMessage*> warnings;
  GMutex lock;
  Run() { g_mutex_init(&lock); }
  ~Run() {
    for (Seen& s : buffers)
      if (s.meta) gst_structure_free(s.meta);
    for (GstMessage* m : warnings) gst_message_unref(m);
    g_mutex_clear(&lock);
  }
};

// Runs `launch` (with a sink named "sink") to EOS, recording what reaches the sink and the
// warnings; an error fails the test.
void run_pipeline(const std::string& launch, Run& run) {
  GError* error = nullptr;
  GstElement* pipeline = gst_parse_launch(launch.c_str(), &error);
  fail_unless(pipeline != nullptr && error == nullptr, "cannot build %s: %s", launch.c_str(),
              error ? error->message : "");
  GstElement* sink = gst_bin_get_by_name(GST_BIN(pipeline), "sink");
  GstPad* pad = gst_element_get_static_pad(sink, "sink");
  gst_pad_add_probe(
      pad, GST_PAD_PROBE_TYPE_BUFFER,
      [](GstPad*, GstPadProbeInfo* info, gpointer data) {
        auto* run = static_cast<Run*>(data);
        GstBuffer* b = GST_PAD_PROBE_INFO_BUFFER(info);
        const GstStructure* meta = lftag_meta_get_structure(b, LFTAG_META_NAME);
        g_mutex_lock(&run->lock);
        run->buffers.push_back(
            {GST_BUFFER_PTS(b), GST_BUFFER_DTS(b), GST_BUFFER_DURATION(b), meta ? gst_structure_copy(meta) : nullptr});
        g_mutex_unlock(&run->lock);
        return GST_PAD_PROBE_OK;
      },
      &run, nullptr);
  gst_object_unref(pad);
  gst_object_unref(sink);

  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  while (GstMessage* m = gst_bus_timed_pop_filtered(
             bus, 120 * GST_SECOND, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR | GST_MESSAGE_WARNING))) {
    if (GST_MESSAGE_TYPE(m) == GST_MESSAGE_ERROR) {
      gst_message_parse_error(m, &error, nullptr);
      fail("%s: %s", launch.c_str(), error->message);
    }
    if (GST_MESSAGE_TYPE(m) == GST_MESSAGE_WARNING) {
      run.warnings.push_back(m);
      continue;
    }
    gst_message_unref(m);
    break;
  }
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(bus);
  gst_object_unref(pipeline);
}

std::vector<nlohmann::json> read_lines(const std::string& path) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

// A scratch directory, removed with whatever the test wrote in it.
class ScratchDir {
 public:
  ScratchDir() {
    gchar* dir = g_dir_make_tmp("lftagpublish-XXXXXX", nullptr);
    fail_unless(dir != nullptr);
    dir_ = dir;
    g_free(dir);
  }
  ~ScratchDir() {
    if (GDir* dir = g_dir_open(dir_.c_str(), 0, nullptr)) {
      while (const gchar* name = g_dir_read_name(dir)) g_unlink(path(name).c_str());
      g_dir_close(dir);
    }
    g_rmdir(dir_.c_str());
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  std::string path(const std::string& name) const { return dir_ + "/" + name; }

 private:
  std::string dir_;
};

nlohmann::json time_json(GstClockTime t) {
  return GST_CLOCK_TIME_IS_VALID(t) ? nlohmann::json(std::uint64_t(t)) : nlohmann::json(nullptr);
}

// Each line is the buffer's: timestamps, frame number, size and the meta's detections as
// `lftag detect` would print them.
void expect_lines_match(const std::vector<nlohmann::json>& lines, const Run& run) {
  fail_unless_equals_int(lines.size(), run.buffers.size());
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const nlohmann::json& line = lines[i];
    const Seen& seen = run.buffers[i];
    fail_unless(seen.meta != nullptr);
    fail_unless_equals_int(line.at("frame").get<int>(), int(i));
    fail_unless(line.at("pts") == time_json(seen.pts), "frame %d: pts %s", int(i), line.at("pts").dump().c_str());
    fail_unless(line.at("dts") == time_json(seen.dts));
    fail_unless(line.at("duration") == time_json(seen.duration));
    fail_unless(line.at("running_time") == time_json(seen.pts));  // one segment from 0
    fail_unless(line.at("stream_time") == time_json(seen.pts));
    fail_unless(std::abs(line.at("time").get<double>() - double(seen.pts) / GST_SECOND) < 1e-9);
    gint width, height;
    gst_structure_get_int(seen.meta, LFTAG_META_FIELD_WIDTH, &width);
    gst_structure_get_int(seen.meta, LFTAG_META_FIELD_HEIGHT, &height);
    fail_unless(line.at("width") == width && line.at("height") == height);
    gboolean analysed = FALSE;
    gst_structure_get_boolean(seen.meta, LFTAG_META_FIELD_ANALYSED, &analysed);
    fail_unless(line.at("analysed") == bool(analysed), "frame %d: analysed %s", int(i),
                line.at("analysed").dump().c_str());
    nlohmann::json expected = nlohmann::json::array();
    const GValue* list = gst_structure_get_value(seen.meta, LFTAG_META_FIELD_DETECTIONS);
    for (guint k = 0; k < gst_value_array_get_size(list); ++k)
      expected.push_back(lftag::io::detection_json(
          lftag::gst::detection_from_structure(gst_value_get_structure(gst_value_array_get_value(list, k)))));
    fail_unless(line.at("detections") == expected, "frame %d: %s", int(i), line.at("detections").dump().c_str());
  }
}

// The file's bytes.
std::string contents(const std::string& path) {
  gchar* text = nullptr;
  gsize size = 0;
  if (!g_file_get_contents(path.c_str(), &text, &size, nullptr)) return "";
  std::string out(text, size);
  g_free(text);
  return out;
}

// The file's lines, each with its '\n' (the last one without, if it has none).
std::vector<std::string> raw_lines(const std::string& path) {
  const std::string text = contents(path);
  std::vector<std::string> lines;
  for (std::size_t begin = 0; begin < text.size();) {
    const std::size_t end = text.find('\n', begin);
    const std::size_t next = end == std::string::npos ? text.size() : end + 1;
    lines.push_back(text.substr(begin, next - begin));
    begin = next;
  }
  return lines;
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// A harness around lftagpublish writing to `path`, its messages on `bus`, fed frames
// that carry an LFTagMeta (with no detections) by push_frame.
struct Publisher {
  GstHarness* h;
  GstBus* bus;
  int pushed = 0;
  explicit Publisher(const std::string& path) {
    h = gst_harness_new_parse(("lftagpublish name=p location=\"" + path + "\"").c_str());
    bus = gst_bus_new();
    gst_element_set_bus(h->element, bus);
    gst_harness_set_src_caps_str(h, "video/x-raw,format=GRAY8,width=32,height=24,framerate=30/1");
  }
  ~Publisher() {
    // Messages left on the bus hold the element, which holds the bus: drop them first.
    gst_element_set_bus(h->element, nullptr);
    gst_bus_set_flushing(bus, TRUE);
    gst_harness_teardown(h);
    gst_object_unref(bus);
  }
  Publisher(const Publisher&) = delete;
  Publisher& operator=(const Publisher&) = delete;
  GstFlowReturn push_frame() {
    GstBuffer* buffer = gst_buffer_new_allocate(nullptr, 32 * 24, nullptr);
    gst_buffer_memset(buffer, 0, 128, 32 * 24);
    GST_BUFFER_PTS(buffer) = gst_util_uint64_scale(pushed++, GST_SECOND, 30);
    lftag::gst::add_detection_meta(buffer, 32, 24, {});
    return gst_harness_push(h, buffer);
  }
  GstMessage* error() { return gst_bus_pop_filtered(bus, GST_MESSAGE_ERROR); }
};

}  // namespace

GST_START_TEST(test_file_matches_metas) {
  const ScratchDir scratch;
  const std::string path = scratch.path("d.jsonl");
  Run run;
  run_pipeline("lftagtestsrc num-buffers=12 ids=6789,42 ! lftagdetect deadline=0 ! lftagpublish location=" + path +
                   " ! fakesink name=sink",
               run);
  const std::vector<nlohmann::json> lines = read_lines(path);
  expect_lines_match(lines, run);
  // Both markers in every frame, as `lftag detect` writes them.
  for (const nlohmann::json& line : lines) {
    fail_unless_equals_int(line["detections"].size(), 2);
    for (const nlohmann::json& d : line["detections"]) {
      fail_unless(d["id"] == 6789 || d["id"] == 42, "%s", d.dump().c_str());
      fail_unless(d["family"] == "3x3" && d.contains("worst_cell") && d.contains("id_hex"));
    }
  }
  fail_unless_equals_uint64(lines[3]["pts"].get<std::uint64_t>(), gst_util_uint64_scale(3, GST_SECOND, 30));
  fail_unless(run.warnings.empty());
}
GST_END_TEST;

// Appending adds to the file; otherwise it is replaced.
GST_START_TEST(test_append) {
  const ScratchDir scratch;
  const std::string path = scratch.path("a.jsonl");
  const std::string launch = "lftagtestsrc num-buffers=3 ! lftagdetect deadline=0 ! lftagpublish location=" + path;
  Run first, second, third;
  run_pipeline(launch + " ! fakesink name=sink", first);
  run_pipeline(launch + " append=true ! fakesink name=sink", second);
  fail_unless_equals_int(read_lines(path).size(), 6);
  run_pipeline(launch + " ! fakesink name=sink", third);
  fail_unless_equals_int(read_lines(path).size(), 3);
}
GST_END_TEST;

// Unset, empty or "-": the standard output.
GST_START_TEST(test_stdout) {
  for (const char* location : {"", " location=-", " location=\"\""}) {
    const ScratchDir scratch;
    const std::string path = scratch.path("stdout.jsonl");
    fflush(stdout);
    const int saved = dup(STDOUT_FILENO);
    FILE* capture = fopen(path.c_str(), "w");
    dup2(fileno(capture), STDOUT_FILENO);
    Run run;
    run_pipeline(std::string("lftagtestsrc num-buffers=4 ids=77 ! lftagdetect deadline=0 ! lftagpublish") + location +
                     " ! fakesink name=sink",
                 run);
    fflush(stdout);
    dup2(saved, STDOUT_FILENO);
    close(saved);
    fclose(capture);
    expect_lines_match(read_lines(path), run);
  }
}
GST_END_TEST;

// A location that cannot be written fails the state change with an error naming it.
GST_START_TEST(test_unwritable_location) {
  const Posted error = start_error(
      "lftagtestsrc num-buffers=3 ! lftagdetect deadline=0 ! lftagpublish name=p location=/nonexistent-dir/d.jsonl ! "
      "fakesink");
  fail_unless_equals_string(error.source.c_str(), "p");
  fail_unless(error.domain == GST_RESOURCE_ERROR && error.code == GST_RESOURCE_ERROR_OPEN_WRITE, "%s",
              error.message.c_str());
  fail_unless(has(error.message, "/nonexistent-dir/d.jsonl"), "%s", error.message.c_str());
}
GST_END_TEST;

// The meta is kept by a video encoder and by a decoder fed by it: lftagpublish after them
// writes every frame. Read back from a file it is gone, and the element says so once.
GST_START_TEST(test_after_encode_and_decode) {
  const ScratchDir scratch;
  const std::string path = scratch.path("coded.jsonl");
  Run run;
  run_pipeline(
      "lftagtestsrc num-buffers=8 ids=6789 ! lftagdetect deadline=0 ! videoconvert ! vp8enc deadline=1 ! "
      "lftagpublish location=" +
          path + ".encoded ! vp8dec ! lftagpublish location=" + path + " ! fakesink name=sink",
      run);
  fail_unless_equals_int(read_lines(path + ".encoded").size(), 8);
  const std::vector<nlohmann::json> lines = read_lines(path);
  fail_unless_equals_int(lines.size(), 8);
  for (const nlohmann::json& line : lines) fail_unless(line["detections"][0]["id"] == 6789);
  fail_unless(run.warnings.empty());

  Run written, read;
  const std::string video = path + ".webm";
  run_pipeline(
      "lftagtestsrc num-buffers=8 ids=6789 ! lftagdetect deadline=0 ! videoconvert ! vp8enc deadline=1 ! webmmux ! "
      "filesink name=sink location=" +
          video,
      written);
  run_pipeline("filesrc location=" + video + " ! matroskademux ! vp8dec ! lftagpublish name=p location=" + path +
                   " ! fakesink name=sink",
               read);
  Run& muxed = read;
  fail_unless_equals_int(muxed.buffers.size(), 8);
  fail_unless_equals_int(read_lines(path).size(), 0);
  fail_unless_equals_int(muxed.warnings.size(), 1);
  GError* error = nullptr;
  gst_message_parse_warning(muxed.warnings[0], &error, nullptr);
  fail_unless(std::string(error->message).find("without LFTagMeta") != std::string::npos, "%s", error->message);
  g_error_free(error);
}
GST_END_TEST;

// videocrop and videobox cannot move the meta's points: they drop it rather than pass it
// on wrong, and lftagpublish after them writes nothing and says why. videoscale moves
// them: its lines are in the scaled frame.
GST_START_TEST(test_after_crop_and_scale) {
  const ScratchDir scratch;
  const std::string path = scratch.path("crop.jsonl");
  for (const char* element : {"videocrop left=10 top=6", "videobox left=8"}) {
    Run run;
    run_pipeline(std::string("lftagtestsrc num-buffers=3 ids=6789 ! lftagdetect deadline=0 ! ") + element +
                     " ! lftagpublish location=" + path + " ! fakesink name=sink",
                 run);
    fail_unless_equals_int(run.buffers.size(), 3);
    for (const Seen& seen : run.buffers) fail_unless(seen.meta == nullptr, "%s kept the meta", element);
    fail_unless_equals_int(read_lines(path).size(), 0);
    fail_unless_equals_int(run.warnings.size(), 1);
    GError* error = nullptr;
    gst_message_parse_warning(run.warnings[0], &error, nullptr);
    fail_unless(has(error->message, "videocrop"), "%s", error->message);
    g_error_free(error);
  }
  Run run;
  run_pipeline(
      "lftagtestsrc num-buffers=3 ids=6789 ! lftagdetect deadline=0 ! videoscale ! video/x-raw,width=320,height=240 ! "
      "lftagpublish location=" +
          path + " ! fakesink name=sink",
      run);
  const std::vector<nlohmann::json> lines = read_lines(path);
  expect_lines_match(lines, run);
  for (const nlohmann::json& line : lines) fail_unless(line["width"] == 320 && line["height"] == 240);
}
GST_END_TEST;

// After a seek the running time starts again at 0 while pts and stream time go on.
GST_START_TEST(test_times_after_seek) {
  const ScratchDir scratch;
  const std::string path = scratch.path("seek.jsonl");
  GstElement* pipeline = gst_parse_launch(
      ("lftagtestsrc count=1 ! lftagdetect deadline=0 ! lftagpublish location=" + path + " ! fakesink").c_str(),
      nullptr);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PAUSED) == GST_STATE_CHANGE_ASYNC);
  fail_unless(gst_element_get_state(pipeline, nullptr, nullptr, GST_CLOCK_TIME_NONE) == GST_STATE_CHANGE_SUCCESS);
  fail_unless(gst_element_seek_simple(pipeline, GST_FORMAT_TIME,
                                      GstSeekFlags(GST_SEEK_FLAG_FLUSH | GST_SEEK_FLAG_ACCURATE), 2 * GST_SECOND));
  fail_unless(gst_element_get_state(pipeline, nullptr, nullptr, GST_CLOCK_TIME_NONE) == GST_STATE_CHANGE_SUCCESS);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);

  // The preroll frame before the seek, and the one after it.
  const std::vector<nlohmann::json> lines = read_lines(path);
  fail_unless_equals_int(lines.size(), 2);
  fail_unless_equals_uint64(lines[0]["pts"].get<std::uint64_t>(), 0);
  const nlohmann::json& after = lines[1];
  fail_unless_equals_int(after["frame"].get<int>(), 1);
  fail_unless_equals_uint64(after["pts"].get<std::uint64_t>(), 2 * GST_SECOND);
  fail_unless_equals_uint64(after["stream_time"].get<std::uint64_t>(), 2 * GST_SECOND);
  fail_unless_equals_uint64(after["running_time"].get<std::uint64_t>(), 0);
}
GST_END_TEST;

// A write that fails part way through a line (here at the process's file size limit, as
// on a full disk) cuts the file back to its last whole line and posts an error saying
// why and which frame's line is lost.
GST_START_TEST(test_write_error_leaves_whole_lines) {
  const ScratchDir scratch;
  const std::string reference = scratch.path("reference.jsonl");
  const std::string path = scratch.path("limited.jsonl");
  const std::string launch =
      "lftagtestsrc num-buffers=8 ids=6789,42 ! lftagdetect deadline=0 ! lftagpublish name=p location=";
  Run run;
  run_pipeline(launch + reference + " ! fakesink name=sink", run);
  const std::vector<std::string> lines = raw_lines(reference);
  fail_unless_equals_int(lines.size(), 8);
  // Room for three lines and half of the fourth.
  const std::string three = lines[0] + lines[1] + lines[2];
  const rlim_t limit = three.size() + lines[3].size() / 2;

  GstElement* pipeline = gst_parse_launch((launch + path + " ! fakesink").c_str(), nullptr);
  fail_unless(pipeline != nullptr);
  GstBus* bus = gst_element_get_bus(pipeline);
  struct rlimit saved;
  fail_unless(getrlimit(RLIMIT_FSIZE, &saved) == 0);
  fail_unless(saved.rlim_max == RLIM_INFINITY || saved.rlim_max >= limit);
  struct rlimit small = saved;
  small.rlim_cur = limit;
  // The limit holds for the whole process, check's own log file included: no check
  // macro until it is lifted. Ignored SIGXFSZ makes the write past it fail with EFBIG.
  void (*const handler)(int) = std::signal(SIGXFSZ, SIG_IGN);
  const int limited = setrlimit(RLIMIT_FSIZE, &small);
  const GstStateChangeReturn started = gst_element_set_state(pipeline, GST_STATE_PLAYING);
  GstMessage* m =
      gst_bus_timed_pop_filtered(bus, GST_CLOCK_TIME_NONE, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR));
  gst_element_set_state(pipeline, GST_STATE_NULL);
  setrlimit(RLIMIT_FSIZE, &saved);
  std::signal(SIGXFSZ, handler);
  gst_object_unref(bus);
  gst_object_unref(pipeline);

  fail_unless(limited == 0);
  fail_unless(started != GST_STATE_CHANGE_FAILURE);
  const Posted error = parse_error(m);
  fail_unless_equals_string(error.source.c_str(), "p");
  // The first three lines, whole, and nothing of the fourth.
  const std::string written = contents(path);
  fail_unless(written == three, "%zu bytes written, the three whole lines are %zu", written.size(), three.size());
  fail_unless_equals_int(read_lines(path).size(), 3);
  fail_unless(error.domain == GST_RESOURCE_ERROR && error.code == GST_RESOURCE_ERROR_WRITE, "%s",
              error.message.c_str());
  fail_unless(has(error.message, path) && has(error.message, g_strerror(EFBIG)), "%s", error.message.c_str());
  fail_unless(has(error.message, "1 frame lost (the line of frame 3)"), "%s", error.message.c_str());
}
GST_END_TEST;

// No space left: the error says so, with its own code, and which frame is lost.
GST_START_TEST(test_no_space_left) {
  GstElement* pipeline = gst_parse_launch(
      "lftagtestsrc num-buffers=3 ! lftagdetect deadline=0 ! lftagpublish name=p location=/dev/full ! fakesink",
      nullptr);
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  const Posted error = parse_error(
      gst_bus_timed_pop_filtered(bus, GST_CLOCK_TIME_NONE, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR)));
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(bus);
  gst_object_unref(pipeline);
  fail_unless_equals_string(error.source.c_str(), "p");
  fail_unless(error.domain == GST_RESOURCE_ERROR && error.code == GST_RESOURCE_ERROR_NO_SPACE_LEFT, "%s",
              error.message.c_str());
  fail_unless(has(error.message, "/dev/full") && has(error.message, g_strerror(ENOSPC)), "%s", error.message.c_str());
  fail_unless(has(error.message, "1 frame lost (the line of frame 0)"), "%s", error.message.c_str());
}
GST_END_TEST;

// The file deleted with its directory while being written: noticed at the next line, at
// EOS when no line comes, or when stopped without EOS, as an error naming the location
// and the frames lost.
GST_START_TEST(test_directory_removed) {
  enum When { kNextLine, kEos, kStop };
  for (const When when : {kNextLine, kEos, kStop}) {
    const ScratchDir scratch;
    const std::string dir = scratch.path("out");
    fail_unless(g_mkdir(dir.c_str(), 0700) == 0);
    const std::string path = dir + "/d.jsonl";
    Publisher p(path);
    for (int i = 0; i < 3; ++i) fail_unless_equals_int(p.push_frame(), GST_FLOW_OK);
    fail_unless_equals_int(read_lines(path).size(), 3);
    fail_unless(g_unlink(path.c_str()) == 0 && g_rmdir(dir.c_str()) == 0);
    if (when == kNextLine) {
      fail_unless_equals_int(p.push_frame(), GST_FLOW_ERROR);
    } else if (when == kEos) {
      gst_harness_push_event(p.h, gst_event_new_eos());
    } else {
      fail_unless(gst_element_set_state(p.h->element, GST_STATE_NULL) == GST_STATE_CHANGE_SUCCESS);
    }
    const Posted error = parse_error(p.error());
    fail_unless_equals_string(error.source.c_str(), "p");
    fail_unless(error.domain == GST_RESOURCE_ERROR && error.code == GST_RESOURCE_ERROR_NOT_FOUND, "%s",
                error.message.c_str());
    fail_unless(has(error.message, "\"" + path + "\" was deleted"), "%s", error.message.c_str());
    fail_unless(has(error.message, when == kNextLine ? "the lines of 4 frames" : "the lines of 3 frames"), "%s",
                error.message.c_str());
    // Nothing more is written, and no more errors come.
    if (when == kNextLine) {
      fail_unless_equals_int(p.push_frame(), GST_FLOW_ERROR);
      fail_unless(p.error() == nullptr);
    }
  }
}
GST_END_TEST;

// Another file renamed over it, or itself renamed away, while being written: an error
// naming the location.
GST_START_TEST(test_file_replaced_or_moved) {
  for (const bool replaced : {true, false}) {
    const ScratchDir scratch;
    const std::string path = scratch.path("d.jsonl");
    const std::string other = scratch.path("other.jsonl");
    Publisher p(path);
    for (int i = 0; i < 2; ++i) fail_unless_equals_int(p.push_frame(), GST_FLOW_OK);
    if (replaced) {
      fail_unless(g_file_set_contents(other.c_str(), "", 0, nullptr));
      fail_unless(g_rename(other.c_str(), path.c_str()) == 0);
    } else {
      fail_unless(g_rename(path.c_str(), other.c_str()) == 0);
    }
    fail_unless_equals_int(p.push_frame(), GST_FLOW_ERROR);
    const Posted error = parse_error(p.error());
    fail_unless_equals_string(error.source.c_str(), "p");
    fail_unless(error.domain == GST_RESOURCE_ERROR, "%s", error.message.c_str());
    fail_unless(has(error.message, "\"" + path + "\""), "%s", error.message.c_str());
    fail_unless(has(error.message, replaced ? "replaced by another file" : "is no longer there"), "%s",
                error.message.c_str());
    fail_unless(has(error.message, "the lines of 3 frames"), "%s", error.message.c_str());
    // The replacing file is left alone; the moved one keeps its two whole lines.
    fail_unless_equals_int(read_lines(replaced ? path : other).size(), replaced ? 0 : 2);
  }
}
GST_END_TEST;

// A frame lftagdetect skips as late (late-frames=skip) is written with "analysed" false,
// not as a frame without markers; the frames around it are analysed and hold their marker.
GST_START_TEST(test_late_frame_not_analysed) {
  const ScratchDir scratch;
  const std::string path = scratch.path("late.jsonl");
  Frames frames;
  pull_frames(frames, "lftagtestsrc num-buffers=3 ids=6789", nullptr, 3);
  GstHarness* h =
      gst_harness_new_parse(("lftagdetect deadline=0 late-frames=skip ! lftagpublish location=" + path).c_str());
  gst_harness_set_src_caps(h, gst_video_info_to_caps(&frames.info));
  const auto push = [&](int i) {
    GstBuffer* out = gst_harness_push_and_pull(h, gst_buffer_ref(frames.buffers[i]));
    fail_unless(out != nullptr, "frame %d was dropped", i);
    gst_buffer_unref(out);
  };
  push(0);
  // The sink rendered frame 0 50 ms late: frame 1, due before pts(0) + 100 ms, is late.
  fail_unless(gst_harness_push_upstream_event(
      h, gst_event_new_qos(GST_QOS_TYPE_UNDERFLOW, 0.5, 50 * GST_MSECOND, GST_BUFFER_PTS(frames.buffers[0]))));
  push(1);
  // On time again.
  fail_unless(gst_harness_push_upstream_event(
      h, gst_event_new_qos(GST_QOS_TYPE_OVERFLOW, 1.0, -10 * GST_MSECOND, GST_BUFFER_PTS(frames.buffers[1]))));
  push(2);
  gst_harness_teardown(h);

  const std::vector<nlohmann::json> lines = read_lines(path);
  fail_unless_equals_int(lines.size(), 3);
  for (int i = 0; i < 3; ++i) {
    const bool late = i == 1;
    fail_unless(lines[i].at("analysed") == !late, "frame %d: %s", i, lines[i].dump().c_str());
    fail_unless_equals_int(lines[i].at("detections").size(), late ? 0 : 1);
  }
}
GST_END_TEST;

// Running time and stream time come from the segment, not from the pts: after x264enc,
// whose segment starts at 1000 hours with stream time 0, and in a segment that also has
// a base (a second segment of a playlist, say), the three differ.
GST_START_TEST(test_times_in_a_segment_not_from_zero) {
  const ScratchDir scratch;
  const std::string path = scratch.path("segment.jsonl");
  GstHarness* h = gst_harness_new_parse(("lftagpublish location=" + path).c_str());
  gst_harness_set_src_caps_str(h, "video/x-raw,format=GRAY8,width=32,height=24,framerate=30/1");
  const GstClockTime start = 1000 * 3600 * GST_SECOND;
  struct Case {
    GstClockTime time, base;
  };
  const Case cases[] = {{0, 0}, {10 * GST_SECOND, 5 * GST_SECOND}};
  for (const Case& c : cases) {
    GstSegment segment;
    gst_segment_init(&segment, GST_FORMAT_TIME);
    segment.start = segment.position = start;
    segment.time = c.time;
    segment.base = c.base;
    fail_unless(gst_harness_push_event(h, gst_event_new_segment(&segment)));
    for (int k = 0; k < 2; ++k) {
      GstBuffer* buffer = gst_buffer_new_allocate(nullptr, 32 * 24, nullptr);
      GST_BUFFER_PTS(buffer) = start + gst_util_uint64_scale(k, GST_SECOND, 30);
      lftag::gst::add_detection_meta(buffer, 32, 24, {});
      fail_unless_equals_int(gst_harness_push(h, buffer), GST_FLOW_OK);
      gst_buffer_unref(gst_harness_pull(h));
    }
  }
  gst_harness_teardown(h);

  const std::vector<nlohmann::json> lines = read_lines(path);
  fail_unless_equals_int(lines.size(), 4);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const Case& c = cases[i / 2];
    const GstClockTime offset = gst_util_uint64_scale(i % 2, GST_SECOND, 30);
    fail_unless_equals_uint64(lines[i].at("pts").get<std::uint64_t>(), start + offset);
    fail_unless_equals_uint64(lines[i].at("stream_time").get<std::uint64_t>(), c.time + offset);
    fail_unless_equals_uint64(lines[i].at("running_time").get<std::uint64_t>(), c.base + offset);
  }
}
GST_END_TEST;

// Whether this process still has `path` open.
bool open_here(const std::string& path) {
  bool found = false;
  if (GDir* dir = g_dir_open("/proc/self/fd", 0, nullptr)) {
    while (const gchar* name = g_dir_read_name(dir)) {
      gchar* link = g_file_read_link((std::string("/proc/self/fd/") + name).c_str(), nullptr);
      if (link && path == link) found = true;
      g_free(link);
    }
    g_dir_close(dir);
  }
  return found;
}

// The buffers that reached lftagpublish, counted on its sink pad; after `error_at` (when
// not negative) its source pad fails the stream as a downstream error would.
struct Received {
  GMutex lock;
  GCond changed;
  int count = 0;
  int error_at = -1;
  Received() {
    g_mutex_init(&lock);
    g_cond_init(&changed);
  }
  ~Received() {
    g_cond_clear(&changed);
    g_mutex_clear(&lock);
  }
  // Waits (up to a minute) until `n` buffers came.
  bool wait_for(int n) {
    const gint64 end = g_get_monotonic_time() + 60 * G_TIME_SPAN_SECOND;
    g_mutex_lock(&lock);
    while (count < n && g_cond_wait_until(&changed, &lock, end)) {
    }
    const bool came = count >= n;
    g_mutex_unlock(&lock);
    return came;
  }
  int seen() {
    g_mutex_lock(&lock);
    const int n = count;
    g_mutex_unlock(&lock);
    return n;
  }
};

void watch_publisher(GstElement* pipeline, Received& received) {
  GstElement* publish = gst_bin_get_by_name(GST_BIN(pipeline), "p");
  GstPad* sink = gst_element_get_static_pad(publish, "sink");
  gst_pad_add_probe(
      sink, GST_PAD_PROBE_TYPE_BUFFER,
      [](GstPad*, GstPadProbeInfo*, gpointer data) {
        auto* r = static_cast<Received*>(data);
        g_mutex_lock(&r->lock);
        ++r->count;
        g_cond_broadcast(&r->changed);
        g_mutex_unlock(&r->lock);
        return GST_PAD_PROBE_OK;
      },
      &received, nullptr);
  gst_object_unref(sink);
  GstPad* src = gst_element_get_static_pad(publish, "src");
  gst_pad_add_probe(
      src, GST_PAD_PROBE_TYPE_BUFFER,
      [](GstPad*, GstPadProbeInfo* info, gpointer data) {
        auto* r = static_cast<Received*>(data);
        if (r->error_at < 0 || r->seen() <= r->error_at) return GST_PAD_PROBE_OK;
        gst_buffer_unref(GST_PAD_PROBE_INFO_BUFFER(info));
        GST_PAD_PROBE_INFO_DATA(info) = nullptr;
        GST_PAD_PROBE_INFO_FLOW_RETURN(info) = GST_FLOW_ERROR;
        return GST_PAD_PROBE_HANDLED;
      },
      &received, nullptr);
  gst_object_unref(src);
  gst_object_unref(publish);
}

// The file holds `n` whole lines, frames 0 to n - 1 in order, and nothing else.
void expect_whole_lines(const std::string& path, int n, const char* when) {
  const std::vector<std::string> lines = raw_lines(path);
  fail_unless_equals_int(lines.size(), n);
  for (int i = 0; i < n; ++i) {
    fail_unless(!lines[i].empty() && lines[i].back() == '\n', "%s: line %d is cut: %s", when, i, lines[i].c_str());
    fail_unless_equals_int(nlohmann::json::parse(lines[i]).at("frame").get<int>(), i);
  }
}

// At EOS every frame received is in the file, whole, before the pipeline stops; once
// stopped the file is closed.
GST_START_TEST(test_every_frame_at_eos) {
  const ScratchDir scratch;
  const std::string path = scratch.path("eos.jsonl");
  GstElement* pipeline = gst_parse_launch(
      ("lftagtestsrc num-buffers=25 ids=6789 ! lftagdetect deadline=0 ! lftagpublish name=p location=" + path +
       " ! fakesink")
          .c_str(),
      nullptr);
  Received received;
  watch_publisher(pipeline, received);
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  GstMessage* m =
      gst_bus_timed_pop_filtered(bus, 120 * GST_SECOND, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR));
  fail_unless(m != nullptr && GST_MESSAGE_TYPE(m) == GST_MESSAGE_EOS);
  gst_message_unref(m);
  fail_unless_equals_int(received.seen(), 25);
  expect_whole_lines(path, 25, "at EOS");
  fail_unless(open_here(path));
  gst_element_set_state(pipeline, GST_STATE_NULL);
  fail_unless(!open_here(path), "still open after NULL");
  expect_whole_lines(path, 25, "after NULL");
  gst_object_unref(bus);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// Set to NULL (or READY) while a live stream flows, without EOS: every frame that reached
// the element is in the file, whole, and the file is closed.
GST_START_TEST(test_every_frame_when_stopped_mid_stream) {
  for (const GstState target : {GST_STATE_NULL, GST_STATE_READY}) {
    const ScratchDir scratch;
    const std::string path = scratch.path("stopped.jsonl");
    GstElement* pipeline =
        gst_parse_launch(("lftagtestsrc is-live=true ids=6789 ! lftagdetect deadline=0 ! lftagpublish "
                          "name=p location=" +
                          path + " ! fakesink sync=true")
                             .c_str(),
                         nullptr);
    Received received;
    watch_publisher(pipeline, received);
    fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
    fail_unless(received.wait_for(10), "10 frames did not come in a minute");
    fail_unless(gst_element_set_state(pipeline, target) == GST_STATE_CHANGE_SUCCESS);
    const int n = received.seen();
    fail_unless(!open_here(path), "still open after %s", gst_element_state_get_name(target));
    expect_whole_lines(path, n, gst_element_state_get_name(target));
    gst_element_set_state(pipeline, GST_STATE_NULL);
    gst_object_unref(pipeline);
  }
}
GST_END_TEST;

// An error downstream stops the stream: the frame it happened on and every one before
// are in the file, whole, when the application stops the pipeline.
GST_START_TEST(test_every_frame_after_an_error_downstream) {
  const ScratchDir scratch;
  const std::string path = scratch.path("error.jsonl");
  GstElement* pipeline = gst_parse_launch(
      ("lftagtestsrc ids=6789 ! lftagdetect deadline=0 ! lftagpublish name=p location=" + path + " ! fakesink").c_str(),
      nullptr);
  Received received;
  received.error_at = 7;
  watch_publisher(pipeline, received);
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  GstMessage* m =
      gst_bus_timed_pop_filtered(bus, 120 * GST_SECOND, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR));
  fail_unless(m != nullptr && GST_MESSAGE_TYPE(m) == GST_MESSAGE_ERROR, "the stream did not fail");
  // The source's "Internal data stream error", not lftagpublish's.
  fail_unless(std::string(GST_OBJECT_NAME(GST_MESSAGE_SRC(m))) != "p");
  gst_message_unref(m);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  fail_unless_equals_int(received.seen(), 8);
  fail_unless(!open_here(path));
  expect_whole_lines(path, 8, "after the error");
  gst_object_unref(bus);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// frame-numbers=stream-time numbers each frame by its stream time and the caps' frame
// rate, so that after frames are lost the numbers are still the file's frame indices; the
// default counts buffers.
GST_START_TEST(test_frame_numbers_by_stream_time) {
  for (const char* numbers : {"count", "stream-time"}) {
    const ScratchDir scratch;
    const std::string path = scratch.path("numbers.jsonl");
    GstHarness* h =
        gst_harness_new_parse(("lftagpublish frame-numbers=" + std::string(numbers) + " location=" + path).c_str());
    gst_harness_set_src_caps_str(h, "video/x-raw,format=GRAY8,width=32,height=24,framerate=25/1");
    // Frames 10 to 14 missing; the segment starts at 1 s of pts, so stream time is pts - 1 s.
    GstSegment segment;
    gst_segment_init(&segment, GST_FORMAT_TIME);
    segment.start = segment.position = GST_SECOND;
    fail_unless(gst_harness_push_event(h, gst_event_new_segment(&segment)));
    const std::vector<int> frames = {0, 1, 9, 15, 16};
    for (const int frame : frames) {
      GstBuffer* buffer = gst_buffer_new_allocate(nullptr, 32 * 24, nullptr);
      GST_BUFFER_PTS(buffer) = GST_SECOND + gst_util_uint64_scale(frame, GST_SECOND, 25) + 3 * GST_MSECOND;
      lftag::gst::add_detection_meta(buffer, 32, 24, {});
      fail_unless_equals_int(gst_harness_push(h, buffer), GST_FLOW_OK);
      gst_buffer_unref(gst_harness_pull(h));
    }
    gst_harness_teardown(h);
    const std::vector<nlohmann::json> lines = read_lines(path);
    fail_unless_equals_int(lines.size(), frames.size());
    const bool by_time = std::string(numbers) == "stream-time";
    for (std::size_t i = 0; i < lines.size(); ++i)
      fail_unless_equals_int(lines[i].at("frame").get<int>(), by_time ? frames[i] : int(i));
  }
}
GST_END_TEST;

#if !LFTAG_HAVE_MQTT
// A build without libmosquitto: target=mqtt fails the start, saying what to install.
GST_START_TEST(test_mqtt_needs_libmosquitto) {
  const Posted error =
      start_error("lftagtestsrc num-buffers=3 ! lftagdetect deadline=0 ! lftagpublish name=p target=mqtt ! fakesink");
  fail_unless_equals_string(error.source.c_str(), "p");
  fail_unless(
      has(error.message, "without MQTT") && has(error.message, "libmosquitto-dev") && has(error.message, "target=file"),
      "%s", error.message.c_str());
}
GST_END_TEST;
#endif

static Suite* lftagpublish_suite(void) {
  Suite* s = suite_create("lftagpublish");
  TCase* tc = tcase_create("general");
  suite_add_tcase(s, tc);
  tcase_add_test(tc, test_file_matches_metas);
  tcase_add_test(tc, test_append);
  tcase_add_test(tc, test_stdout);
  tcase_add_test(tc, test_unwritable_location);
  tcase_add_test(tc, test_after_encode_and_decode);
  tcase_add_test(tc, test_after_crop_and_scale);
  tcase_add_test(tc, test_times_after_seek);
  tcase_add_test(tc, test_times_in_a_segment_not_from_zero);
  tcase_add_test(tc, test_late_frame_not_analysed);
  tcase_add_test(tc, test_write_error_leaves_whole_lines);
  tcase_add_test(tc, test_no_space_left);
  tcase_add_test(tc, test_directory_removed);
  tcase_add_test(tc, test_file_replaced_or_moved);
  tcase_add_test(tc, test_frame_numbers_by_stream_time);
  tcase_add_test(tc, test_every_frame_at_eos);
  tcase_add_test(tc, test_every_frame_when_stopped_mid_stream);
  tcase_add_test(tc, test_every_frame_after_an_error_downstream);
#if !LFTAG_HAVE_MQTT
  tcase_add_test(tc, test_mqtt_needs_libmosquitto);
#endif
  return s;
}

LFTAG_CHECK_MAIN(lftagpublish)
