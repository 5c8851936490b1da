// SPDX-License-Identifier: LGPL-2.1-or-later
// Real, marker-free images: the photos and videos that opencv-doc installs in
// /usr/share/doc/opencv-doc/examples/data. Used as false-positive bait and timing frames.
#pragma once

#include <filesystem>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

namespace bench {

struct Source {
  std::filesystem::path path;
  bool video = false;
  int frames = 1;  // of a video: the frames that can actually be read
};

// Every image (.jpg, .png) and video (.avi) directly in `dir`, by name. Throws
// std::runtime_error when there are none (opencv-doc not installed).
std::vector<Source> list_sources(const std::filesystem::path& dir);

// Reads any frame of any source as grey. Reading forward through a video is cheap;
// going back reopens it, so callers visit frames in (source, frame) order. The last
// frame read is kept, so asking for it again costs nothing.
class FrameReader {
 public:
  explicit FrameReader(std::vector<Source> sources) : sources_(std::move(sources)) {}
  cv::Mat1b read(int source, int frame);

 private:
  std::vector<Source> sources_;
  cv::VideoCapture capture_;
  int open_ = -1, next_ = 0;  // the open video and the index of its next frame
  int last_source_ = -1, last_frame_ = -1;
  cv::Mat1b last_;
};

// Scaled to cover `size` and cropped about the centre (as SceneRenderer fits a photo).
cv::Mat1b cover(const cv::Mat1b& image, cv::Size size);

}  // namespace bench
