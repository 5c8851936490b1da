// SPDX-License-Identifier: LGPL-2.1-or-later
// Writes the generated seeds of the fuzz targets into DIR/TARGET/ (checked in as
// fuzz/corpus/; the other seeds there are hand-written, and the reproducers of findings):
//
//   frames, scenes  frames in the input format of frame_input.hpp, with how many markers
//                   the detector finds in each (printed)
//   image_header    small PNG, JPEG, BMP, PGM/PPM/PBM, PAM, TIFF and WebP files (cv::imencode)
//   calibration     larger files (large-*): many XML attributes and elements, deep XML,
//                   many YAML keys, a long JSON array
//   element         (with GStreamer) a frame of a 3x3 marker in every format of
//                   element_input.hpp, with and without a video meta, and lying ones
//   json            (with GStreamer) a real detection as bytes and as structure text
//
// Run once by hand when an input format changes:
//
//   build-sanitize/fuzz/make_corpus fuzz/corpus
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "../src/core/calibration_file.hpp"  // kMaxCalibrationBytes
#include "frame_input.hpp"
#include "lftag/render.hpp"
#if LFTAG_CORPUS_GST
#include <gst/video/video.h>

#include "element_input.hpp"
#include "lftag-meta.h"
#include "metaconversion.h"
#endif

namespace {

using Bytes = std::vector<std::uint8_t>;

void save(const std::string& path, const Bytes& bytes) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}
void save(const std::string& path, const std::string& text) { save(path, Bytes(text.begin(), text.end())); }

void put16(Bytes& out, unsigned v) {
  out.push_back(std::uint8_t(v));
  out.push_back(std::uint8_t(v >> 8));
}
void put32(Bytes& out, std::uint32_t v) {
  put16(out, v & 0xFFFF);
  put16(out, v >> 16);
}
void put64(Bytes& out, std::uint64_t v) {
  put32(out, std::uint32_t(v));
  put32(out, std::uint32_t(v >> 32));
}
void put_double(Bytes& out, double x) {
  std::uint64_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  put64(out, bits);
}

// `flags` as in frame_input.hpp, window 16, offset 4, no row padding.
void write(const std::string& path, const cv::Mat1b& image, std::uint8_t flags) {
  const int w = image.cols - 1;
  std::vector<std::uint8_t> out{flags, 14, 4, std::uint8_t(w & 255), std::uint8_t(w >> 8), 0};
  for (int y = 0; y < image.rows; ++y) out.insert(out.end(), image.ptr(y), image.ptr(y) + image.cols);
  save(path, out);
  lftag::DetectorParams params;
  params.families = lftag::Family::all();
  std::printf("%s: %dx%d, %zu found\n", path.c_str(), image.cols, image.rows,
              lftag::Detector(params).detect(lftag::ImageView(image)).size());
}

// ---- image_header: every format image_file_size reads, grey and colour.
void image_seeds(const std::string& dir) {
  cv::Mat1b grey = lftag::rasterize_marker(lftag::Family(3), 6789, 1.0);
  cv::Mat3b colour;
  cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
  colour(3, 4) = cv::Vec3b(0, 0, 255);
  struct Seed {
    const char* name;
    const char* ext;
    bool colour;
    std::vector<int> params;
  };
  const Seed seeds[] = {
      {"grey.png", ".png", false, {}},
      {"colour.png", ".png", true, {}},
      {"grey.jpg", ".jpg", false, {cv::IMWRITE_JPEG_QUALITY, 50}},
      {"progressive.jpg", ".jpg", true, {cv::IMWRITE_JPEG_PROGRESSIVE, 1}},
      {"grey.bmp", ".bmp", false, {}},
      {"colour.bmp", ".bmp", true, {}},
      {"grey.pgm", ".pgm", false, {}},
      {"ascii.pgm", ".pgm", false, {cv::IMWRITE_PXM_BINARY, 0}},
      {"colour.ppm", ".ppm", true, {}},
      {"bits.pbm", ".pbm", false, {}},
      {"colour.pam", ".pam", true, {}},
      {"grey.tiff", ".tiff", false, {}},
      {"colour.tiff", ".tiff", true, {cv::IMWRITE_TIFF_COMPRESSION, 1}},
      {"lossy.webp", ".webp", true, {cv::IMWRITE_WEBP_QUALITY, 50}},
      {"lossless.webp", ".webp", false, {cv::IMWRITE_WEBP_QUALITY, 101}},
  };
  for (const Seed& seed : seeds) {
    Bytes out;
    cv::imencode(seed.ext, seed.colour ? cv::Mat(colour) : cv::Mat(grey), out, seed.params);
    save(dir + "/" + seed.name, out);
  }
  // A big-endian TIFF and a 16-bit PNG: the other byte orders and depths.
  Bytes out;
  cv::Mat1w wide;
  grey.convertTo(wide, CV_16U, 257);
  cv::imencode(".png", wide, out);
  save(dir + "/wide.png", out);
  std::printf("%s: %zu image files\n", dir.c_str(), std::size(seeds) + 1);
}

