// SPDX-License-Identifier: LGPL-2.1-or-later
// The input format of the frame fuzz targets (fuzz_frames, fuzz_scenes) and the check
// they run on each input. An input is a 6-byte header and the pixels:
//
//   byte 0      flags: 1 second look, 2 pose refinement, 4 trace, 8 stats,
//               16 centroids against full scale, 32 a distorting calibrated camera
//   byte 1      threshold window: 2 + b % 63
//   byte 2      threshold offset: b % 32
//   bytes 3, 4  width: 1 + (b3 | b4 << 8) % 512
//   byte 5      row padding: stride = width + b % 16
//   the rest    rows of `stride` bytes; height = as many rows as there are bytes (the last
//               row needs only `width` of them)
//
// The pixels are copied into a buffer that ends right after the last pixel, so that
// AddressSanitizer sees any read past the frame. Every family from 2x2 to 8x8 is searched.
// One Detector sees the frame, then a crop of it (another size, the same buffers), then the
// frame again, which must give exactly the first result: the reused buffers must not
// carry anything from one frame to the next.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "lftag/detector.hpp"

namespace lftag::fuzz {

constexpr std::size_t kHeader = 6;

inline bool same(const std::vector<Detection>& a, const std::vector<Detection>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].family != b[i].family || a[i].id != b[i].id || a[i].centroids != b[i].centroids ||
        a[i].tvec != b[i].tvec || a[i].rvec != b[i].rvec)
      return false;
  return true;
}

inline void detect_frame(const std::uint8_t* data, std::size_t size) {
  if (size < kHeader + 1) return;
  const unsigned flags = data[0];
  const int width = 1 + int((data[3] | (data[4] << 8)) % 512);
  const std::ptrdiff_t stride = width + data[5] % 16;
  const std::size_t pixels = size - kHeader;
  if (pixels < std::size_t(width)) return;
  const int height = int((pixels - std::size_t(width)) / std::size_t(stride)) + 1;
  std::vector<std::uint8_t> frame(std::size_t(height - 1) * std::size_t(stride) + std::size_t(width));
  std::memcpy(frame.data(), data + kHeader, frame.size());

  DetectorParams params;
  params.families = Family::all();
  params.second_look = flags & 1;
  params.refine_pose = flags & 2;
  params.threshold_window = 2 + data[1] % 63;
  params.threshold_offset = data[2] % 32;
  if (flags & 16) params.centroid_reference = CentroidReference::full_scale;
  if (flags & 32) {
    // No frame size: it applies as it is to the crop below (one with a size would be
    // refused for a crop of another aspect ratio, as documented).
    params.camera = Camera::pinhole(width, width, (width - 1) / 2.0, (height - 1) / 2.0);
    params.camera->distortion = {-0.2, 0.05, 0.001, -0.001};
  }
  Detector detector(params);
  DetectionStats stats;
  DetectionTrace trace;
  const ImageView view(frame.data(), width, height, stride);
  const std::vector<Detection> first = detector.detect(view, flags & 8 ? &stats : nullptr, flags & 4 ? &trace : nullptr);
  if (width > 2 && height > 2) {
    const ImageView crop(frame.data() + stride + 1, width - 2, height - 2, stride);
    detector.detect(crop, flags & 8 ? &stats : nullptr, flags & 4 ? &trace : nullptr);
  }
  const std::vector<Detection> again = detector.detect(view);
  if (!same(first, again)) {
    std::fprintf(stderr, "the same frame gave %zu detections, then %zu\n", first.size(), again.size());
    std::abort();
  }
}

}  // namespace lftag::fuzz
