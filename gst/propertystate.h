/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* Properties that take effect only when an element starts (GST_PARAM_MUTABLE_READY):
 * GStreamer does not stop them being set later, so the elements refuse such a change
 * out loud instead of storing a value nothing reads. */
#pragma once

#include <gst/gst.h>

namespace lftag::gst {

/* TRUE when `pspec` may be set now: it is mutable in every state, or `element` is in
 * NULL or READY. Otherwise posts an element warning naming the property and the state,
 * and returns FALSE: the caller keeps the old value. */
gboolean property_settable_now(GstElement* element, GParamSpec* pspec);

}  // namespace lftag::gst
