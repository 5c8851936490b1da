/* SPDX-License-Identifier: LGPL-2.1-or-later */
#ifndef __GST_LFTAG_DETECT_H__
#define __GST_LFTAG_DETECT_H__

#include <gst/gst.h>
#include <gst/video/gstvideofilter.h>

G_BEGIN_DECLS

#define GST_TYPE_LFTAG_DETECT (gst_lftag_detect_get_type())
G_DECLARE_FINAL_TYPE(GstLFTagDetect, gst_lftag_detect, GST, LFTAG_DETECT, GstVideoFilter)

/**
 * GstLFTagDetectOverlay:
 * @GST_LFTAG_DETECT_OVERLAY_OUTLINE: the outer border of each marker
 * @GST_LFTAG_DETECT_OVERLAY_ID: family and id beside the marker (under it, over it
 *     at the foot of the frame), inside the frame
 * @GST_LFTAG_DETECT_OVERLAY_AXES: the marker's axes, x red, y green, z blue,
 *     one tag size long (a metric pose: see calibration-file)
 *
 * What lftagdetect draws onto the frames. Nothing (the default) leaves the
 * pixels untouched.
 */
typedef enum {
  GST_LFTAG_DETECT_OVERLAY_OUTLINE = (1 << 0),
  GST_LFTAG_DETECT_OVERLAY_ID = (1 << 1),
  GST_LFTAG_DETECT_OVERLAY_AXES = (1 << 2),
} GstLFTagDetectOverlay;

/**
 * GstLFTagDetectLateFrames:
 * @GST_LFTAG_DETECT_LATE_FRAMES_ANALYSE: analyse every frame, however late
 * @GST_LFTAG_DETECT_LATE_FRAMES_SKIP: pass a frame that a synchronised sink
 *     reported late on without analysing it; its LFTagMeta says "analysed" FALSE
 *
 * What lftagdetect does with a frame that arrives after the time downstream QoS
 * says it is due. It never drops one: an analyser's results must account for
 * every frame.
 */
typedef enum {
  GST_LFTAG_DETECT_LATE_FRAMES_ANALYSE = 0,
  GST_LFTAG_DETECT_LATE_FRAMES_SKIP = 1,
} GstLFTagDetectLateFrames;

GST_ELEMENT_REGISTER_DECLARE(lftagdetect);

G_END_DECLS

#endif /* __GST_LFTAG_DETECT_H__ */
