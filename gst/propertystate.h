/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* Property values the elements refuse out loud instead of storing or dropping them
 * silently: a change of a property that takes effect only at start
 * (GST_PARAM_MUTABLE_READY) once started, and text that cannot be read. */
#pragma once

#include <initializer_list>
#include <string>

#include <gst/gst.h>

namespace lftag::gst {

/* TRUE when `pspec` may be set now: it is mutable in every state, or `element` is in
 * NULL or READY. Otherwise posts an element warning naming the property and the state,
 * and returns FALSE: the caller keeps the old value. */
gboolean property_settable_now(GstElement* element, GParamSpec* pspec);

/* A text value of `property` that cannot be read (`why`): posts an element warning naming
 * the property and the value (the old value stays) and returns the refusal, which the
 * element keeps, under its object lock, until a good value clears it. */
std::string refuse_value(GstElement* element, const char* property, const char* value, const std::string& why);

/* At start: FALSE, with an element error, when a refusal is kept; a value set before the
 * start (in a launch line) was refused when the element had no bus to warn on yet. */
gboolean no_refused_values(GstElement* element, std::initializer_list<const std::string*> refusals);

}  // namespace lftag::gst
