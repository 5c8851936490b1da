/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The per-buffer metadata of the lftag GStreamer plugin, for applications.
 *
 * This comment is the one written schema of the metas: the element documentation,
 * docs/gstreamer.md and the README refer here instead of listing the fields. The
 * same "lftag/detection" structure is the "lftag" param of lftagdetect's region
 * metas and the "detections" of its "lftag" bus message (with
 * message-detections=true). The JSON that lftag detect and lftagpublish write
 * holds the same values under underscored names, the pose's grouped under "pose"
 * (docs/cli.md, "JSON output").
 *
 * Both metas are GstCustomMeta: a GstStructure attached to the buffer, kept by
 * videoconvert, videoscale, queue, tee, video encoders and decoders. LFTagTruthMeta
 * has no tags and passes everywhere unchanged. LFTagMeta is tagged "video" and
 * "size" (as GstVideoRegionOfInterestMeta): videoscale moves its points and sets
 * its "width" and "height" to the scaled frame's, and elements that crop or box
 * the frame (videocrop, videobox), which could not move them, drop it. Nothing
 * needs linking: once the plugin has been loaded, read them with
 *
 *   C:       GstCustomMeta *m = gst_buffer_get_custom_meta (buf, LFTAG_TRUTH_META_NAME);
 *            const GstStructure *s = m ? gst_custom_meta_get_structure (m) : NULL;
 *   Python:  m = buf.get_custom_meta("LFTagTruthMeta"); s = m.get_structure() if m else None
 *
 * Coordinates are pixels of the frame of the meta's "width" and "height", with
 * pixel centres at integer coordinates: for LFTagMeta the frame it is on (after
 * videoscale too), for LFTagTruthMeta the frame rendered. A point is a
 * GstValueArray of two doubles <x, y>; a list of points is a GstValueArray of
 * points (numpy.array() reads it as N x 2).
 *
 * LFTagMeta ("LFTagMeta"): what a detector found.
 *   width, height      gint                 the analysed frame
 *   analysed           gboolean             FALSE when the frame was passed on without
 *                                           detection (late under QoS with
 *                                           late-frames=skip, or unreadable): its empty
 *                                           detections say nothing about markers
 *   detections         GstValueArray of GstStructure "lftag/detection"
 *
 * LFTagTruthMeta ("LFTagTruthMeta"): GROUND TRUTH, attached by lftagtestsrc to
 * every frame it renders; never produced by detection.
 *   width, height      gint                 the rendered frame
 *   fx, fy, cx, cy     gdouble              the camera that rendered it (pixels)
 *   distortion         GstValueArray of gdouble (k1, k2, p1, p2[, k3...]); empty: none
 *   markers            GstValueArray of GstStructure "lftag/truth", one per marker
 *
 * Fields of every marker structure (detection and truth):
 *   family             gchararray   "3x3" ... "8x8"
 *   id                 guint64      the id; only present when it fits in 64 bits
 *   id-string          gchararray   the id in decimal, always present and exact
 *                                   (6x6 and larger ids need up to 124 bits)
 *   keypoints          4 points     K0..K3: both baseline centres, then the
 *                                   bottom-left and bottom-right data cells
 *   centroids          n^2 points   area centroids of the black squares, grid order
 *   corners            4 points     outer corners of the black border, clockwise
 *                                   from the marker's top-left
 *   center             point        the marker centre
 *   rvec, tvec         GstValueArray of 3 gdouble: rotation (Rodrigues) and
 *                                   translation from the marker frame (origin at the
 *                                   centre, x right, y down, z into the marker) to
 *                                   the camera frame; metres
 *   tag-size           gdouble      outer edge of the black border, metres
 * Detections only:
 *   calibrated         gboolean     pose from a real calibration (else from the
 *                                   default camera: decoding is exact, metric pose is not)
 *   decode-error       gdouble      decoding error metric, lower is better
 *   worst-cell         gdouble      largest offset of a square from its decoded
 *                                   position, marker units (0.35 is the limit)
 *   noise-margin       gdouble      standard deviations of the noise measured on the
 *                                   marker by which its least certain cell stands from
 *                                   reading as another digit (2 at least for a marker
 *                                   read by its blobs; 0 for 2x2)
 *   edge-score         gdouble      mean gradient along the inner border edge
 *   reprojection-error gdouble      RMS of the final pose over the centroids, pixels
 *   alternative-rvec, alternative-tvec
 *                      3 gdouble    the planar pose's other solution (IPPE finds two),
 *                                   refined like the first (the flip of a marker seen
 *                                   nearly face on)
 *   alternative-reprojection-error
 *                      gdouble      its RMS over the centroids, pixels
 *   ambiguity-ratio    gdouble      alternative-reprojection-error over
 *                                   reprojection-error: under about 2 the pose may be
 *                                   the flip (under 1: the squares' foreshortening
 *                                   chose it against the centroids), from 3 settled;
 *                                   0 without a second solution
 *   from-outline       gboolean     read from the grey levels under its aligned outline
 *                                   (far or blurred; decode-error and worst-cell are 0)
 * Detections of lftagdetect with tracking=TRUE only (absent otherwise):
 *   track-id           guint64      the marker's track, from 1 in order of the tracks'
 *                                   starts; the same for as long as the track lasts
 *                                   (0: a second marker of the same family and id in
 *                                   one frame, which is not tracked)
 *   track-state        gchararray   "measured" (detected in this frame) or "predicted"
 *                                   (not detected: the last detection moved where the
 *                                   track's constant-velocity model puts it; its quality
 *                                   fields are the last detection's)
 *   track-age          gdouble      seconds from the track's first frame to this one
 *   first-seen, last-seen
 *                      gdouble      the buffer timestamps (seconds) of the track's first
 *                                   frame and of the last one it was detected in
 *   pose-flipped       gboolean     an ambiguous pose was replaced by its other solution,
 *                                   the one the track's evidence favours (rvec, tvec and
 *                                   alternative-* are then swapped)
 *   smoothed-rvec, smoothed-tvec
 *                      3 gdouble    the One Euro filter's pose (smoothing=TRUE only;
 *                                   rvec and tvec stay the raw pose)
 * Truth only:
 *   centers            n^2 points   exact projected centres of the black squares
 *   fully-visible      gboolean     in front of the camera and wholly inside the frame
 *   edge-px            gdouble      mean projected edge of the black border, pixels
 */
