// SPDX-License-Identifier: LGPL-2.1-or-later
// The input format of fuzz_element, shared with make_corpus, which writes its seeds. Read
// from the front (gst_fuzz.hpp's Reader: u16 and u32 little-endian, zeros once the input
// is spent, so that every input is a complete one):
//
//   stream      u8 format (index into kFormats), u16 width, u16 height (1 + v % kMaxSide
//               each), u8 settings (kOverlay* bits, kCompositions, kNoSecondLook, messages in
//               bits 5-6, kLateFrames), u8 families (bit i: (i + 2)x(i + 2); 0: the
//               default), u8 deadline (0.25 ms * (1 + b % 16)), u8 threshold window
//               (2 + b % 63), u8 buffers (1 + b % 4); with kLateFrames, a QoS event: u16
//               lateness (ms), u8 timestamp (10 ms)
//   each buffer u8 flags (kMeta, kSplit, kNewCaps, kFamiliesText, kFlipOverlay,
//               kUpstreamMetas, kNoTimestamp, kCamera), then as flagged:
//                 kNewCaps       format, width, height as above, first
//                 kFamiliesText  u8 length and the text, set as "families" while playing
//                 kCamera        (not on the first buffer) u16 fx and fy (v / 4 px; 0: not
//                                set), u16 cx and cy (v / 16 - 1 px; -1: not set), u8
//                                tag-size (0.01 m * (1 + b)), u8 length and the
//                                "distortion" text, set while playing
//                 kMeta          u8 padding right (% 16), u8 padding bottom (% 4), u8
//                                stride alignment (2^(b % 7)), then per plane u8 lie
//                                (Lie, % 8) and u32 value, then u8 the meta's extra width
//                                (bits 0-1) and height (bits 2-3)
//               u8 size kind (Size, % 4) and u32 value; with kSplit u8 cuts (1 + b % 3)
//               and a u16 offset each (% size); u16 length and the pixels, repeated to
//               fill the buffer (none: a ramp).
#pragma once

#include <cstdint>

namespace lftag::fuzz::element {

// lftagdetect's sink formats (DETECT_FORMATS in gst/gstlftagdetect.cpp), in its order;
// fuzz_element checks at start that the element's template lists exactly these.
constexpr const char* kFormats[] = {"GRAY8", "I420", "YV12", "NV12", "NV21",      "Y42B",     "Y444", "RGB",
                                    "BGR",   "RGBx", "BGRx", "xRGB", "xBGR",      "RGBA",     "BGRA", "ARGB",
                                    "ABGR",  "YUY2", "UYVY", "YVYU", "I420_10LE", "P010_10LE"};
constexpr int kMaxSide = 256;

// Stream settings.
constexpr std::uint8_t kOverlayOutline = 1, kOverlayId = 2, kOverlayAxes = 4;
constexpr std::uint8_t kCompositions = 8;  // downstream takes overlay compositions (allocation query)
constexpr std::uint8_t kNoSecondLook = 16;
constexpr int kMessagesShift = 5;          // messages: none, with-markers, on-change, every-frame
constexpr std::uint8_t kLateFrames = 128;  // late-frames=skip, and a QoS event from downstream

// Buffer flags.
constexpr std::uint8_t kMeta = 1, kSplit = 2, kNewCaps = 4, kFamiliesText = 8, kFlipOverlay = 16, kUpstreamMetas = 32,
                       kNoTimestamp = 64, kCamera = 128;

// What a plane's entry in the video meta says (the value is the lie's u32).
enum Lie : std::uint8_t {
  kTrue = 0,
  kStrideOff = 1,       // stride plus a signed 16-bit value
  kStrideNegative = 2,  // minus the stride's size
  kStrideAny = 3,       // the value as a stride
  kOffsetOff = 4,       // offset plus the value % 65536
  kOffsetAny = 5,       // the value as an offset
  kBothOff = 6,         // stride plus the low 16 bits (signed), offset plus the high ones
};

// The buffer's size against the layout's.
enum Size : std::uint8_t {
  kExact = 0,
  kShort = 1,  // by the value % (size + 1), at least one byte left
  kLong = 2,   // by the value % 4096
  kAny = 3,    // 1 + the value % (2 * size)
};

}  // namespace lftag::fuzz::element