// ---- calibration: larger files, so that mutations reach the sizes of the loader's
// limits (kMaxCalibrationBytes and what it bounds inside).
void calibration_seeds(const std::string& dir) {
  const std::string matrix =
      "  <rows>3</rows><cols>3</cols><dt>d</dt>\n  <data>500. 0. 320. 0. 500. 240. 0. 0. 1.</data>";
  const std::string distortion =
      "<distortion_coefficients type_id=\"opencv-matrix\"><rows>5</rows><cols>1</cols><dt>d</dt>"
      "<data>0. 0. 0. 0. 0.</data></distortion_coefficients>\n";
  // 2,000 attributes on the matrix (about 25 KB), for mutations to multiply.
  std::string attributes;
  for (int i = 0; i < 2000; ++i) attributes += " a" + std::to_string(i) + "=\"" + std::to_string(i) + "\"";
  const std::string head = "<?xml version=\"1.0\"?>\n<opencv_storage>\n";
  save(dir + "/large-attributes.xml", head + "<camera_matrix type_id=\"opencv-matrix\"" + attributes + ">\n" + matrix +
                                          "</camera_matrix>\n" + distortion + "</opencv_storage>\n");
  // 10,000 elements that are not read, before the ones that are (about 200 KB).
  std::string elements;
  for (int i = 0; i < 10000; ++i) {
    const std::string name = "note" + std::to_string(i % 97);
    elements += "<" + name + ">x</" + name + ">\n";
  }
  save(dir + "/large-elements.xml", "<?xml version=\"1.0\"?>\n<opencv_storage>\n" + elements +
                                        "<camera_matrix type_id=\"opencv-matrix\">" + matrix + "</camera_matrix>\n" +
                                        distortion + "</opencv_storage>\n");
  // Nested just under the depth limit.
  std::string open, close;
  for (int i = 0; i < lftag::detail::kMaxCalibrationDepth - 2; ++i) {
    open += "<n" + std::to_string(i) + ">";
    close = "</n" + std::to_string(i) + ">" + close;
  }
  save(dir + "/large-depth.xml", "<?xml version=\"1.0\"?>\n<opencv_storage>\n" + open + close +
                                     "<camera_matrix type_id=\"opencv-matrix\">" + matrix + "</camera_matrix>\n" +
                                     distortion + "</opencv_storage>\n");
  const std::string yaml_camera =
      "camera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [ 500., 0., 320., 0., 500., 240., 0., "
      "0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n  rows: 5\n  cols: 1\n  dt: d\n  data: [ 0., 0., 0., 0., "
      "0. ]\n";
  // 10,000 keys that are not read (about 170 KB).
  std::string keys;
  for (int i = 0; i < 10000; ++i) keys += "key" + std::to_string(i) + ": " + std::to_string(i) + "\n";
  save(dir + "/large-keys.yml", "%YAML:1.0\n---\n" + keys + yaml_camera);
  // A long array of numbers that is not read (about 100 KB).
  std::string numbers;
  for (int i = 0; i < 20000; ++i) numbers += (i ? "," : "") + std::to_string(i % 1000);
  save(dir + "/large-array.json",
       "{\n\"samples\": [" + numbers +
           "],\n\"camera_matrix\": {\"type_id\": \"opencv-matrix\", \"rows\": 3, \"cols\": 3, \"dt\": \"d\", "
           "\"data\": [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]}\n}\n");
  std::printf("%s: 5 larger calibration files\n", dir.c_str());
}