#ifndef __LFTAG_META_H__
#define __LFTAG_META_H__

#include <gst/gst.h>

G_BEGIN_DECLS

#define LFTAG_META_NAME "LFTagMeta"
#define LFTAG_TRUTH_META_NAME "LFTagTruthMeta"

#define LFTAG_DETECTION_STRUCTURE_NAME "lftag/detection"
#define LFTAG_TRUTH_STRUCTURE_NAME "lftag/truth"

/* Fields of the metas' own structures. */
#define LFTAG_META_FIELD_WIDTH "width"
#define LFTAG_META_FIELD_HEIGHT "height"
#define LFTAG_META_FIELD_ANALYSED "analysed"
#define LFTAG_META_FIELD_DETECTIONS "detections"
#define LFTAG_META_FIELD_MARKERS "markers"
#define LFTAG_META_FIELD_FX "fx"
#define LFTAG_META_FIELD_FY "fy"
#define LFTAG_META_FIELD_CX "cx"
#define LFTAG_META_FIELD_CY "cy"
#define LFTAG_META_FIELD_DISTORTION "distortion"

/* Fields of each marker structure. */
#define LFTAG_FIELD_FAMILY "family"
#define LFTAG_FIELD_ID "id"
#define LFTAG_FIELD_ID_STRING "id-string"
#define LFTAG_FIELD_KEYPOINTS "keypoints"
#define LFTAG_FIELD_CENTROIDS "centroids"
#define LFTAG_FIELD_CORNERS "corners"
#define LFTAG_FIELD_CENTER "center"
#define LFTAG_FIELD_RVEC "rvec"
#define LFTAG_FIELD_TVEC "tvec"
#define LFTAG_FIELD_TAG_SIZE "tag-size"
#define LFTAG_FIELD_CALIBRATED "calibrated"
#define LFTAG_FIELD_DECODE_ERROR "decode-error"
#define LFTAG_FIELD_WORST_CELL "worst-cell"
#define LFTAG_FIELD_NOISE_MARGIN "noise-margin"
#define LFTAG_FIELD_EDGE_SCORE "edge-score"
#define LFTAG_FIELD_FROM_OUTLINE "from-outline"
#define LFTAG_FIELD_REPROJECTION_ERROR "reprojection-error"
#define LFTAG_FIELD_AMBIGUITY_RATIO "ambiguity-ratio"
#define LFTAG_FIELD_ALTERNATIVE_RVEC "alternative-rvec"
#define LFTAG_FIELD_ALTERNATIVE_TVEC "alternative-tvec"
#define LFTAG_FIELD_ALTERNATIVE_REPROJECTION_ERROR "alternative-reprojection-error"
#define LFTAG_FIELD_TRACK_ID "track-id"
#define LFTAG_FIELD_TRACK_STATE "track-state"
#define LFTAG_FIELD_TRACK_AGE "track-age"
#define LFTAG_FIELD_FIRST_SEEN "first-seen"
#define LFTAG_FIELD_LAST_SEEN "last-seen"
#define LFTAG_FIELD_POSE_FLIPPED "pose-flipped"
#define LFTAG_FIELD_SMOOTHED_RVEC "smoothed-rvec"
#define LFTAG_FIELD_SMOOTHED_TVEC "smoothed-tvec"
#define LFTAG_FIELD_CENTERS "centers"
#define LFTAG_FIELD_FULLY_VISIBLE "fully-visible"
#define LFTAG_FIELD_EDGE_PX "edge-px"

/* The structure of meta @meta_name on @buffer, or NULL when the buffer has none. */
static inline const GstStructure* lftag_meta_get_structure(GstBuffer* buffer, const gchar* meta_name) {
  GstCustomMeta* meta = gst_buffer_get_custom_meta(buffer, meta_name);
  return meta ? gst_custom_meta_get_structure(meta) : NULL;
}

/* Point @index of a list-of-points field (or index 0 of a single point field,
 * such as "center", when @index is -1). FALSE when there is no such point. */
static inline gboolean lftag_structure_get_point(const GstStructure* s, const gchar* field, gint index, gdouble* x,
                                                 gdouble* y) {
  const GValue* v = gst_structure_get_value(s, field);
  if (v == NULL || !GST_VALUE_HOLDS_ARRAY(v)) return FALSE;
  if (index >= 0) {
    if ((guint)index >= gst_value_array_get_size(v)) return FALSE;
    v = gst_value_array_get_value(v, index);
    if (!GST_VALUE_HOLDS_ARRAY(v)) return FALSE;
  }
  if (gst_value_array_get_size(v) != 2 || !G_VALUE_HOLDS_DOUBLE(gst_value_array_get_value(v, 0)) ||
      !G_VALUE_HOLDS_DOUBLE(gst_value_array_get_value(v, 1)))
    return FALSE;
  *x = g_value_get_double(gst_value_array_get_value(v, 0));
  *y = g_value_get_double(gst_value_array_get_value(v, 1));
  return TRUE;
}

G_END_DECLS

#endif /* __LFTAG_META_H__ */
