// SPDX-License-Identifier: LGPL-2.1-or-later
// How the `lftag` tool finds the lftag GStreamer plugin (libgstlftag.so).
#pragma once

#include <string>

namespace lftag::tools {

// Initialises GStreamer with the plugin available: GStreamer's registry (GST_PLUGIN_PATH,
// then the system plugin directory, where `meson install` puts the plugin) and, if the
// plugin is not there, the directory it is installed to. Nothing of the build tree is
// baked in: a tool run from the build finds the build's plugin on GST_PLUGIN_PATH, which
// `meson devenv -C build` and the tests set. Returns an empty string, or why the plugin's
// elements cannot be had (a sentence that says what to do).
std::string init_gstreamer_with_plugin();

}  // namespace lftag::tools
