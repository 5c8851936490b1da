/* SPDX-License-Identifier: LGPL-2.1-or-later */
/* The detector's tunable parameters (lftag::io::tunables()) as GObject properties: one
 * int, double or boolean property per row, installed, read and written here only
 * (header-only: `lftag annotate` includes it without linking the plugin), so that
 * lftagdetect and the apps that set it up convert them the same way. */
#pragma once

#include <gst/gst.h>

#include "tunables.hpp"

namespace lftag::gst {
namespace detail {

inline GType type_of(io::Tunable::Kind kind) {
  switch (kind) {
    case io::Tunable::Kind::integer: return G_TYPE_INT;
    case io::Tunable::Kind::real: return G_TYPE_DOUBLE;
    case io::Tunable::Kind::boolean: return G_TYPE_BOOLEAN;
  }
  return G_TYPE_INVALID;
}

}  // namespace detail

/* Installs one property per tunable, with consecutive ids from `first_id`, their
 * defaults those of `defaults`. */
inline void install_tunable_properties(GObjectClass* klass, guint first_id, const DetectorParams& defaults,
                                       GParamFlags flags) {
  for (guint i = 0; i < io::kTunables; ++i) {
    const io::Tunable& t = io::tunables()[i];
    const double value = t.get(defaults);
    GParamSpec* spec = nullptr;
    switch (t.kind) {
      case io::Tunable::Kind::integer:
        spec = g_param_spec_int(t.name, t.nick, t.blurb, gint(t.min), gint(t.max), gint(value), flags);
        break;
      case io::Tunable::Kind::real:
        spec = g_param_spec_double(t.name, t.nick, t.blurb, t.min, t.max, value, flags);
        break;
      case io::Tunable::Kind::boolean: spec = g_param_spec_boolean(t.name, t.nick, t.blurb, value != 0, flags); break;
    }
    g_object_class_install_property(klass, first_id + i, spec);
  }
}

/* The tunable's value in `params` from `value`, a GValue of its property's type. */
inline void set_tunable(const io::Tunable& tunable, const GValue* value, DetectorParams& params) {
  switch (tunable.kind) {
    case io::Tunable::Kind::integer: tunable.set(params, g_value_get_int(value)); break;
    case io::Tunable::Kind::real: tunable.set(params, g_value_get_double(value)); break;
    case io::Tunable::Kind::boolean: tunable.set(params, g_value_get_boolean(value)); break;
  }
}

/* `value` (of the tunable's property type) set to the tunable's value in `params`. */
inline void get_tunable(const io::Tunable& tunable, const DetectorParams& params, GValue* value) {
  const double v = tunable.get(params);
  switch (tunable.kind) {
    case io::Tunable::Kind::integer: g_value_set_int(value, gint(v)); break;
    case io::Tunable::Kind::real: g_value_set_double(value, v); break;
    case io::Tunable::Kind::boolean: g_value_set_boolean(value, v != 0); break;
  }
}

/* Sets every tunable property of `object` (an lftagdetect) to its value in `params`. */
inline void set_tunable_properties(GObject* object, const DetectorParams& params) {
  for (const io::Tunable& t : io::tunables()) {
    GValue value = G_VALUE_INIT;
    g_value_init(&value, detail::type_of(t.kind));
    get_tunable(t, params, &value);
    g_object_set_property(object, t.name, &value);
    g_value_unset(&value);
  }
}

}  // namespace lftag::gst
