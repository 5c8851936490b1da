// SPDX-License-Identifier: LGPL-2.1-or-later
#include "propertystate.h"

namespace lftag::gst {

gboolean property_settable_now(GstElement* element, GParamSpec* pspec) {
  if (!(pspec->flags & GST_PARAM_MUTABLE_READY)) return TRUE;
  GST_OBJECT_LOCK(element);
  const GstState state = GST_STATE(element), pending = GST_STATE_PENDING(element);
  GST_OBJECT_UNLOCK(element);
  // Going up from READY counts: start() may already have read the settings.
  if (state <= GST_STATE_READY && (pending == GST_STATE_VOID_PENDING || pending <= GST_STATE_READY)) return TRUE;
  const GstState shown = state > GST_STATE_READY ? state : pending;
  GST_ELEMENT_WARNING(element, RESOURCE, SETTINGS,
                      ("\"%s\" can only change in the NULL or READY state, not in %s: the new value is ignored "
                       "and the old one stays. Set it before starting the pipeline, or stop it first.",
                       pspec->name, gst_element_state_get_name(shown)),
                      (nullptr));
  return FALSE;
}

std::string refuse_value(GstElement* element, const char* property, const char* value, const std::string& why) {
  const std::string refusal = std::string(property) + " \"" + (value ? value : "") + "\": " + why;
  GST_ELEMENT_WARNING(element, RESOURCE, SETTINGS, ("Invalid %s; the previous value stays.", refusal.c_str()),
                      (nullptr));
  return refusal;
}

gboolean no_refused_values(GstElement* element, std::initializer_list<const std::string*> refusals) {
  for (const std::string* refusal : refusals)
    if (!refusal->empty()) {
      GST_ELEMENT_ERROR(element, RESOURCE, SETTINGS, ("Invalid %s.", refusal->c_str()), (nullptr));
      return FALSE;
    }
  return TRUE;
}

}  // namespace lftag::gst