#if LFTAG_CORPUS_GST
namespace element = lftag::fuzz::element;

// The pixels of `info` showing `grey` (scaled to the frame): luma, or R, G and B, from it;
// chroma 128 and alpha opaque, at each component's depth and place.
Bytes frame_pixels(const GstVideoInfo& info, const cv::Mat1b& grey) {
  Bytes out(GST_VIDEO_INFO_SIZE(&info), 0);
  const GstVideoFormatInfo* f = info.finfo;
  for (guint c = 0; c < GST_VIDEO_FORMAT_INFO_N_COMPONENTS(f); ++c) {
    const guint plane = GST_VIDEO_FORMAT_INFO_PLANE(f, c);
    const int w = GST_VIDEO_INFO_COMP_WIDTH(&info, c), h = GST_VIDEO_INFO_COMP_HEIGHT(&info, c);
    const int bits = GST_VIDEO_FORMAT_INFO_DEPTH(f, c), shift = GST_VIDEO_FORMAT_INFO_SHIFT(f, c);
    const bool image = GST_VIDEO_FORMAT_INFO_IS_RGB(f) ? c < 3 : c == GST_VIDEO_COMP_Y;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const unsigned v8 = image ? grey(y * grey.rows / h, x * grey.cols / w) : c == GST_VIDEO_COMP_A ? 255 : 128;
        const unsigned v = (bits > 8 ? v8 << (bits - 8) : v8) << shift;
        const gsize at = info.offset[plane] + gsize(y) * info.stride[plane] + GST_VIDEO_FORMAT_INFO_POFFSET(f, c) +
                         gsize(x) * GST_VIDEO_FORMAT_INFO_PSTRIDE(f, c);
        out[at] = std::uint8_t(v);
        if (bits + shift > 8) out[at + 1] = std::uint8_t(v >> 8);  // little-endian
      }
  }
  return out;
}

Bytes element_stream(int format, int width, int height, std::uint8_t settings, int buffers) {
  Bytes out{std::uint8_t(format)};
  put16(out, width - 1);
  put16(out, height - 1);
  // Default families, 4 ms, window 16.
  out.insert(out.end(), {settings, 0, 15, 14, std::uint8_t(buffers - 1)});
  return out;
}

