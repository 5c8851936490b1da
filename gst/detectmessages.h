/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* lftagdetect's bus messages: when a frame posts one (the "messages" property) and
 * what it holds. */
#ifndef __LFTAG_DETECT_MESSAGES_H__
#define __LFTAG_DETECT_MESSAGES_H__

#include <string>
#include <vector>

#include <gst/gst.h>

#include <lftag/detector.hpp>
#include <lftag/tracker.hpp>

G_BEGIN_DECLS

/**
 * GstLFTagDetectMessages:
 * @GST_LFTAG_DETECT_MESSAGES_NONE: no messages
 * @GST_LFTAG_DETECT_MESSAGES_WITH_MARKERS: every frame with at least one marker
 * @GST_LFTAG_DETECT_MESSAGES_ON_CHANGE: a frame whose set of markers (family and
 *     id) differs from the previous frame's, including the first frame without any
 * @GST_LFTAG_DETECT_MESSAGES_EVERY_FRAME: every analysed frame, with or without markers
 *
 * When lftagdetect posts its "lftag" element message.
 */
typedef enum {
  GST_LFTAG_DETECT_MESSAGES_NONE = 0,
  GST_LFTAG_DETECT_MESSAGES_WITH_MARKERS = 1,
  GST_LFTAG_DETECT_MESSAGES_ON_CHANGE = 2,
  GST_LFTAG_DETECT_MESSAGES_EVERY_FRAME = 3,
} GstLFTagDetectMessages;

#define GST_TYPE_LFTAG_DETECT_MESSAGES (gst_lftag_detect_messages_get_type())
GType gst_lftag_detect_messages_get_type(void);

G_END_DECLS

namespace lftag::gst {

/* Decides, frame after frame of one stream, which frames post a message, and
 * builds it. Used by the streaming thread only. */
class DetectMessages {
 public:
  /* The "lftag" message of this frame under `mode`, or null when it posts none;
   * with `full`, the whole detections at its end (message-detections). Every
   * analysed frame must come through here, whatever the mode, so that
   * "on-change" and the "appeared" and "vanished" fields compare with the frame
   * just before. With `tracks` (tracking: one per detection, predicted markers
   * included, so that on-change posts when a track starts or is lost), the message
   * also holds "track-ids" and "track-states" beside "ids". */
  GstMessage* frame(GstObject* source, GstLFTagDetectMessages mode, bool full, const GstSegment& segment,
                    GstBuffer* buffer, int width, int height, const std::vector<Detection>& detections,
                    const std::vector<TrackInfo>* tracks = nullptr);
  /* A new stream: nothing was seen before. */
  void reset() { previous_.clear(); }

 private:
  std::vector<std::string> previous_; /* sorted "3x3:6789" of the frame before */
};

/* "3x3:6789": a marker's family and decimal id, as the messages name it. */
std::string marker_key(const Family& family, const TagId& id);

}  // namespace lftag::gst

#endif /* __LFTAG_DETECT_MESSAGES_H__ */
