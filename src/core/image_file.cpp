// SPDX-License-Identifier: LGPL-2.1-or-later
// Image sizes from file headers. OpenCV checks a header's size only against its own
// startup limit (2^30 pixels, 3 GB once decoded in colour), so the sizes are read here
// first, and a file is handed to cv::imread only when its size is known: a format not
// read here, or a header that does not give its size, is refused (fail closed).
//
// cv::imread picks the first of its decoders whose signature matches. Each reader below
// answers only for files that OpenCV's decoder of the same format takes, and reads the
// size the way that decoder (or the library under it) does: where the two could differ,
// it gives up (nullopt), which refuses the file.
#include "lftag/image_file.hpp"

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration_file.hpp"

namespace lftag {
namespace {

const char* const kFormats =
    "PNG, JPEG, BMP, PNM (PBM, PGM, PPM), PAM, PFM, TIFF (and BigTIFF), WebP, Sun raster and Radiance HDR";

std::uint32_t be16(const unsigned char* p) { return std::uint32_t(p[0]) << 8 | p[1]; }
std::uint32_t be32(const unsigned char* p) { return be16(p) << 16 | be16(p + 2); }
std::uint32_t le16(const unsigned char* p) { return std::uint32_t(p[1]) << 8 | p[0]; }
std::uint32_t le32(const unsigned char* p) { return le16(p + 2) << 16 | le16(p); }

// White space as the C locale's isspace, which OpenCV's text headers use.
bool space(int c) { return c == ' ' || (c >= '\t' && c <= '\r'); }
bool digit(int c) { return c >= '0' && c <= '9'; }

std::optional<cv::Size> size_of(std::uint64_t w, std::uint64_t h) {
  // Past int, cv::Size cannot hold it: report the largest, which every limit refuses.
  const std::uint64_t top = std::uint64_t(std::numeric_limits<int>::max());
  return cv::Size(int(std::min(w, top)), int(std::min(h, top)));
}

// A file read through a buffer of 64 KB: the header walks step through segments that can
// be a few bytes each, and a system call (or a seek) for every one would make a file of a
// million tiny segments slow. Every walk is bounded by the file's size.
class Reader {
 public:
  explicit Reader(const std::string& path) : f_(path, std::ios::binary) {
    if (!f_) return;
    f_.seekg(0, std::ios::end);
    const std::streamoff end = f_.tellg();
    size_ = end > 0 ? std::uint64_t(end) : 0;
  }
  bool is_open() const { return f_.is_open(); }
  std::uint64_t tell() const { return start_ + pos_; }

  // Moves to `offset`; false past the end of the file.
  bool seek(std::uint64_t offset) {
    if (offset > size_) return false;
    if (offset >= start_ && offset - start_ <= buf_.size()) {
      pos_ = std::size_t(offset - start_);
    } else {
      start_ = offset, pos_ = 0;
      buf_.clear();
    }
    return true;
  }
  bool skip(std::uint64_t n) { return n <= size_ - tell() && seek(tell() + n); }

  // The next byte, or -1 at the end of the file.
  int get() {
    if (pos_ == buf_.size() && !fill()) return -1;
    return buf_[pos_++];
  }
  // `n` bytes into `out`; false when the file ends first.
  bool read(unsigned char* out, std::size_t n) {
    while (n > 0) {
      if (pos_ == buf_.size() && !fill()) return false;
      const std::size_t k = std::min(n, buf_.size() - pos_);
      std::memcpy(out, buf_.data() + pos_, k);
      out += k, n -= k, pos_ += k;
    }
    return true;
  }
  bool read_at(std::uint64_t offset, unsigned char* out, std::size_t n) { return seek(offset) && read(out, n); }

 private:
  bool fill() {
    const std::uint64_t at = tell();
    if (at >= size_) return false;
    buf_.resize(std::size_t(std::min<std::uint64_t>(kChunk, size_ - at)));
    f_.clear();
    f_.seekg(std::streamoff(at));
    f_.read(reinterpret_cast<char*>(buf_.data()), std::streamsize(buf_.size()));
    buf_.resize(std::size_t(f_.gcount()));
    start_ = at, pos_ = 0;
    return !buf_.empty();
  }

