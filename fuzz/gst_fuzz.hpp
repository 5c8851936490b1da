// SPDX-License-Identifier: LGPL-2.1-or-later
// What the GStreamer fuzz targets (fuzz_element, fuzz_json) share: GStreamer started once
// with the lftag plugin registered statically, and a reader of the input's bytes.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <gst/gst.h>

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LFTAG_FUZZ_LSAN 1
#include <sanitizer/lsan_interface.h>
#endif
#endif

// From GST_PLUGIN_DEFINE in gst/plugin.cpp (C linkage), compiled into the target
// (fuzz/meson.build).
extern "C" {
GST_PLUGIN_STATIC_DECLARE(lftag);
}

namespace lftag::fuzz {

// Criticals and warnings of GLib and GStreamer are bugs of the caller (ours): they
// stop the target as a crash would, with their message. Except inside a Tolerance,
// around a call of GStreamer's own on bad input: gst_structure_from_string logs a
// critical for a structure name it did not validate, and (GStreamer 1.22.0) leaks the
// nested structure of a field whose type it does not know, so what it allocates there
// is not checked for leaks either. Our code never runs inside one.
inline bool tolerating = false;

struct Tolerance {
  Tolerance() {
    tolerating = true;
#if LFTAG_FUZZ_LSAN
    __lsan_disable();
#endif
  }
  ~Tolerance() {
#if LFTAG_FUZZ_LSAN
    __lsan_enable();
#endif
    tolerating = false;
  }
  Tolerance(const Tolerance&) = delete;
  Tolerance& operator=(const Tolerance&) = delete;
};

inline void log_handler(const gchar* domain, GLogLevelFlags level, const gchar* message, gpointer) {
  if (!(level & (G_LOG_LEVEL_ERROR | G_LOG_LEVEL_CRITICAL | G_LOG_LEVEL_WARNING)) || tolerating) return;
  std::fprintf(stderr, "%s-%s: %s\n", domain ? domain : "", level & G_LOG_LEVEL_CRITICAL ? "CRITICAL" : "WARNING",
               message);
  std::abort();
}

// Once per process (LLVMFuzzerInitialize). No registry is read or written and no
// plugin directory scanned: the plugin is registered from the target itself, and
// GstHarness needs nothing else.
inline void start_gstreamer() {
  g_setenv("GST_REGISTRY_DISABLE", "yes", TRUE);
  g_setenv("GST_REGISTRY_FORK", "no", TRUE);
  gst_init(nullptr, nullptr);
  GST_PLUGIN_STATIC_REGISTER(lftag);
  g_log_set_default_handler(log_handler, nullptr);
}

// The input's bytes from the front, little-endian; zeros once they are spent, so that
// every input, however short, is a complete one.
class Reader {
 public:
  Reader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  std::uint8_t u8() { return at_ < size_ ? data_[at_++] : 0; }
  std::uint16_t u16() {
    const std::uint16_t low = u8();
    return std::uint16_t(low | u8() << 8);
  }
  std::uint32_t u32() {
    const std::uint32_t low = u16();
    return low | std::uint32_t(u16()) << 16;
  }
  std::uint64_t u64() {
    const std::uint64_t low = u32();
    return low | std::uint64_t(u32()) << 32;
  }
  // A length byte, then as many bytes (at most what is left).
  std::string text() {
    const std::size_t n = std::min<std::size_t>(u8(), left());
    std::string out(reinterpret_cast<const char*>(data_ + at_), n);
    at_ += n;
    return out;
  }
  // The next `n` bytes, or fewer when the input ends first.
  std::size_t take(std::size_t n, const std::uint8_t** out) {
    n = std::min(n, left());
    *out = data_ + at_;
    at_ += n;
    return n;
  }
  std::size_t left() const { return size_ - at_; }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

}  // namespace lftag::fuzz
