// SPDX-License-Identifier: LGPL-2.1-or-later
#include "gstplugin.hpp"

#include <gst/gst.h>

namespace lftag::tools {
namespace {

bool have(const char* factory) {
  GstElementFactory* f = gst_element_factory_find(factory);
  if (!f) return false;
  gst_object_unref(f);
  return true;
}

}  // namespace

std::string init_gstreamer_with_plugin() {
  GError* error = nullptr;
  if (!gst_init_check(nullptr, nullptr, &error)) {
    const std::string why = std::string("cannot initialise GStreamer: ") + error->message;
    g_error_free(error);
    return why;
  }
  // GST_PLUGIN_SYSTEM_PATH may leave out the directory the plugin was installed to.
  if (!have("lftagdetect")) gst_registry_scan_path(gst_registry_get(), LFTAG_PLUGIN_INSTALL_DIR);
  if (!have("lftagdetect"))
    return "the lftag GStreamer plugin (libgstlftag.so) is not installed: run `meson install`, or set "
           "GST_PLUGIN_PATH to the folder that holds it (" LFTAG_PLUGIN_INSTALL_DIR
           " when installed; from a "
           "build tree, run the tool under `meson devenv -C build`)";
  if (!have("lftagpublish")) {
    GstPlugin* plugin = gst_registry_find_plugin(gst_registry_get(), "lftag");
    const std::string file = plugin && gst_plugin_get_filename(plugin) ? gst_plugin_get_filename(plugin) : "?";
    if (plugin) gst_object_unref(plugin);
    return "the lftag GStreamer plugin found (" + file +
           ") is older than this tool and lacks lftagpublish: install this build's plugin (`meson install`)";
  }
  return {};
}

}  // namespace lftag::tools
