// SPDX-License-Identifier: LGPL-2.1-or-later
// No detection at all, for any family, on marker-free real images: every photo and every
// frame of every video in opencv-doc's examples/data, at 640x480 and 1280x720.
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "lftag/detector.hpp"
#include "lftag/trace.hpp"

using namespace lftag;

namespace {

const std::filesystem::path kData = "/usr/share/doc/opencv-doc/examples/data";

struct Count {
  int frames = 0;
  std::vector<std::string> hits;
};

void check(Detector& detector, const cv::Mat& grey, const std::string& name, Count& count, DetectionStats& stats) {
  for (const cv::Size size : {cv::Size(640, 480), cv::Size(1280, 720)}) {
    cv::Mat frame;
    cv::resize(grey, frame, size, 0, 0, cv::INTER_AREA);
    ++count.frames;
    for (const Detection& d : detector.detect(ImageView(frame), &stats))
      count.hits.push_back(name + " at " + std::to_string(size.width) + ": " + d.family.name() + " id " +
                           d.id.to_decimal());
  }
}

}  // namespace

TEST(FalsePositives, NoneOnOpenCvPhotosAndVideos) {
  if (!std::filesystem::is_directory(kData))
    GTEST_SKIP() << kData << " is missing: install the Debian package opencv-doc (scripts/test.sh does)";
  DetectorParams params;
  params.families = Family::all();
  Detector detector(params);
  Count count;
  DetectionStats stats;
  int videos = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kData)) {
    const std::string path = entry.path().string();
    if (entry.path().extension() == ".avi") {
      cv::VideoCapture video(path);
      ASSERT_TRUE(video.isOpened()) << path;
      cv::Mat frame, grey;
      for (int i = 0; video.read(frame); ++i) {
        cv::cvtColor(frame, grey, cv::COLOR_BGR2GRAY);
        check(detector, grey, entry.path().filename().string() + " frame " + std::to_string(i), count, stats);
      }
      ++videos;
    } else {
      const cv::Mat grey = cv::imread(path, cv::IMREAD_GRAYSCALE);
      if (!grey.empty() && grey.cols >= 32 && grey.rows >= 32)
        check(detector, grey, entry.path().filename().string(), count, stats);
    }
  }
  EXPECT_GE(videos, 4);
  EXPECT_GT(count.frames, 2500);
  EXPECT_GT(stats.topology, 1000);  // plenty of candidates reached the later stages
  EXPECT_GT(stats.collinearity, 100);
  EXPECT_TRUE(count.hits.empty()) << count.hits.size() << " false positives, first: " << count.hits.front();
  std::cout << count.frames << " frames, funnel " << stats.topology << " -> " << stats.area << " -> " << stats.geometry
            << " -> " << stats.angle << " -> " << stats.collinearity << " -> " << stats.residual << " -> "
            << stats.unambiguous << " -> " << stats.decoded << "\n";
}
