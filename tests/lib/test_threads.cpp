// SPDX-License-Identifier: LGPL-2.1-or-later
// Detection from several threads at once, one Detector per thread as detector.hpp asks,
// on frames shared read-only between the threads: every thread finds exactly what one
// thread alone finds. Run under ThreadSanitizer by scripts/test-sanitizers.sh (suite
// "threads"), this also checks the library for data races between detectors.
#include <atomic>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "lftag/detector.hpp"
#include "lftag/draw.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"
#include "scenes.hpp"

using namespace lftag;

namespace {

// Three frames with markers of several families, far, near, tilted and blurred.
std::vector<cv::Mat1b> frames() {
  std::vector<cv::Mat1b> out;
  for (int k = 0; k < 3; ++k) {
    SceneParams p;
    p.camera = lftag::test::paper_camera();
    p.blur_length_px = k == 2 ? 3 : 0;
    p.noise_sigma = k;
    std::vector<SceneMarker> markers;
    for (int i = 0; i < 3; ++i) {
      SceneMarker m;
      m.family = Family(3 + (i + k) % 4);
      m.id = TagId(std::uint64_t(1000 * k + 77 * i + 5));
      m.tag_size = 0.1;
      m.tvec = {-0.15 + 0.15 * i, 0.02 * k, 0.25 + 0.05 * i};
      m.rvec = lftag::test::rotation(30.0 * i + 10 * k, 20.0 * (i % 2), 0);
      markers.push_back(m);
    }
    out.push_back(render_scene(p, markers).image);
  }
  return out;
}

DetectorParams params() {
  DetectorParams p;
  p.families = Family::all();
  p.tag_size = 0.1;
  return p;
}

bool same(const std::vector<Detection>& a, const std::vector<Detection>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].family != b[i].family || a[i].id != b[i].id || a[i].centroids != b[i].centroids || a[i].tvec != b[i].tvec)
      return false;
  return true;
}

}  // namespace

TEST(Threads, OneDetectorPerThreadFindsWhatOneThreadFinds) {
  const std::vector<cv::Mat1b> images = frames();
  std::vector<std::vector<Detection>> expected;
  Detector single(params());
  for (const cv::Mat1b& image : images) {
    expected.push_back(single.detect(ImageView(image)));
    ASSERT_GE(expected.back().size(), 2u) << "too few markers found to compare";
  }

  constexpr int kThreads = 4, kRounds = 3;
  std::atomic<int> mismatches{0}, errors{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      try {
        Detector detector(params());  // never shared: it keeps its buffers between frames
        for (int round = 0; round < kRounds; ++round)
          for (std::size_t k = 0; k < images.size(); ++k) {
            const std::size_t i = (k + std::size_t(t)) % images.size();  // threads out of step
            DetectionStats stats;
            const std::vector<Detection> found = detector.detect(ImageView(images[i]), &stats);
            if (!same(found, expected[i])) ++mismatches;
            cv::Mat drawn;
            cv::cvtColor(images[i], drawn, cv::COLOR_GRAY2BGR);
            draw_detections(drawn, found, Camera::default_for(drawn.cols, drawn.rows));
          }
      } catch (...) {
        ++errors;
      }
    });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_EQ(errors.load(), 0);
}