void element_seeds(const std::string& dir) {
  const cv::Mat1b marker = lftag::rasterize_marker(lftag::Family(3), 6789, 2.0, 3.0);
  const int width = 64, height = 64;
  int count = 0;
  for (int format = 0; format < int(std::size(element::kFormats)); ++format) {
    GstVideoInfo info;
    gst_video_info_set_format(&info, gst_video_format_from_string(element::kFormats[format]), width, height);
    // Overlays and messages differ from seed to seed; every fourth takes compositions.
    const std::uint8_t settings = std::uint8_t((format % 7 + 1) | (format % 4 == 0 ? element::kCompositions : 0) |
                                               ((format % 4) << element::kMessagesShift));
    const bool meta = format % 2;
    Bytes out = element_stream(format, width, height, settings, 1);
    out.push_back(meta ? element::kMeta : 0);
    if (meta) {
      out.insert(out.end(), {0, 0, 0});  // no padding: the caps' own layout, in a meta
      for (guint p = 0; p < GST_VIDEO_INFO_N_PLANES(&info); ++p) {
        out.push_back(element::kTrue);
        put32(out, 0);
      }
      out.push_back(0);
    }
    out.push_back(element::kExact);
    put32(out, 0);
    const Bytes pixels = frame_pixels(info, marker);
    put16(out, unsigned(pixels.size()));
    out.insert(out.end(), pixels.begin(), pixels.end());
    save(dir + "/marker-" + element::kFormats[format], out);
    ++count;
  }
  // Lies and odd streams, on small grey frames (a ramp: no pixels given).
  struct Odd {
    const char* name;
    int format;
    Bytes buffer;  // after the stream header
    std::uint8_t settings = 0;
    int buffers = 1;
  };
  auto lie = [](std::uint8_t kind, std::uint32_t value, int planes) {
    Bytes b{element::kMeta, 0, 0, 0};
    for (int p = 0; p < planes; ++p) {
      b.push_back(p == 0 ? kind : element::kTrue);
      put32(b, p == 0 ? value : 0);
    }
    b.push_back(0);
    b.push_back(element::kExact);
    put32(b, 0);
    put16(b, 0);
    return b;
  };
  std::vector<Odd> odd = {
      {"lie-stride-huge-GRAY8", 0, lie(element::kStrideAny, 1u << 30, 1)},
      {"lie-stride-negative-GRAY8", 0, lie(element::kStrideNegative, 0, 1)},
      {"lie-offset-past-end-NV12", 3, lie(element::kOffsetAny, 1u << 20, 2)},
      {"lie-stride-short-I420", 1, lie(element::kStrideOff, std::uint32_t(-3), 3)},
  };
  {  // a buffer a third too short, without a meta
    Bytes b{0, element::kShort};
    put32(b, 64 * 64 / 3);
    put16(b, 0);
    odd.push_back({"short-buffer-GRAY8", 0, b});
  }
  {  // a padded layout in a meta, split into three memories
    Bytes b{element::kMeta | element::kSplit, 8, 2, 5};
    for (int p = 0; p < 3; ++p) {
      b.push_back(element::kTrue);
      put32(b, 0);
    }
    b.push_back(0);
    b.push_back(element::kExact);
    put32(b, 0);
    b.push_back(2);
    put16(b, 1000);
    put16(b, 5000);
    put16(b, 0);
    odd.push_back({"split-padded-I420", 1, b});
  }
  {  // families refused while playing, new caps, upstream metas, late frames
    Bytes b{element::kFamiliesText | element::kNewCaps | element::kUpstreamMetas};
    b.push_back(17);  // YUY2
    put16(b, 40 - 1);
    put16(b, 30 - 1);
    const std::string text = "3x3,9x9";
    b.push_back(std::uint8_t(text.size()));
    b.insert(b.end(), text.begin(), text.end());
    b.push_back(element::kExact);
    put32(b, 0);
    put16(b, 0);
    b.push_back(element::kFlipOverlay | element::kNoTimestamp);
    b.push_back(element::kExact);
    put32(b, 0);
    put16(b, 0);
    odd.push_back({"families-caps-metas-GRAY8", 0, b, element::kOverlayOutline, 2});
    Bytes late;
    put16(late, 100);
    late.push_back(5);
    late.push_back(0);
    late.push_back(element::kExact);
    put32(late, 0);
    put16(late, 0);
    odd.push_back({"late-frames-GRAY8", 0, late, element::kLateFrames});
  }
  for (const Odd& o : odd) {
    Bytes out = element_stream(o.format, 64, 64, o.settings, o.buffers);
    out.insert(out.end(), o.buffer.begin(), o.buffer.end());
    save(dir + "/" + o.name, out);
    ++count;
  }
  std::printf("%s: %d streams\n", dir.c_str(), count);
}

