// SPDX-License-Identifier: LGPL-2.1-or-later
// Image sizes from file headers. OpenCV checks a header's size only against its own
// compile-time-or-startup limit (2^30 pixels, 3 GB once decoded in colour), so the sizes
// are read here first. Each reader takes the few bytes the format's specification places
// the size in and gives up (nullopt) on anything unexpected: OpenCV then decides.
#include "lftag/image_file.hpp"

#include <array>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>

namespace lftag {
namespace {

using Bytes = std::vector<unsigned char>;

std::uint32_t be16(const unsigned char* p) { return std::uint32_t(p[0]) << 8 | p[1]; }
std::uint32_t be32(const unsigned char* p) { return be16(p) << 16 | be16(p + 2); }
std::uint32_t le16(const unsigned char* p) { return std::uint32_t(p[1]) << 8 | p[0]; }
std::uint32_t le32(const unsigned char* p) { return le16(p + 2) << 16 | le16(p); }

std::optional<cv::Size> size_of(std::uint64_t w, std::uint64_t h) {
  // Past int, cv::Size cannot hold it: report the largest, which every limit refuses.
  const std::uint64_t top = std::uint64_t(std::numeric_limits<int>::max());
  return cv::Size(int(std::min(w, top)), int(std::min(h, top)));
}

// Reads `n` bytes at `offset`; false when the file is shorter.
bool read_at(std::ifstream& f, std::uint64_t offset, unsigned char* out, std::size_t n) {
  f.clear();
  f.seekg(std::streamoff(offset));
  f.read(reinterpret_cast<char*>(out), std::streamsize(n));
  return std::size_t(f.gcount()) == n;
}

std::optional<cv::Size> png_size(const Bytes& head) {
  // Signature, then the IHDR chunk: length, "IHDR", width, height (big-endian).
  if (head.size() < 24 || std::memcmp(head.data() + 12, "IHDR", 4) != 0) return std::nullopt;
  return size_of(be32(head.data() + 16), be32(head.data() + 20));
}

std::optional<cv::Size> jpeg_size(std::ifstream& f) {
  // Walk the marker segments up to a start-of-frame: precision, height, width.
  std::uint64_t at = 2;
  for (int segments = 0; segments < 4096; ++segments) {
    unsigned char m[4];
    if (!read_at(f, at, m, 2) || m[0] != 0xFF) return std::nullopt;
    const unsigned char marker = m[1];
    if (marker == 0xFF) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // no length
      at += 2;
      continue;
    }
    if (!read_at(f, at + 2, m, 2)) return std::nullopt;
    const std::uint32_t length = be16(m);
    if (length < 2) return std::nullopt;
    const bool frame = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (frame) {
      unsigned char sof[5];
      if (!read_at(f, at + 4, sof, 5)) return std::nullopt;
      return size_of(be16(sof + 3), be16(sof + 1));
    }
    if (marker == 0xD9 || marker == 0xDA) return std::nullopt;  // end, or scan before any frame
    at += 2 + length;
  }
  return std::nullopt;
}

std::optional<cv::Size> bmp_size(const Bytes& head) {
  if (head.size() < 26) return std::nullopt;
  const std::uint32_t info = le32(head.data() + 14);
  if (info == 12) return size_of(le16(head.data() + 18), le16(head.data() + 20));  // OS/2 core header
  const auto w = std::int32_t(le32(head.data() + 18)), h = std::int32_t(le32(head.data() + 22));
  // A negative height means top-down rows.
  return size_of(std::uint64_t(std::abs(std::int64_t(w))), std::uint64_t(std::abs(std::int64_t(h))));
}

std::optional<cv::Size> pnm_size(const Bytes& head) {
  // "P1".."P6" then width and height as decimal tokens, with '#' comments; "P7" (PAM)
  // has WIDTH and HEIGHT lines.
  std::size_t i = 2;
  auto skip_space = [&] {
    while (i < head.size()) {
      if (head[i] == '#')
        while (i < head.size() && head[i] != '\n') ++i;
      else if (std::isspace(head[i]))
        ++i;
      else
        break;
    }
  };
  auto number = [&]() -> std::optional<std::uint64_t> {
    skip_space();
    std::uint64_t v = 0;
    std::size_t digits = 0;
    for (; i < head.size() && std::isdigit(head[i]) && digits < 12; ++i, ++digits) v = v * 10 + (head[i] - '0');
    if (digits == 0 || digits == 12) return std::nullopt;
    return v;
  };
  if (head[1] != '7') {
    const auto w = number(), h = number();
    if (!w || !h) return std::nullopt;
    return size_of(*w, *h);
  }
  std::optional<std::uint64_t> w, h;
  while (i < head.size() && !(w && h)) {
    skip_space();
    auto keyword = [&](const char* k) {
      const std::size_t n = std::strlen(k);
      if (i + n > head.size() || std::memcmp(head.data() + i, k, n) != 0) return false;
      i += n;
      return true;
    };
    if (keyword("WIDTH")) w = number();
    else if (keyword("HEIGHT")) h = number();
    else if (keyword("ENDHDR")) break;
    else
      while (i < head.size() && head[i] != '\n') ++i;
  }
  if (!w || !h) return std::nullopt;
  return size_of(*w, *h);
}

std::optional<cv::Size> tiff_size(std::ifstream& f, const Bytes& head) {
  // The first image file directory: tags 256 (width) and 257 (height), SHORT or LONG.
  const bool little = head[0] == 'I';
  auto u16 = [&](const unsigned char* p) { return little ? le16(p) : be16(p); };
  auto u32 = [&](const unsigned char* p) { return little ? le32(p) : be32(p); };
  const std::uint32_t ifd = u32(head.data() + 4);
  unsigned char count_bytes[2];
  if (!read_at(f, ifd, count_bytes, 2)) return std::nullopt;
  const std::uint32_t count = u16(count_bytes);
  Bytes entries(std::size_t(count) * 12);
  if (!read_at(f, ifd + 2, entries.data(), entries.size())) return std::nullopt;
  std::optional<std::uint64_t> w, h;
  for (std::uint32_t e = 0; e < count; ++e) {
    const unsigned char* p = entries.data() + e * 12;
    const std::uint32_t tag = u16(p), type = u16(p + 2);
    if (tag != 256 && tag != 257) continue;
    std::uint64_t v;
    if (type == 3) v = u16(p + 8);
    else if (type == 4) v = u32(p + 8);
    else return std::nullopt;
    (tag == 256 ? w : h) = v;
  }
  if (!w || !h) return std::nullopt;
  return size_of(*w, *h);
}

std::optional<cv::Size> webp_size(const Bytes& head) {
  if (head.size() < 30) return std::nullopt;
  const unsigned char* c = head.data() + 12;  // first chunk: tag, size, data
  const unsigned char* d = c + 8;
  if (std::memcmp(c, "VP8X", 4) == 0)  // canvas size minus one, 24 bits each
    return size_of((le32(d + 4) & 0xFFFFFF) + 1, (le32(d + 6) >> 8) + 1);
  if (std::memcmp(c, "VP8L", 4) == 0 && d[0] == 0x2F) {  // 14 bits each, minus one
    const std::uint32_t bits = le32(d + 1);
    return size_of((bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1);
  }
  if (std::memcmp(c, "VP8 ", 4) == 0 && d[3] == 0x9D && d[4] == 0x01 && d[5] == 0x2A)  // key frame
    return size_of(le16(d + 6) & 0x3FFF, le16(d + 8) & 0x3FFF);
  return std::nullopt;
}

}  // namespace

std::optional<cv::Size> image_file_size(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot open '" + path + "'");
  Bytes head(512);
  f.read(reinterpret_cast<char*>(head.data()), std::streamsize(head.size()));
  head.resize(std::size_t(f.gcount()));
  auto starts = [&](const char* magic, std::size_t n) { return head.size() >= n && std::memcmp(head.data(), magic, n) == 0; };
  if (starts("\x89PNG\r\n\x1a\n", 8)) return png_size(head);
  if (starts("\xFF\xD8", 2)) return jpeg_size(f);
  if (starts("BM", 2)) return bmp_size(head);
  if (head.size() >= 3 && head[0] == 'P' && head[1] >= '1' && head[1] <= '7' && std::isspace(head[2]))
    return pnm_size(head);
  if ((starts("II*\0", 4) || starts("MM\0*", 4)) && head.size() >= 8) return tiff_size(f, head);
  if (starts("RIFF", 4) && head.size() >= 12 && std::memcmp(head.data() + 8, "WEBP", 4) == 0) return webp_size(head);
  return std::nullopt;
}

cv::Mat read_grey_image(const std::string& path, std::uint64_t max_pixels) {
  const std::optional<cv::Size> size = image_file_size(path);
  if (size && std::uint64_t(size->width) * std::uint64_t(size->height) > max_pixels)
    throw std::runtime_error("'" + path + "' is " + std::to_string(size->width) + "x" + std::to_string(size->height) +
                             " pixels, more than the limit of " + std::to_string(max_pixels));
  cv::Mat grey;
  try {
    grey = cv::imread(path, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot decode '" + path + "': " + e.err);
  }
  if (grey.empty()) throw std::runtime_error("cannot decode '" + path + "' as an image");
  return grey;
}

}  // namespace lftag
