/* SPDX-License-Identifier: LGPL-2.1-or-later */
#ifndef __GST_LFTAG_TEST_SRC_H__
#define __GST_LFTAG_TEST_SRC_H__

#include <gst/base/gstpushsrc.h>
#include <gst/gst.h>

G_BEGIN_DECLS

#define GST_TYPE_LFTAG_TEST_SRC (gst_lftag_test_src_get_type())
G_DECLARE_FINAL_TYPE(GstLFTagTestSrc, gst_lftag_test_src, GST, LFTAG_TEST_SRC, GstPushSrc)

/**
 * GstLFTagTestSrcBackground:
 * @GST_LFTAG_TEST_SRC_BACKGROUND_FLAT: uniform grey, evenly lit
 * @GST_LFTAG_TEST_SRC_BACKGROUND_GRADIENT: uniform grey lit unevenly: the light
 *     varies by +-30 % across the frame, markers included
 * @GST_LFTAG_TEST_SRC_BACKGROUND_PHOTO: the image file named by background-location,
 *     scaled to cover the frame
 */
typedef enum {
  GST_LFTAG_TEST_SRC_BACKGROUND_FLAT,
  GST_LFTAG_TEST_SRC_BACKGROUND_GRADIENT,
  GST_LFTAG_TEST_SRC_BACKGROUND_PHOTO,
} GstLFTagTestSrcBackground;

GST_ELEMENT_REGISTER_DECLARE(lftagtestsrc);

G_END_DECLS

#endif /* __GST_LFTAG_TEST_SRC_H__ */
