// SPDX-License-Identifier: LGPL-2.1-or-later
// A clip through an H.264 encoder and decoder (GStreamer's x264enc and avdec_h264, in
// process), as a camera streaming at a fixed bitrate would deliver it.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace bench {

// Empty when the round trip can run; otherwise why not (which elements or packages are
// missing, or that lftag-bench was built without gstreamer-app-1.0).
std::string h264_unavailable();

// Encodes grey frames of one size as one H.264 stream (`fps` frames a second, `kbps`
// kbit/s, one thread, x264's veryfast preset tuned for zero latency: no B-frames, no
// look-ahead, a key frame every second) and decodes it; the frames go in as the luma of
// I420 frames with neutral chroma, and the decoded luma comes back as it is. Throws
// std::runtime_error when GStreamer fails or returns another number of frames.
std::vector<cv::Mat1b> h264_round_trip(const std::vector<cv::Mat1b>& frames, int kbps, int fps = 30);

}  // namespace bench
