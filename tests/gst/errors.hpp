// SPDX-License-Identifier: LGPL-2.1-or-later
// The errors elements post, for the element tests.
#pragma once

#include <string>

#include <gst/check/gstcheck.h>
#include <gst/gst.h>

// An element error: its source, domain, code and message.
struct Posted {
  std::string source;
  GQuark domain = 0;
  int code = 0;
  std::string message;
};

// The error message `m` (which it takes).
inline Posted parse_error(GstMessage* m) {
  fail_unless(m != nullptr && GST_MESSAGE_TYPE(m) == GST_MESSAGE_ERROR, "no error posted");
  GError* error = nullptr;
  gst_message_parse_error(m, &error, nullptr);
  Posted posted{GST_OBJECT_NAME(GST_MESSAGE_SRC(m)), error->domain, error->code, error->message};
  g_error_free(error);
  gst_message_unref(m);
  return posted;
}

// The error with which the pipeline `launch` refuses to start (the test fails if it starts).
inline Posted start_error(const std::string& launch) {
  GstElement* pipeline = gst_parse_launch(launch.c_str(), nullptr);
  fail_unless(pipeline != nullptr, "cannot parse '%s'", launch.c_str());
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) == GST_STATE_CHANGE_FAILURE, "'%s' started",
              launch.c_str());
  const Posted error = parse_error(gst_bus_pop_filtered(bus, GST_MESSAGE_ERROR));
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(bus);
  gst_object_unref(pipeline);
  return error;
}