  static constexpr std::size_t kChunk = 1 << 16;
  std::ifstream f_;
  std::uint64_t size_ = 0;
  std::uint64_t start_ = 0;  // file offset of buf_[0]
  std::vector<unsigned char> buf_;
  std::size_t pos_ = 0;
};

// What the header says.
struct Header {
  std::string format;             // empty: not a format read here
  bool refused = false;           // a format OpenCV reads and lftag does not
  std::optional<cv::Size> size;   // empty: the header does not give it
  std::optional<cv::Size> block;  // TIFF: the tile or strip OpenCV decodes at once
};

std::optional<cv::Size> png_size(const unsigned char* head, std::size_t n) {
  // Signature, then the IHDR chunk (libpng requires it first): length, "IHDR", width, height.
  if (n < 24 || std::memcmp(head + 12, "IHDR", 4) != 0) return std::nullopt;
  return size_of(be32(head + 16), be32(head + 20));
}

std::optional<cv::Size> jpeg_size(Reader& r) {
  // libjpeg's marker loop up to the frame header: precision, height, width.
  r.seek(2);
  for (;;) {
    // As libjpeg's next_marker: bytes other than 0xFF are skipped (it warns), then any
    // number of 0xFF fill bytes; FF 00 is not a marker. None of them counts as a step:
    // the walk ends with the file.
    int c;
    do {
      do c = r.get();
      while (c >= 0 && c != 0xFF);
      do c = r.get();
      while (c == 0xFF);
    } while (c == 0);
    if (c < 0) return std::nullopt;
    if (c == 0xC0 || c == 0xC1 || c == 0xC2 || c == 0xC9 || c == 0xCA) {  // the frames libjpeg decodes
      unsigned char sof[7];
      if (!r.read(sof, 7)) return std::nullopt;
      return size_of(be16(sof + 5), be16(sof + 3));
    }
    if (c == 0x01 || (c >= 0xD0 && c <= 0xD7)) continue;  // TEM, RSTn: no length
    const bool skipped = c == 0xC4 || c == 0xCC || (c >= 0xDB && c <= 0xDD) || (c >= 0xE0 && c <= 0xEF) || c == 0xFE;
    // Anything else stops libjpeg before a frame: another SOI, EOI, a scan, an unsupported
    // frame (lossless, hierarchical) or an unknown marker.
    if (!skipped) return std::nullopt;
    unsigned char length[2];
    if (!r.read(length, 2)) return std::nullopt;
    // libjpeg skips APPn, COM and DNL of a bogus length under 2 as if empty; the tables
    // (DHT, DAC, DQT, DRI) must add up to their length, so it stops there.
    const std::uint32_t n = be16(length);
    const bool tables = c == 0xC4 || c == 0xCC || c == 0xDB || c == 0xDD;
    if (n < 2 && tables) return std::nullopt;
    if (n > 2 && !r.skip(n - 2)) return std::nullopt;
  }
}

std::optional<cv::Size> bmp_size(const unsigned char* head, std::size_t n) {
  if (n < 26) return std::nullopt;
  const std::uint32_t info = le32(head + 14);
  if (info == 12) return size_of(le16(head + 18), le16(head + 20));  // OS/2 core header
  const auto w = std::int32_t(le32(head + 18)), h = std::int32_t(le32(head + 22));
  // A negative height means top-down rows.
  return size_of(std::uint64_t(std::abs(std::int64_t(w))), std::uint64_t(std::abs(std::int64_t(h))));
}

// A decimal number as OpenCV's PNM reader takes it: white space and '#' comments (to a CR
// or an LF) before it, and the byte after its digits consumed, whatever it is.
std::optional<std::uint64_t> pnm_number(Reader& r) {
  int c = r.get();
  while (!digit(c)) {
    if (c == '#') {
      do c = r.get();
      while (c >= 0 && c != '\n' && c != '\r');
      c = r.get();
    } else if (space(c)) {
      while (space(c)) c = r.get();
    } else {
      return std::nullopt;  // OpenCV stops with an error (or the file ended)
    }
  }
  std::uint64_t v = 0;
  for (; digit(c); c = r.get()) v = std::min<std::uint64_t>(v * 10 + std::uint64_t(c - '0'), 1ull << 40);
  return v;
}

std::optional<cv::Size> pnm_size(Reader& r) {  // "P1".."P6": width, height
  r.seek(2);
  const auto w = pnm_number(r);
  if (!w) return std::nullopt;
  const auto h = pnm_number(r);
  if (!h) return std::nullopt;
  return size_of(*w, *h);
}

std::optional<cv::Size> pam_size(Reader& r) {
  // "P7", a line break, then lines of an identifier (at most 8 bytes) and a value, up to
  // ENDHDR, as OpenCV's PAM reader splits them (a value may start on a later line). It
  // refuses unknown identifiers; a repeated one, which older versions took the last of,
  // is refused here.
  r.seek(2);
  int c = r.get();
  if (c != '\n' && c != '\r') return std::nullopt;
  std::optional<std::uint64_t> w, h;
  for (;;) {
    do c = r.get();
    while (space(c));
    if (c < 0) return std::nullopt;
    if (c == '#') {
      do c = r.get();
      while (c >= 0 && c != '\n' && c != '\r');
      if (c < 0) return std::nullopt;
      continue;
    }
    std::string ident;
    for (; ident.size() < 8 && c >= 0 && !space(c); c = r.get()) ident += char(c);
    if (!space(c)) return std::nullopt;
    std::string value;
    if (c != '\n' && c != '\r') {
      do c = r.get();
      while (space(c));
      for (; value.size() < 255 && c >= 0 && c != '\n' && c != '\r'; c = r.get()) value += char(c);
      if (c != '\n' && c != '\r') return std::nullopt;
      while (!value.empty() && space(static_cast<unsigned char>(value.back()))) value.pop_back();
    }
    if (ident == "ENDHDR") break;
    auto whole = [&]() -> std::optional<std::uint64_t> {
      const bool digits = std::all_of(value.begin(), value.end(), [](char d) { return digit(d); });
      if (value.empty() || value.size() > 12 || !digits) return std::nullopt;
      return std::stoull(value);
    };
    if (ident == "WIDTH" || ident == "HEIGHT") {
      std::optional<std::uint64_t>& field = ident == "WIDTH" ? w : h;
      if (field) return std::nullopt;
      field = whole();
      if (!field) return std::nullopt;
    } else if (ident == "DEPTH") {
      // Channels: OpenCV's tuple types have 1 to 4; its row buffer grows with the depth.
      const auto d = whole();
      if (!d || *d < 1 || *d > 4) return std::nullopt;
    } else if (ident != "MAXVAL" && ident != "TUPLTYPE") {
      return std::nullopt;
    }
  }
  if (!w || !h) return std::nullopt;
  return size_of(*w, *h);
}

std::optional<cv::Size> pfm_size(Reader& r) {
  // "Pf" or "PF", a line feed, then width and height, each ended by one white-space byte
  // (OpenCV's PFM reader has no comments and takes each number up to white space).
  r.seek(2);
  if (r.get() != '\n') return std::nullopt;
  std::uint64_t wh[2];
  for (std::uint64_t& v : wh) {
    v = 0;
    int c = r.get(), digits = 0;
    for (; digit(c) && digits < 20; c = r.get(), ++digits) v = std::min<std::uint64_t>(v * 10 + (c - '0'), 1ull << 40);
    if (digits == 0 || !space(c)) return std::nullopt;
  }
  return size_of(wh[0], wh[1]);
}

std::optional<cv::Size> sun_raster_size(const unsigned char* head, std::size_t n) {
  if (n < 12) return std::nullopt;
  return size_of(be32(head + 4), be32(head + 8));
}

std::optional<cv::Size> hdr_size(Reader& r) {
  // OpenCV's Radiance reader takes its header with fgets into 128 bytes: pieces of at most
  // 127 bytes, each ending at a line feed. The first piece (the "#?" line) is passed over;
  // the header ends at the first piece that is a lone line feed (OpenCV versions differ on
  // what they accept before it, not on where it is), and the next piece is "-Y H +X W".
  r.seek(0);
  std::string piece;
  auto next = [&] {
    piece.clear();
    for (int c; piece.size() < 127 && (c = r.get()) >= 0;) {
      piece += char(c);
      if (c == '\n') break;
    }
    return !piece.empty();
  };
  if (!next()) return std::nullopt;
  do {
    if (!next()) return std::nullopt;
  } while (piece[0] != '\n');
  if (!next()) return std::nullopt;
  // sscanf(piece, "-Y %d +X %d"): a blank in the format matches any white space, and %d
  // skips white space before its digits. Signs are not taken here.
  const std::string line = piece.substr(0, piece.find('\0'));
  std::size_t i = 0;
  auto literal = [&](const char* s) {
    if (line.compare(i, 2, s) != 0) return false;
    i += 2;
    return true;
  };
  auto blanks = [&] {
    while (i < line.size() && space(static_cast<unsigned char>(line[i]))) ++i;
  };
  auto number = [&]() -> std::optional<std::uint64_t> {
    blanks();
    std::uint64_t v = 0;
    std::size_t digits = 0;
    for (; i < line.size() && digit(line[i]); ++i, ++digits)
      v = std::min<std::uint64_t>(v * 10 + std::uint64_t(line[i] - '0'), 1ull << 40);
    if (digits == 0) return std::nullopt;
    return v;
  };
  if (!literal("-Y")) return std::nullopt;
  const auto h = number();
  blanks();
  if (!h || !literal("+X")) return std::nullopt;
  const auto w = number();
  if (!w) return std::nullopt;
  return size_of(*w, *h);
}

// The first image file directory of a TIFF or BigTIFF, as libtiff reads it: width (tag
// 256), height (257), rows per strip (278), tile width and length (322, 323). libtiff
// takes the first of repeated tags, and these as one unsigned number of any integer type.
// OpenCV then decodes a tile (or a strip: the rows per strip, not cut to the height) at
// a time into a buffer of four bytes a pixel.
bool tiff_header(Reader& r, const unsigned char* head, Header& out) {
  const bool little = head[0] == 'I', big = head[2] == 0x2B || head[3] == 0x2B;
  auto u16 = [&](const unsigned char* p) { return little ? le16(p) : be16(p); };
  auto u32 = [&](const unsigned char* p) { return little ? le32(p) : be32(p); };
  auto u64 = [&](const unsigned char* p) {
    const std::uint64_t a = u32(p), b = u32(p + 4);
    return little ? b << 32 | a : a << 32 | b;
  };
  std::uint64_t ifd;
  if (big) {
    unsigned char h[16];
    if (!r.read_at(0, h, 16) || u16(h + 4) != 8 || u16(h + 6) != 0) return false;  // 8-byte offsets
    ifd = u64(h + 8);
  } else {
    ifd = u32(head + 4);
  }
  unsigned char count_bytes[8];
  if (!r.read_at(ifd, count_bytes, big ? 8 : 2)) return false;
  const std::uint64_t count = big ? u64(count_bytes) : u16(count_bytes);
  if (count > 4096) return false;  // libtiff refuses such a directory too
  const std::size_t entry = big ? 20 : 12, field = big ? 8 : 4;
  std::vector<unsigned char> entries(std::size_t(count) * entry);
  if (!r.read(entries.data(), entries.size())) return false;
  std::optional<std::uint64_t> tags[5];  // 256, 257, 278, 322, 323
  const std::uint32_t wanted[5] = {256, 257, 278, 322, 323};
  for (std::size_t e = 0; e < count; ++e) {
    const unsigned char* p = entries.data() + e * entry;
    const std::uint32_t* slot = std::find(std::begin(wanted), std::end(wanted), u16(p));
    if (slot == std::end(wanted) || tags[slot - wanted]) continue;
    const std::uint32_t type = u16(p + 2);
    const std::uint64_t n = big ? u64(p + 4) : u32(p + 4);
    const unsigned char* value = p + 4 + field;
    // BYTE, SHORT, LONG, SBYTE, SSHORT, SLONG, LONG8, SLONG8
    std::size_t bytes;
    switch (type) {
      case 1:
      case 6: bytes = 1; break;
      case 3:
      case 8: bytes = 2; break;
      case 4:
      case 9: bytes = 4; break;
      case 16:
      case 17: bytes = 8; break;
      default: return false;  // libtiff fails the directory
    }
    if (n != 1) return false;
    unsigned char far[8];
    if (bytes > field) {  // an 8-byte number in a classic TIFF lies at an offset
      if (!r.read_at(u32(value), far, 8)) return false;
      value = far;
    }
    std::uint64_t v = bytes == 1 ? value[0] : bytes == 2 ? u16(value) : bytes == 4 ? u32(value) : u64(value);
    const bool is_signed = type == 6 || type == 8 || type == 9 || type == 17;
    if (is_signed && (v >> (bytes * 8 - 1) & 1)) return false;  // negative: libtiff refuses it
    tags[slot - wanted] = v;
  }
  if (!tags[0] || !tags[1]) return false;
  const std::uint64_t width = *tags[0], height = *tags[1];
  std::uint64_t bw = width, bh = height;
  if (tags[3] || tags[4]) {
    // Tiles: their sides are multiples of 16 (TIFF 6.0); libtiff only warns, but a tile of
    // a few pixels would make millions of tile reads.
    bw = tags[3].value_or(0), bh = tags[4].value_or(0);
    if (bw == 0 || bh == 0 || bw % 16 != 0 || bh % 16 != 0) return false;
  } else if (tags[2] && *tags[2] != 0 && *tags[2] != 0xFFFFFFFF) {
    bh = *tags[2];
  }
  out.size = size_of(width, height);
  out.block = size_of(bw, bh);
  return true;
}

std::optional<cv::Size> webp_size(const unsigned char* head, std::size_t n) {
  if (n < 30) return std::nullopt;
  const unsigned char* c = head + 12;  // first chunk: tag, size, data
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

Header read_header(const std::string& path) {
  if (const std::string problem = detail::not_a_regular_file(path); !problem.empty())
    throw std::runtime_error("'" + path + "' " + problem +
                             (detail::names_a_kind(problem) ? ", not an image file" : ""));
  Reader r(path);
  if (!r.is_open()) throw std::runtime_error("cannot open '" + path + "'");
  unsigned char head[132] = {};
  std::size_t n = 0;
  while (n < sizeof head) {
    const int c = r.get();
    if (c < 0) break;
    head[n++] = static_cast<unsigned char>(c);
  }
  auto starts = [&](const char* magic, std::size_t k) { return n >= k && std::memcmp(head, magic, k) == 0; };
  Header h;
  auto named = [&](const char* format, bool refused = false) {
    h.format = format, h.refused = refused;
    return true;
  };
  // OpenCV's DICOM decoder looks at offset 128, after the decoders that look at the first
  // bytes; a file that one of those refuses (libwebp validates more than is checked here)
  // would reach it, so a file with its signature is refused whatever its first bytes.
  if (n >= 132 && std::memcmp(head + 128, "DICM", 4) == 0) {
    named("DICOM", true);
  } else if (starts("\x89PNG\r\n\x1a\n", 8) && named("PNG")) {
    h.size = png_size(head, n);
  } else if (starts("\xFF\xD8\xFF", 3) && named("JPEG")) {
    h.size = jpeg_size(r);
  } else if (starts("BM", 2) && named("BMP")) {
    h.size = bmp_size(head, n);
  } else if (n >= 3 && head[0] == 'P' && head[1] >= '1' && head[1] <= '6' && space(head[2]) && named("PNM")) {
    h.size = pnm_size(r);
  } else if (n >= 3 && head[0] == 'P' && head[1] == '7' && space(head[2]) && named("PAM")) {
    h.size = pam_size(r);
  } else if (n >= 3 && head[0] == 'P' && (head[1] == 'f' || head[1] == 'F') && space(head[2]) && named("PFM")) {
    h.size = pfm_size(r);
  } else if ((starts("II*\0", 4) || starts("MM\0*", 4)) && named("TIFF")) {
    tiff_header(r, head, h);
  } else if ((starts("II+\0", 4) || starts("MM\0+", 4)) && named("BigTIFF")) {
    tiff_header(r, head, h);
  } else if (starts("RIFF", 4) && n >= 12 && std::memcmp(head + 8, "WEBP", 4) == 0 && named("WebP")) {
    h.size = webp_size(head, n);
  } else if (starts("\x59\xA6\x6A\x95", 4) && named("Sun raster")) {
    h.size = sun_raster_size(head, n);
  } else if ((starts("#?RGBE", 6) || starts("#?RADIANCE", 10)) && named("Radiance HDR")) {
    h.size = hdr_size(r);
  } else if (starts("\x76\x2F\x31\x01", 4)) {
    named("OpenEXR", true);
  } else if (starts("\0\0\0\x0CjP  \r\n\x87\n", 12) || starts("\xFF\x4F\xFF\x51", 4)) {
    named("JPEG 2000", true);
  } else if (starts("NITF", 4)) {
    named("NITF", true);
  }
  return h;
}

}  // namespace

std::optional<cv::Size> image_file_size(const std::string& path) { return read_header(path).size; }

cv::Mat read_grey_image(const std::string& path, std::uint64_t max_pixels) {
  const Header h = read_header(path);
  const std::string name = "'" + path + "'";
  if (h.format.empty())
    throw std::runtime_error(name + " is not an image file lftag reads (it reads " + kFormats + ")");
  if (h.refused)
    throw std::runtime_error(name + (h.format[0] == 'O' ? " is an " : " is a ") + h.format +
                             " file, which lftag does not read (it reads " + kFormats + ")");
  if (!h.size)
    throw std::runtime_error(name + " has a " + h.format +
                             " header that does not give its size (cut short or malformed), so it is not decoded");
  auto over = [&](const cv::Size& s) { return std::uint64_t(s.width) * std::uint64_t(s.height) > max_pixels; };
  auto show = [](const cv::Size& s) { return std::to_string(s.width) + "x" + std::to_string(s.height); };
  if (over(*h.size))
    throw std::runtime_error(name + " is " + show(*h.size) + " pixels, more than the limit of " +
                             std::to_string(max_pixels));
  if (h.block && over(*h.block))
    throw std::runtime_error(name + " is decoded in " + h.format + " tiles or strips of " + show(*h.block) +
                             " pixels, more than the limit of " + std::to_string(max_pixels));
  cv::Mat grey;
  try {
    grey = cv::imread(path, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot decode '" + path + "': " + e.err);
  }
  if (grey.empty()) throw std::runtime_error("cannot decode '" + path + "' as an image");
  // OpenCV's colour PFM and Radiance HDR readers give three channels whatever the flag
  // asks: the detector takes one, of 8 bits.
  if (grey.depth() != CV_8U) grey.convertTo(grey, CV_8U);
  if (grey.channels() == 3) cv::cvtColor(grey, grey, cv::COLOR_BGR2GRAY);
  if (grey.channels() == 4) cv::cvtColor(grey, grey, cv::COLOR_BGRA2GRAY);
  if (grey.type() != CV_8UC1) throw std::runtime_error("cannot decode '" + path + "' as an 8-bit grey image");
  return grey;
}

}  // namespace lftag
