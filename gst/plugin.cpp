/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The lftag plugin: LFTag fiducial markers in GStreamer pipelines. */
#include <gst/gst.h>

#include "gstlftagdetect.h"
#include "gstlftagpublish.h"
#include "gstlftagtestsrc.h"
#include "metaconversion.h"

static gboolean plugin_init(GstPlugin* plugin) {
  gboolean ret = FALSE;

  lftag::gst::detection_meta_info();
  lftag::gst::truth_meta_info();
  ret |= GST_ELEMENT_REGISTER(lftagdetect, plugin);
  ret |= GST_ELEMENT_REGISTER(lftagpublish, plugin);
  ret |= GST_ELEMENT_REGISTER(lftagtestsrc, plugin);
  return ret;
}

GST_PLUGIN_DEFINE(GST_VERSION_MAJOR, GST_VERSION_MINOR, lftag,
                  "LFTag fiducial markers: detection with metadata, messages and overlay; "
                  "detections as JSON Lines; synthetic video with ground truth",
                  plugin_init, VERSION, "LGPL", GST_PACKAGE_NAME, GST_PACKAGE_ORIGIN)
