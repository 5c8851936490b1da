// SPDX-License-Identifier: LGPL-2.1-or-later
// Writes the seed corpora of the frame targets (fuzz/corpus/frames, fuzz/corpus/scenes)
// in the input format of frame_input.hpp (about 150 KB in all), and prints how many markers the detector finds
// in each seed. Run once by hand when the format changes:
//
//   build-sanitize/fuzz/make_corpus fuzz/corpus
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "frame_input.hpp"
#include "lftag/render.hpp"

namespace {

// `flags` as in frame_input.hpp, window 16, offset 4, no row padding.
void write(const std::string& path, const cv::Mat1b& image, std::uint8_t flags) {
  const int w = image.cols - 1;
  std::vector<std::uint8_t> out{flags, 14, 4, std::uint8_t(w & 255), std::uint8_t(w >> 8), 0};
  for (int y = 0; y < image.rows; ++y) out.insert(out.end(), image.ptr(y), image.ptr(y) + image.cols);
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
  lftag::DetectorParams params;
  params.families = lftag::Family::all();
  std::printf("%s: %dx%d, %zu found\n", path.c_str(), image.cols, image.rows,
              lftag::Detector(params).detect(lftag::ImageView(image)).size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_corpus DIR (writes DIR/frames and DIR/scenes)\n");
    return 2;
  }
  const std::string dir = argv[1];
  // Small fronto-parallel markers and plain frames: the frames target starts from these.
  write(dir + "/frames/marker-3x3", lftag::rasterize_marker(lftag::Family(3), 6789, 1.0), 3);
  write(dir + "/frames/marker-2x2", lftag::rasterize_marker(lftag::Family(2), 9, 1.5), 1);
  cv::Mat1b checker(16, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) checker(y, x) = ((x / 2 + y / 2) % 2) ? 255 : 0;
  write(dir + "/frames/checker", checker, 7);
  write(dir + "/frames/flat", cv::Mat1b(8, 8, std::uint8_t(128)), 0);

  // Rendered scenes: every family, face-on and turned, tilted, blurred and noisy, at
  // 64x56 (2x2 to 5x5) or 80x80 (6x6 to 8x8), the marker's border about 0.6 of the
  // frame's height across: small, so that the detector (with fuzz_scenes' deadline)
  // reaches decoding and pose in milliseconds, and every marker is still found.
  for (int n = lftag::Family::kMinN; n <= lftag::Family::kMaxN; ++n) {
    const lftag::Family family(n);
    const int w = n <= 5 ? 64 : 80, h = n <= 5 ? 56 : 80;
    for (int variant = 0; variant < 3; ++variant) {
      lftag::SceneParams scene;
      scene.camera = lftag::Camera::pinhole(w, w, (w - 1) / 2.0, (h - 1) / 2.0, w, h);
      scene.supersample = 4;
      lftag::SceneMarker marker;
      marker.family = family;
      marker.id = lftag::TagId(0x9e3779b97f4a7c15ull * std::uint64_t(n + variant), 0x7f4a7c159e3779b9ull);
      if (!family.contains(marker.id))
        marker.id = lftag::TagId(marker.id.high() & family.max_id().high(), marker.id.low() & family.max_id().low());
      marker.tvec = {0.02 * (variant - 1), 0.0, w / (0.6 * h)};
      marker.rvec = lftag::rotation_from_angles(25.0 * variant + 5 * n, variant == 1 ? 35 : 0, variant == 2 ? 20 : 0);
      if (variant == 2) {
        scene.blur_length_px = 2.5;
        scene.blur_angle_deg = 30;
        scene.noise_sigma = 3;
        scene.light_gradient = 0.4;
      }
      const lftag::RenderedScene rendered = lftag::render_scene(scene, {marker});
      const std::uint8_t flags = variant == 0 ? 3 : variant == 1 ? (1 | 2 | 4 | 8 | 32) : (1 | 16);
      write(dir + "/scenes/" + family.name() + "-" + std::to_string(variant), rendered.image, flags);
    }
  }
  return 0;
}
