// SPDX-License-Identifier: LGPL-2.1-or-later
// Properties of lftagdetect and lftagtestsrc changed from the application's thread while
// frames flow in the streaming threads, and two lftagdetect elements detecting and drawing
// at the same time in two branches. Every frame must still be analysed. Built into every
// build; scripts/test-sanitizers.sh runs it (suite "threads") under ThreadSanitizer, where
// tsan-glib.c shows the sanitizer GLib's locks.
#include <string>

#include "detectmessages.h"
#include "metaconversion.h"
// Last: check's macros (fail...) clash with names in the C++ library.
#include "check-main.h"

namespace {

struct Counts {
  gint frames = 0, analysed = 0;
};

// Counts the buffers that reach `sink` and those of them that carry an LFTagMeta.
void count_frames(GstElement* pipeline, const char* sink, Counts* counts) {
  GstElement* element = gst_bin_get_by_name(GST_BIN(pipeline), sink);
  GstPad* pad = gst_element_get_static_pad(element, "sink");
  gst_pad_add_probe(
      pad, GST_PAD_PROBE_TYPE_BUFFER,
      [](GstPad*, GstPadProbeInfo* info, gpointer data) {
        auto* c = static_cast<Counts*>(data);
        g_atomic_int_inc(&c->frames);
        if (lftag_meta_get_structure(GST_PAD_PROBE_INFO_BUFFER(info), LFTAG_META_NAME)) g_atomic_int_inc(&c->analysed);
        return GST_PAD_PROBE_OK;
      },
      counts, nullptr);
  gst_object_unref(pad);
  gst_object_unref(element);
}

// Plays `launch` to the end, calling `change(i)` in this thread between waits of a millisecond.
template <typename Change>
void play_while_changing(GstElement* pipeline, Change change) {
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  GstMessage* end = nullptr;
  for (int i = 0; !end; ++i) {
    change(i);
    end = gst_bus_timed_pop_filtered(bus, GST_MSECOND, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR));
  }
  fail_unless(GST_MESSAGE_TYPE(end) == GST_MESSAGE_EOS, "the pipeline failed");
  gst_message_unref(end);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(bus);
}

}  // namespace

// Every property that may change while PLAYING, changed over and over.
GST_START_TEST(test_detect_properties_from_another_thread) {
  GstElement* pipeline = gst_parse_launch(
      "lftagtestsrc num-buffers=40 count=2 ! video/x-raw,format=I420,width=320,height=240 ! "
      "lftagdetect name=d ! fakesink name=sink sync=false",
      nullptr);
  GstElement* d = gst_bin_get_by_name(GST_BIN(pipeline), "d");
  Counts counts;
  count_frames(pipeline, "sink", &counts);
  play_while_changing(pipeline, [&](int i) {
    const int messages = i % 2 ? GST_LFTAG_DETECT_MESSAGES_WITH_MARKERS : GST_LFTAG_DETECT_MESSAGES_NONE;
    g_object_set(d, "families", i % 2 ? "3x3" : "4x4,3x3,6x6", "tag-size", 0.05 + 0.01 * (i % 7), "threshold-window",
                 12 + i % 9, "threshold-offset", i % 6, "second-look", gboolean(i % 3 != 0), "messages", messages,
                 "max-ink-ratio", 4.0 + i % 3, "min-spread-ratio", 0.05 + 0.01 * (i % 5), "max-decode-error",
                 i % 4 ? 0.0 : 1e-3, "max-cell-residual", 0.3 + 0.01 * (i % 5), "fx", i % 5 ? 0.0 : 300.0 + i % 50,
                 "fy", i % 5 ? 0.0 : 310.0, "cx", i % 5 ? -1.0 : 159.5, "cy", i % 5 ? -1.0 : 119.5, "distortion",
                 i % 4 == 1 ? "-0.1,0.01,0,0" : "", nullptr);
    gst_util_set_object_arg(G_OBJECT(d), "overlay", i % 3 ? "outline+id+axes" : "0");
    gchar* families = nullptr;
    g_object_get(d, "families", &families, nullptr);  // reading back races with nothing either
    g_free(families);
  });
  fail_unless_equals_int(counts.frames, 40);
  fail_unless_equals_int(counts.analysed, 40);
  gst_object_unref(d);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// The source's markers and rendering changed while it plays.
GST_START_TEST(test_testsrc_properties_from_another_thread) {
  GstElement* pipeline = gst_parse_launch(
      "lftagtestsrc name=src num-buffers=30 ! video/x-raw,width=320,height=240 ! lftagdetect ! "
      "fakesink name=sink sync=false",
      nullptr);
  GstElement* src = gst_bin_get_by_name(GST_BIN(pipeline), "src");
  Counts counts;
  count_frames(pipeline, "sink", &counts);
  play_while_changing(pipeline, [&](int i) {
    g_object_set(src, "ids", i % 2 ? "6789,42" : "1-3", "count", guint(1 + i % 3), "noise", double(i % 4),
                 "motion-blur", i % 3 ? 0.0 : 0.3, "speed", 0.5 + i % 2, "tag-size", 0.1 + 0.01 * (i % 3), nullptr);
  });
  fail_unless_equals_int(counts.frames, 30);
  fail_unless_equals_int(counts.analysed, 30);
  gst_object_unref(src);
  gst_object_unref(pipeline);
}
GST_END_TEST;

// Two detectors in two branches of a tee: two streaming threads detect and draw at once.
GST_START_TEST(test_two_detectors_at_once) {
  GstElement* pipeline = gst_parse_launch(
      "lftagtestsrc num-buffers=30 count=3 ! video/x-raw,format=I420,width=320,height=240 ! tee name=t "
      "t. ! queue ! videoconvert ! video/x-raw,format=BGRx ! lftagdetect overlay=outline+id+axes families=3x3,4x4 ! "
      "fakesink name=a sync=false "
      "t. ! queue ! videoconvert ! video/x-raw,format=GRAY8 ! lftagdetect overlay=outline+id families=3x3,5x5 ! "
      "fakesink name=b sync=false",
      nullptr);
  Counts a, b;
  count_frames(pipeline, "a", &a);
  count_frames(pipeline, "b", &b);
  play_while_changing(pipeline, [](int) {});
  fail_unless_equals_int(a.analysed, 30);
  fail_unless_equals_int(b.analysed, 30);
  gst_object_unref(pipeline);
}
GST_END_TEST;

static Suite* threads_suite() {
  Suite* s = suite_create("threads");
  TCase* tc = tcase_create("general");
  tcase_add_test(tc, test_detect_properties_from_another_thread);
  tcase_add_test(tc, test_testsrc_properties_from_another_thread);
  tcase_add_test(tc, test_two_detectors_at_once);
  suite_add_tcase(s, tc);
  return s;
}

LFTAG_CHECK_MAIN(threads)
