/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* Reads lftagdetect's results in C: a pad probe after the detector takes the
 * LFTagMeta off every buffer and prints each marker's family, id, centre and
 * distance. Only GStreamer and the header lftag-meta.h are needed; nothing links
 * against the plugin.
 *
 *   read-meta                          synthetic markers from lftagtestsrc
 *   read-meta 'filesrc location=in.webm ! decodebin ! videoconvert'
 *
 * The argument is the pipeline's start; "! lftagdetect name=detect ! fakesink" is
 * appended. Exits non-zero when the pipeline fails. */
#include <stdlib.h>

#include <gst/gst.h>

#include "lftag-meta.h"

static GstPadProbeReturn print_detections(G_GNUC_UNUSED GstPad* pad, GstPadProbeInfo* info, gpointer user_data) {
  GstBuffer* buffer = GST_PAD_PROBE_INFO_BUFFER(info);
  const GstStructure* meta = lftag_meta_get_structure(buffer, LFTAG_META_NAME);
  guint* frames = user_data;
  gint width = 0, height = 0;

  ++*frames;
  if (meta == NULL) /* a frame the detector could not analyse */
    return GST_PAD_PROBE_OK;
  gst_structure_get_int(meta, LFTAG_META_FIELD_WIDTH, &width);
  gst_structure_get_int(meta, LFTAG_META_FIELD_HEIGHT, &height);

  const GValue* detections = gst_structure_get_value(meta, LFTAG_META_FIELD_DETECTIONS);
  g_print("%" GST_TIME_FORMAT " %dx%d: %u marker(s)%s", GST_TIME_ARGS(GST_BUFFER_PTS(buffer)), width, height,
          gst_value_array_get_size(detections), gst_value_array_get_size(detections) ? ":" : "");
  for (guint i = 0; i < gst_value_array_get_size(detections); ++i) {
    const GstStructure* d = gst_value_get_structure(gst_value_array_get_value(detections, i));
    const GValue* tvec = gst_structure_get_value(d, LFTAG_FIELD_TVEC);
    gboolean calibrated = FALSE;
    gdouble x = 0, y = 0;

    lftag_structure_get_point(d, LFTAG_FIELD_CENTER, -1, &x, &y);
    gst_structure_get_boolean(d, LFTAG_FIELD_CALIBRATED, &calibrated);
    /* The id is exact as a decimal string; "id" (guint64) exists only when it fits. */
    g_print("%s %s %s at (%.1f, %.1f), %.3f m away%s", i ? "," : "", gst_structure_get_string(d, LFTAG_FIELD_FAMILY),
            gst_structure_get_string(d, LFTAG_FIELD_ID_STRING), x, y,
            g_value_get_double(gst_value_array_get_value(tvec, 2)), calibrated ? "" : " (uncalibrated)");
  }
  g_print("\n");
  return GST_PAD_PROBE_OK;
}

int main(int argc, char** argv) {
  GError* error = NULL;
  guint frames = 0;
  int status = EXIT_SUCCESS;

  gst_init(&argc, &argv);
  const gchar* source = argc > 1 ? argv[1] : "lftagtestsrc num-buffers=30 count=3";
  gchar* launch = g_strdup_printf("%s ! lftagdetect name=detect ! fakesink", source);
  /* A pipeline may come back with an error, such as an unknown element: fail as well. */
  GstElement* pipeline = gst_parse_launch(launch, &error);
  if (error) {
    g_printerr("Cannot build \"%s\": %s\n", launch, error->message);
    return EXIT_FAILURE;
  }

  GstElement* detect = gst_bin_get_by_name(GST_BIN(pipeline), "detect");
  GstPad* pad = gst_element_get_static_pad(detect, "src");
  gst_pad_add_probe(pad, GST_PAD_PROBE_TYPE_BUFFER, print_detections, &frames, NULL);
  gst_object_unref(pad);
  gst_object_unref(detect);

  gst_element_set_state(pipeline, GST_STATE_PLAYING);
  GstBus* bus = gst_element_get_bus(pipeline);
  GstMessage* message = gst_bus_timed_pop_filtered(bus, GST_CLOCK_TIME_NONE, GST_MESSAGE_EOS | GST_MESSAGE_ERROR);
  if (GST_MESSAGE_TYPE(message) == GST_MESSAGE_ERROR) {
    gchar* debug = NULL;
    gst_message_parse_error(message, &error, &debug);
    g_printerr("Error from %s: %s\n%s\n", GST_OBJECT_NAME(GST_MESSAGE_SRC(message)), error->message,
               debug ? debug : "");
    g_clear_error(&error);
    g_free(debug);
    status = EXIT_FAILURE;
  } else {
    g_print("%u frames\n", frames);
  }
  gst_message_unref(message);
  gst_object_unref(bus);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(pipeline);
  g_free(launch);
  return status;
}
