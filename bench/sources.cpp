// SPDX-License-Identifier: LGPL-2.1-or-later
#include "sources.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace bench {

std::vector<Source> list_sources(const std::filesystem::path& dir) {
  std::vector<Source> sources;
  if (std::filesystem::is_directory(dir))
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".jpg" || ext == ".png") sources.push_back({entry.path(), false, 1});
      if (ext == ".avi") {
        // The container's frame count can overstate what decodes (tree.avi), so count.
        cv::VideoCapture capture(entry.path().string());
        int frames = 0;
        while (capture.grab()) ++frames;
        if (frames > 0) sources.push_back({entry.path(), true, frames});
      }
    }
  if (sources.empty())
    throw std::runtime_error("no images or videos in " + dir.string() + " (install the opencv-doc package)");
  std::sort(sources.begin(), sources.end(), [](const Source& a, const Source& b) { return a.path < b.path; });
  return sources;
}

cv::Mat1b FrameReader::read(int source, int frame) {
  if (source == last_source_ && frame == last_frame_) return last_.clone();
  const Source& s = sources_.at(source);
  cv::Mat image;
  if (!s.video) {
    image = cv::imread(s.path.string(), cv::IMREAD_GRAYSCALE);
  } else {
    if (open_ != source || next_ > frame) {
      capture_.open(s.path.string());
      open_ = source, next_ = 0;
    }
    for (; next_ < frame; ++next_) capture_.grab();
    ++next_;
    if (capture_.read(image)) cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
  }
  if (image.empty())
    throw std::runtime_error("cannot read " + s.path.string() + (s.video ? " frame " + std::to_string(frame) : ""));
  last_source_ = source, last_frame_ = frame, last_ = image;
  return last_.clone();
}

cv::Mat1b cover(const cv::Mat1b& image, cv::Size size) {
  const double s = std::max(double(size.width) / image.cols, double(size.height) / image.rows);
  const cv::Size scaled_size(std::max(size.width, int(std::ceil(image.cols * s))),
                             std::max(size.height, int(std::ceil(image.rows * s))));
  cv::Mat1b scaled;
  cv::resize(image, scaled, scaled_size, 0, 0, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
  const cv::Point corner((scaled.cols - size.width) / 2, (scaled.rows - size.height) / 2);
  return scaled(cv::Rect(corner, size)).clone();
}

}  // namespace bench