// ---- json: a detection of a rendered 3x3 marker, and of a 6x6 one (an id from 2^53).
void json_seeds(const std::string& dir) {
  std::vector<lftag::Detection> found;
  for (const auto& [n, id] : {std::pair<int, lftag::TagId>{3, 6789}, {6, lftag::TagId(0xA, 0x9e3779b97f4a7c15ull)}}) {
    lftag::DetectorParams params;
    params.families = {lftag::Family(n)};
    const std::vector<lftag::Detection> d =
        lftag::Detector(params).detect(lftag::ImageView(lftag::rasterize_marker(lftag::Family(n), id, 3.0)));
    if (d.size() != 1) {
      std::fprintf(stderr, "the %dx%d marker was not found\n", n, n);
      std::exit(1);
    }
    found.push_back(d[0]);
  }
  // Binary: as fuzz_json.cpp's binary() and read_detection() read them.
  auto binary = [](const std::vector<lftag::Detection>& detections, std::uint8_t flags, bool odd_values) {
    Bytes out{0};
    put32(out, 640);
    put32(out, 480);
    out.push_back(flags);
    out.push_back(std::uint8_t(detections.size()));
    for (const lftag::Detection& d : detections) {
      out.push_back(std::uint8_t(d.family.n() - lftag::Family::kMinN));
      put64(out, d.id.high());
      put64(out, d.id.low());
      out.push_back(std::uint8_t(d.centroids.size()));
      for (const cv::Point2d& p : d.centroids) put_double(out, p.x), put_double(out, p.y);
      for (const cv::Point2d& p : d.keypoints) put_double(out, p.x), put_double(out, p.y);
      for (const cv::Point2d& p : d.corners) put_double(out, p.x), put_double(out, p.y);
      put_double(out, d.center.x);
      put_double(out, d.center.y);
      for (int i = 0; i < 3; ++i) put_double(out, odd_values && i == 0 ? std::nan("") : d.rvec[i]);
      for (int i = 0; i < 3; ++i) put_double(out, odd_values && i == 0 ? -0.0 : d.tvec[i]);
      put_double(out, odd_values ? std::numeric_limits<double>::infinity() : d.tag_size);
      put_double(out, d.decode_error);
      put_double(out, odd_values ? std::numeric_limits<double>::denorm_min() : d.worst_cell);
      put_double(out, d.edge_score);
      put_double(out, d.reprojection_error);
      out.push_back(std::uint8_t(d.calibrated | d.from_outline << 1));
    }
    for (int i = 0; i < 3; ++i) put64(out, 1000000000ull * (i + 1));  // pts, dts, duration
    for (int i = 0; i < 3; ++i) put32(out, 100u * i);                 // segment start, time, base
    put64(out, 42);                                                   // frame
    return out;
  };
  save(dir + "/binary-3x3", binary({found[0]}, 1 | 2 | 16, false));
  save(dir + "/binary-both-times", binary(found, 1 | 2 | 4 | 8 | 16 | 32, false));
  save(dir + "/binary-nan-inf", binary({found[1]}, 0, true));
  // Text: the structures of an LFTagMeta and of an LFTagTruthMeta, as elements write them.
  auto text = [](const GstStructure* s) {
    gchar* t = gst_structure_to_string(s);
    std::string out = std::string(1, '\1') + t;
    g_free(t);
    return out;
  };
  GstBuffer* buffer = gst_buffer_new();
  lftag::gst::add_detection_meta(buffer, 640, 480, found);
  save(dir + "/text-meta", text(lftag_meta_get_structure(buffer, LFTAG_META_NAME)));
  GstStructure* one = lftag::gst::detection_structure(found[1]);
  save(dir + "/text-detection", text(one));
  gst_structure_free(one);
  lftag::SceneMarker marker;
  marker.id = 6789;
  marker.tvec = {0.1, 0.0, 4.0};
  marker.rvec = lftag::rotation_from_angles(10, 20, 0);
  const lftag::Camera camera = lftag::Camera::pinhole(600, 600, 319.5, 239.5, 640, 480);
  lftag::gst::add_truth_meta(buffer, camera, {lftag::make_truth(camera, marker)});
  save(dir + "/text-truth", text(lftag_meta_get_structure(buffer, LFTAG_TRUTH_META_NAME)));
  gst_buffer_unref(buffer);
  std::printf("%s: 6 records\n", dir.c_str());
}
#endif

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_corpus DIR (writes seeds into DIR/TARGET/)\n");
    return 2;
  }
  const std::string dir = argv[1];
  image_seeds(dir + "/image_header");
  calibration_seeds(dir + "/calibration");
#if LFTAG_CORPUS_GST
  gst_init(&argc, &argv);
  element_seeds(dir + "/element");
  json_seeds(dir + "/json");
#endif
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
