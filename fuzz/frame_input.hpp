// SPDX-License-Identifier: LGPL-2.1-or-later
// The input format of the frame fuzz targets (fuzz_frames, fuzz_scenes) and the check
// they run on each input. An input is a 6-byte header and the pixels:
//
//   byte 0      flags: 1 second look, 2 pose refinement, 4 trace, 8 stats of the crop's run,
//               16 centroids against full scale, 32 a distorting calibrated camera,
//               64 the reuse check (below)
//   byte 1      threshold window: 2 + b % 63
//   byte 2      threshold offset: b % 32
//   bytes 3, 4  width: 1 + (b3 | b4 << 8) % kMaxSide
//   byte 5      row padding: stride = width + b % 16
//   the rest    rows of `stride` bytes; height = as many rows as there are bytes, at most
//               kMaxSide (the last row needs only `width` of them; bytes past it are unused)
//
// Frames are at most 128 x 128 (kMaxInput bytes; scripts/fuzz.sh's max_len), and every
// detection has a deadline in processor time (DetectorParams::deadline_ms, set by each
// target), so that no input costs more than a few tens of milliseconds: large frames are
// the tests' (tests/lib), the fuzzers' are the many odd small ones. (Inputs of the
// earlier format, width up to 512, read the same when no side was over 128.)
//
// The pixels are copied into a buffer that ends right after the last pixel, so that
// AddressSanitizer sees any read past the frame. Every family from 2x2 to 8x8 is searched.
// With flag 64 (half the inputs, so that the target stays at thousands of inputs a second)
// the one Detector sees the frame, then a crop of it (another size, the same buffers), then
// the frame again, which must give exactly the first result when the deadline cut neither
// run (a cut run legitimately stops elsewhere): the reused buffers must not carry
// anything from one frame to the next.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include <opencv2/core/utility.hpp>

#include "lftag/detector.hpp"
#include "lftag/trace.hpp"

namespace lftag::fuzz {

constexpr std::size_t kHeader = 6;
constexpr int kMaxSide = 128;
// The largest input that is read whole: 128 rows of 128 pixels and 15 bytes of padding.
constexpr std::size_t kMaxInput = kHeader + (kMaxSide - 1) * (kMaxSide + 15) + kMaxSide;

inline bool same(const std::vector<Detection>& a, const std::vector<Detection>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].family != b[i].family || a[i].id != b[i].id || a[i].centroids != b[i].centroids ||
        a[i].tvec != b[i].tvec || a[i].rvec != b[i].rvec)
      return false;
  return true;
}

// `deadline_ms`: each detection's deadline (DetectorParams::deadline_ms), > 0.
inline void detect_frame(const std::uint8_t* data, std::size_t size, double deadline_ms) {
  if (size < kHeader + 1) return;
  const unsigned flags = data[0];
  const int width = 1 + int((data[3] | (data[4] << 8)) % kMaxSide);
  const std::ptrdiff_t stride = width + data[5] % 16;
  const std::size_t pixels = size - kHeader;
  if (pixels < std::size_t(width)) return;
  const int height = int(std::min<std::size_t>((pixels - std::size_t(width)) / std::size_t(stride) + 1, kMaxSide));
  std::vector<std::uint8_t> frame(std::size_t(height - 1) * std::size_t(stride) + std::size_t(width));
  std::memcpy(frame.data(), data + kHeader, frame.size());

  DetectorParams params;
  params.families = Family::all();
  params.second_look = flags & 1;
  params.refine_pose = flags & 2;
  params.threshold_window = 2 + data[1] % 63;
  params.threshold_offset = data[2] % 32;
  params.deadline_ms = deadline_ms;
  if (flags & 16) params.centroid_reference = CentroidReference::full_scale;
  if (flags & 32) {
    // No frame size: it applies as it is to the crop below (one with a size would be
    // refused for a crop of another aspect ratio, as documented).
    params.camera = Camera::pinhole(width, width, (width - 1) / 2.0, (height - 1) / 2.0);
    params.camera->distortion = {-0.2, 0.05, 0.001, -0.001};
  }
  Detector detector(params);
  // The first and last runs always count their work: whether the deadline cut them.
  DetectionStats first_stats, stats, again_stats;
  DetectionTrace trace;
  const ImageView view(frame.data(), width, height, stride);
  const std::vector<Detection> first = detector.detect(view, &first_stats, flags & 4 ? &trace : nullptr);
  if (!(flags & 64)) return;
  if (width > 2 && height > 2) {
    const ImageView crop(frame.data() + stride + 1, width - 2, height - 2, stride);
    detector.detect(crop, flags & 8 ? &stats : nullptr, flags & 4 ? &trace : nullptr);
  }
  // A cut first run has nothing to compare with; the crop has already reused the buffers.
  if (first_stats.past_deadline > 0) return;
  const std::vector<Detection> again = detector.detect(view, &again_stats);
  if (again_stats.past_deadline == 0 && !same(first, again)) {
    std::fprintf(stderr, "the same frame gave %zu detections, then %zu\n", first.size(), again.size());
    std::abort();
  }
}

}  // namespace lftag::fuzz

// OpenCV's thread pool costs more than it gives on frames of 128 x 128 (its workers
// spinning were a tenth of the frames target's time): every call runs on this thread.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  cv::setNumThreads(0);
  return 0;
}
