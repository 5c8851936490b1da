// SPDX-License-Identifier: LGPL-2.1-or-later
// Frames pulled from a pipeline through a GstHarness, for the element tests.
#pragma once

#include <string>
#include <vector>

#include <gst/check/gstcheck.h>
#include <gst/check/gstharness.h>
#include <gst/video/video.h>

// Buffers pulled from a pipeline, with their negotiated format.
struct Frames {
  std::vector<GstBuffer*> buffers;
  GstVideoInfo info;
  Frames() = default;
  Frames(const Frames&) = delete;
  ~Frames() {
    for (GstBuffer* b : buffers) gst_buffer_unref(b);
  }
};

// Pulls `n` frames from a harness around `launch` whose sink accepts `caps` (any when null).
inline void pull_frames(Frames& out, const std::string& launch, const char* caps, int n) {
  GstHarness* h = gst_harness_new_parse(launch.c_str());
  if (caps) gst_harness_set_sink_caps_str(h, caps);
  gst_harness_play(h);
  for (int i = 0; i < n; ++i) {
    GstBuffer* buffer = gst_harness_pull(h);
    fail_unless(buffer != nullptr, "frame %d of '%s' did not come", i, launch.c_str());
    out.buffers.push_back(buffer);
  }
  GstCaps* negotiated = gst_pad_get_current_caps(h->sinkpad);
  fail_unless(gst_video_info_from_caps(&out.info, negotiated));
  gst_caps_unref(negotiated);
  gst_harness_teardown(h);
}
