/* SPDX-License-Identifier: LGPL-2.1-or-later */
#ifndef __GST_LFTAG_PUBLISH_H__
#define __GST_LFTAG_PUBLISH_H__

#include <gst/base/gstbasetransform.h>
#include <gst/gst.h>

G_BEGIN_DECLS

#define GST_TYPE_LFTAG_PUBLISH (gst_lftag_publish_get_type())
G_DECLARE_FINAL_TYPE(GstLFTagPublish, gst_lftag_publish, GST, LFTAG_PUBLISH, GstBaseTransform)

GST_ELEMENT_REGISTER_DECLARE(lftagpublish);

G_END_DECLS

#endif /* __GST_LFTAG_PUBLISH_H__ */
