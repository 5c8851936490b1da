// SPDX-License-Identifier: LGPL-2.1-or-later
#include "gstplugin.hpp"

#include <filesystem>
#include <system_error>

#include <gst/gst.h>

namespace lftag::tools {
namespace {

namespace fs = std::filesystem;

// Whether this process is the tool built in this build tree (not an installed copy).
bool running_from_build_tree() {
  std::error_code error;
  const fs::path self = fs::canonical("/proc/self/exe", error);
  if (error) return false;
  const fs::path build = fs::canonical(LFTAG_TOOL_BUILD_DIR, error);
  return !error && self.parent_path() == build;
}

// Puts `dir` first on GStreamer's plugin path (the variable GStreamer reads: the
// versioned one when it is set).
void prepend_plugin_path(const std::string& dir) {
  const char* name = g_getenv("GST_PLUGIN_PATH_1_0") ? "GST_PLUGIN_PATH_1_0" : "GST_PLUGIN_PATH";
  const char* old = g_getenv(name);
  if (old) {
    gchar** parts = g_strsplit(old, G_SEARCHPATH_SEPARATOR_S, -1);
    const bool there = g_strv_contains(parts, dir.c_str());
    g_strfreev(parts);
    if (there) return;
  }
  const std::string value = old && *old ? dir + G_SEARCHPATH_SEPARATOR_S + old : dir;
  g_setenv(name, value.c_str(), TRUE);
}

bool have(const char* factory) {
  GstElementFactory* f = gst_element_factory_find(factory);
  if (!f) return false;
  gst_object_unref(f);
  return true;
}

}  // namespace

std::string init_gstreamer_with_plugin() {
  if (running_from_build_tree()) prepend_plugin_path(LFTAG_PLUGIN_BUILD_DIR);
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
           "GST_PLUGIN_PATH to the folder that holds it (" LFTAG_PLUGIN_INSTALL_DIR " when installed)";
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
