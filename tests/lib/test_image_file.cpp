// SPDX-License-Identifier: LGPL-2.1-or-later
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "lftag/image_file.hpp"

#include "errors.hpp"

using namespace lftag;

namespace {

const std::string kTmp = testing::TempDir();

std::vector<unsigned char> slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

void write(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

void put_be16(std::vector<unsigned char>& b, std::size_t at, unsigned v) { b[at] = v >> 8, b[at + 1] = v & 0xFF; }
void put_be32(std::vector<unsigned char>& b, std::size_t at, unsigned v) {
  put_be16(b, at, v >> 16), put_be16(b, at + 2, v & 0xFFFF);
}
void put_le16(std::vector<unsigned char>& b, std::size_t at, unsigned v) { b[at] = v & 0xFF, b[at + 1] = v >> 8; }
void put_le32(std::vector<unsigned char>& b, std::size_t at, unsigned v) {
  put_le16(b, at, v & 0xFFFF), put_le16(b, at + 2, v >> 16);
}

// The message read_grey_image refuses `path` with ("" if it reads it).
std::string refusal(const std::string& path) {
  return error_of([&] { read_grey_image(path); });
}

// One TIFF image file directory entry of a single number, held in the entry.
struct TiffEntry {
  unsigned tag, type;
  std::uint64_t value;
};

// A TIFF (BigTIFF when `big`) with one directory of `entries` and then `data`; the value
// of StripOffsets (273) is set to where the data starts.
std::vector<unsigned char> tiff(bool big, bool little, const std::vector<TiffEntry>& entries,
                                const std::vector<unsigned char>& data = {}) {
  std::vector<unsigned char> b;
  auto put = [&](std::uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) b.push_back((v >> (8 * (little ? i : bytes - 1 - i))) & 0xFF);
  };
  const int offset = big ? 8 : 4, count = big ? 8 : 2, entry = big ? 20 : 12;
  b.assign(2, little ? 'I' : 'M');
  put(big ? 43 : 42, 2);
  if (big) put(8, 2), put(0, 2);
  const std::uint64_t ifd = b.size() + offset;
  put(ifd, offset);
  const std::uint64_t start = ifd + count + entries.size() * entry + offset;
  put(entries.size(), count);
  for (const TiffEntry& e : entries) {
    put(e.tag, 2), put(e.type, 2), put(1, offset);
    const int size = e.type == 3 || e.type == 8 ? 2 : e.type == 1 || e.type == 6 ? 1 : e.type >= 16 ? 8 : 4;
    put(e.tag == 273 ? start : e.value, size);
    put(0, offset - size);
  }
  put(0, offset);  // no next directory
  b.insert(b.end(), data.begin(), data.end());
  return b;
}

// An uncompressed 8-bit grey TIFF of w x h pixels, one strip of `rows` rows (0: all).
std::vector<unsigned char> grey_tiff(bool big, bool little, unsigned w, unsigned h, unsigned width_type = 4,
                                     unsigned rows = 0) {
  const unsigned offsets = big ? 16 : 4;
  return tiff(big, little,
              {{256, width_type, w},
               {257, 3, h},
               {258, 3, 8},
               {259, 3, 1},
               {262, 3, 1},
               {273, offsets, 0},
               {277, 3, 1},
               {278, 4, rows ? rows : h},
               {279, 4, std::uint64_t(w) * h}},
              std::vector<unsigned char>(std::size_t(w) * h, 0x80));
}

// A 20,000 x 20,000 image (400 MP) of each format, as a header and a few bytes of data.
std::vector<unsigned char> huge_png() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.png");
  put_be32(b, 16, 20000), put_be32(b, 20, 20000);
  return b;
}

std::vector<unsigned char> huge_jpeg() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.jpg");
  for (std::size_t i = 2; i + 9 < b.size(); ++i)
    if (b[i] == 0xFF && b[i + 1] == 0xC0) {  // baseline start of frame: length, precision, height, width
      put_be16(b, i + 5, 20000), put_be16(b, i + 7, 20000);
      break;
    }
  return b;
}

std::vector<unsigned char> huge_bmp() {
  std::vector<unsigned char> b = slurp(kTmp + "/img.bmp");
  put_le32(b, 18, 20000), put_le32(b, 22, 20000);
  return b;
}

std::vector<unsigned char> huge_pgm() {
  const std::string s = "P5\n# a comment\n20000 20000\n255\n\x80\x80";
  return {s.begin(), s.end()};
}

std::vector<unsigned char> huge_tiff() {
  std::vector<unsigned char> b(8 + 2 + 2 * 12 + 4, 0);
  b[0] = b[1] = 'I', b[2] = '*';
  put_le32(b, 4, 8);
  put_le16(b, 8, 2);
  for (int e = 0; e < 2; ++e) {
    const std::size_t at = 10 + e * 12;
    put_le16(b, at, 256 + e), put_le16(b, at + 2, 4), put_le32(b, at + 4, 1), put_le32(b, at + 8, 20000);
  }
  return b;
}

std::vector<unsigned char> huge_webp() {
  std::vector<unsigned char> b(32, 0);
  std::copy_n("RIFF", 4, b.begin()), std::copy_n("WEBPVP8X", 8, b.begin() + 8);
  put_le32(b, 4, 22), put_le32(b, 16, 10);
  put_le32(b, 24, 19999), put_le32(b, 27, 19999);  // 24-bit sizes minus one (the second overwrites a zero byte)
  return b;
}

}  // namespace

TEST(ImageFile, HeadersGiveTheSizesOpenCVWrites) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  for (const char* ext : {"png", "jpg", "bmp", "pbm", "pgm", "ppm", "pam", "pfm", "tiff", "webp", "sr", "hdr"}) {
    const std::string path = kTmp + "/img." + ext;
    cv::Mat written = image;
    if (std::string(ext) == "ppm") cv::cvtColor(image, written, cv::COLOR_GRAY2BGR);
    if (!cv::imwrite(path, written)) {
      ADD_FAILURE() << "OpenCV cannot write ." << ext;
      continue;
    }
    const std::optional<cv::Size> size = image_file_size(path);
    ASSERT_TRUE(size) << ext;
    EXPECT_EQ(*size, cv::Size(53, 37)) << ext;
    const cv::Mat grey = read_grey_image(path);
    EXPECT_EQ(grey.size(), cv::Size(53, 37)) << ext;
    EXPECT_EQ(grey.type(), CV_8UC1) << ext;  // the detector's input, whatever the file holds
  }
}

// OpenCV decodes a colour PFM (and Radiance HDR) as three channels even when asked for
// grey: read_grey_image gives one, as the detector takes (a fuzzed PFM once came through
// as three and was refused by the detector).
TEST(ImageFile, ColourPfmIsReadAsOneChannel) {
  const std::string path = kTmp + "/colour.pfm";
  ASSERT_TRUE(cv::imwrite(path, cv::Mat3f(4, 6, cv::Vec3f(100, 100, 100))));
  const cv::Mat grey = read_grey_image(path);
  ASSERT_EQ(grey.type(), CV_8UC1);
  EXPECT_EQ(grey.size(), cv::Size(6, 4));
  EXPECT_EQ(cv::countNonZero(grey != 100), 0);
}

TEST(ImageFile, ImagesPastTheLimitAreRefusedBeforeDecoding) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  for (const char* ext : {"png", "jpg", "bmp"}) ASSERT_TRUE(cv::imwrite(kTmp + "/img." + ext, image));
  const std::pair<const char*, std::vector<unsigned char>> cases[] = {{"png", huge_png()},   {"jpg", huge_jpeg()},
                                                                      {"bmp", huge_bmp()},   {"pgm", huge_pgm()},
                                                                      {"tiff", huge_tiff()}, {"webp", huge_webp()}};
  for (const auto& [ext, bytes] : cases) {
    const std::string path = kTmp + "/huge." + ext;
    write(path, bytes);
    const std::optional<cv::Size> size = image_file_size(path);
    ASSERT_TRUE(size) << ext;
    EXPECT_EQ(*size, cv::Size(20000, 20000)) << ext;
    try {
      read_grey_image(path);
      ADD_FAILURE() << ext << " was not refused";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("20000x20000 pixels, more than the limit of 100000000"), std::string::npos)
          << e.what();
    }
  }
  // A smaller limit applies to ordinary images too.
  EXPECT_THROW(read_grey_image(kTmp + "/img.png", 1000), std::runtime_error);
  EXPECT_NO_THROW(read_grey_image(kTmp + "/img.png", 53 * 37));
}

TEST(ImageFile, CutAndUnknownHeadersAreRefused) {
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  ASSERT_TRUE(cv::imwrite(kTmp + "/img.png", image));
  ASSERT_TRUE(cv::imwrite(kTmp + "/img.jpg", image));
  for (const char* ext : {"png", "jpg"}) {
    std::vector<unsigned char> b = slurp(kTmp + "/img." + ext);
    b.resize(ext == std::string("png") ? 20 : 4);
    const std::string path = kTmp + "/cut." + ext;
    write(path, b);
    EXPECT_FALSE(image_file_size(path)) << ext;
    EXPECT_THROW(read_grey_image(path), std::runtime_error) << ext;
    EXPECT_MENTIONS(refusal(path), "header that does not give its size (cut short or malformed)");
  }
  const std::string text = kTmp + "/text.png";
  write(text, {'h', 'e', 'l', 'l', 'o'});
  EXPECT_FALSE(image_file_size(text));
  EXPECT_THROW(read_grey_image(text), std::runtime_error);
  EXPECT_MENTIONS(refusal(text), "is not an image file lftag reads (it reads PNG, JPEG, BMP");
  // A JPEG whose segments loop on themselves (length 2 forever) ends.
  std::vector<unsigned char> loop = {0xFF, 0xD8};
  for (int i = 0; i < 10000; ++i) loop.insert(loop.end(), {0xFF, 0xE0, 0x00, 0x02});
  write(kTmp + "/loop.jpg", loop);
  EXPECT_FALSE(image_file_size(kTmp + "/loop.jpg"));
  EXPECT_THROW(image_file_size(kTmp + "/does-not-exist.png"), std::runtime_error);
  EXPECT_THROW(read_grey_image(kTmp + "/does-not-exist.png"), std::runtime_error);
  // TIFF and BigTIFF directories cut short, or past the end of the file.
  for (const bool big : {false, true}) {
    std::vector<unsigned char> b = grey_tiff(big, true, 16, 16);
    b.resize(big ? 40 : 20);
    write(kTmp + "/cut.tiff", b);
    EXPECT_MENTIONS(refusal(kTmp + "/cut.tiff"), big ? "BigTIFF header that does not give its size" : "TIFF header");
    b.resize(big ? 16 : 8);
    write(kTmp + "/cut.tiff", b);
    EXPECT_MENTIONS(refusal(kTmp + "/cut.tiff"), "does not give its size");
  }
}

TEST(ImageFile, FillBytesBeforeTheFrameAreNotSteps) {
  // SOI, 4,100 fill bytes, then a frame of 32768 x 32768: the header walk once gave up
  // after 4,096 steps, and OpenCV decoded the 4 KB file into 1 GB.
  std::vector<unsigned char> b = {0xFF, 0xD8};
  b.insert(b.end(), 4100, 0xFF);
  b.insert(b.end(), {0xFF, 0xC0, 0x00, 0x0B, 0x08, 0x80, 0x00, 0x80, 0x00, 0x01, 0x01, 0x11, 0x00});
  const std::string path = kTmp + "/fill.jpg";
  write(path, b);
  ASSERT_EQ(image_file_size(path), cv::Size(32768, 32768));
  EXPECT_MENTIONS(refusal(path), "is 32768x32768 pixels, more than the limit of 100000000");
  // libjpeg also skips bytes other than 0xFF before a marker (with a warning), and so does
  // the walk: a real JPEG with such bytes and many fill bytes in it reads as OpenCV reads it.
  const cv::Mat image(37, 53, CV_8U, cv::Scalar(128));
  ASSERT_TRUE(cv::imwrite(kTmp + "/img.jpg", image));
  std::vector<unsigned char> j = slurp(kTmp + "/img.jpg");
  const std::size_t after_app0 = 4 + (std::size_t(j[4]) << 8 | j[5]);
  std::vector<unsigned char> junk = {0x12, 0x00, 0xFF, 0x00, 0x34};
  junk.insert(junk.end(), 10000, 0xFF);
  j.insert(j.begin() + after_app0, junk.begin(), junk.end());
  write(kTmp + "/junk.jpg", j);
  EXPECT_EQ(image_file_size(kTmp + "/junk.jpg"), cv::Size(53, 37));
  EXPECT_EQ(read_grey_image(kTmp + "/junk.jpg").size(), cv::Size(53, 37));
  for (std::size_t i = after_app0; i + 9 < j.size(); ++i)
    if (j[i] == 0xFF && j[i + 1] == 0xC0) {
      put_be16(j, i + 5, 20000), put_be16(j, i + 7, 20000);
      break;
    }
  write(kTmp + "/junk.jpg", j);
  EXPECT_MENTIONS(refusal(kTmp + "/junk.jpg"), "is 20000x20000 pixels, more than the limit");
}

TEST(ImageFile, BigTiffHeadersAreRead) {
  // Small BigTIFF files of both byte orders (and a width of type LONG8) decode as read.
  for (const bool little : {true, false})
    for (const unsigned type : {3u, 4u, 16u}) {
      write(kTmp + "/small.tiff", grey_tiff(true, little, 53, 37, type));
      EXPECT_EQ(image_file_size(kTmp + "/small.tiff"), cv::Size(53, 37)) << little << " " << type;
      EXPECT_EQ(read_grey_image(kTmp + "/small.tiff").size(), cv::Size(53, 37)) << little << " " << type;
    }
  // A BigTIFF header of 12000 x 12000 (a 140 KB file once decoded into 760 MB) is refused.
  const std::vector<TiffEntry> huge = {{256, 3, 12000}, {257, 3, 12000}, {258, 3, 8},     {259, 3, 8},   {262, 3, 1},
                                       {273, 16, 0},    {277, 3, 1},     {278, 3, 12000}, {279, 16, 100}};
  write(kTmp + "/huge.tiff", tiff(true, true, huge, std::vector<unsigned char>(100, 0)));
  EXPECT_EQ(image_file_size(kTmp + "/huge.tiff"), cv::Size(12000, 12000));
  EXPECT_MENTIONS(refusal(kTmp + "/huge.tiff"), "is 12000x12000 pixels, more than the limit of 100000000");
}

TEST(ImageFile, TiffTilesAndStripsAreWithinTheLimitToo) {
  // OpenCV decodes a strip of the rows per strip (not cut to the height) or a tile at a
  // time into a buffer of four bytes a pixel: 10000 x 1 pixels in strips of 20000 rows
  // asked for 800 MB.
  write(kTmp + "/strips.tiff", grey_tiff(false, true, 10000, 1, 4, 20000));
  EXPECT_EQ(image_file_size(kTmp + "/strips.tiff"), cv::Size(10000, 1));
  EXPECT_MENTIONS(refusal(kTmp + "/strips.tiff"),
                  "tiles or strips of 10000x20000 pixels, more than the limit of 100000000");
  EXPECT_EQ(read_grey_image(kTmp + "/strips.tiff", 10000 * 20000).size(), cv::Size(10000, 1));
  const std::vector<TiffEntry> tiled = {{256, 3, 16}, {257, 3, 16}, {258, 3, 8},     {259, 3, 1},
                                        {262, 3, 1},  {277, 3, 1},  {322, 4, 16384}, {323, 4, 16384}};
  write(kTmp + "/tiles.tiff", tiff(false, false, tiled, std::vector<unsigned char>(256, 0)));
  EXPECT_MENTIONS(refusal(kTmp + "/tiles.tiff"), "tiles or strips of 16384x16384 pixels");
  // Tiles of a few pixels (TIFF wants multiples of 16) would make millions of tile reads.
  std::vector<TiffEntry> tiny = tiled;
  tiny[6].value = tiny[7].value = 1;
  write(kTmp + "/tiles.tiff", tiff(false, false, tiny, std::vector<unsigned char>(256, 0)));
  EXPECT_MENTIONS(refusal(kTmp + "/tiles.tiff"), "TIFF header that does not give its size");
}

TEST(ImageFile, SizesAreReadAsOpenCVReadsThem) {
  // libtiff takes the first of repeated tags: a width of 20000, then one of 1.
  std::vector<unsigned char> b = tiff(false, true, {{256, 4, 20000}, {256, 4, 1}, {257, 3, 20000}});
  write(kTmp + "/twice.tiff", b);
  EXPECT_EQ(image_file_size(kTmp + "/twice.tiff"), cv::Size(20000, 20000));
  // OpenCV ends a PNM comment at a CR as well as an LF, and consumes the byte after a
  // number ('#' too): these headers are 20000 x 20000 to it (and smaller if read otherwise).
  const std::string cr = "P5\n#\r20000 20000\n1 1\n255\n";
  write(kTmp + "/cr.pgm", {cr.begin(), cr.end()});
  EXPECT_EQ(image_file_size(kTmp + "/cr.pgm"), cv::Size(20000, 20000));
  const std::string hash = "P5 20000#20000 255\n1 255\n";
  write(kTmp + "/hash.pgm", {hash.begin(), hash.end()});
  EXPECT_EQ(image_file_size(kTmp + "/hash.pgm"), cv::Size(20000, 20000));
  // Small headers of these shapes decode to the sizes read.
  const std::string small_cr = "P5\n#\r53 37\n1 1\n255\n" + std::string(53 * 37, '\x80');
  write(kTmp + "/cr.pgm", {small_cr.begin(), small_cr.end()});
  EXPECT_EQ(read_grey_image(kTmp + "/cr.pgm").size(), cv::Size(53, 37));
  // A PAM value may start on the next line; a repeated field is refused.
  const std::string pam = "P7\nWIDTH\t\n53\nHEIGHT 37\nDEPTH 1\nMAXVAL 255\nENDHDR\n" + std::string(53 * 37, '\x80');
  write(kTmp + "/next.pam", {pam.begin(), pam.end()});
  EXPECT_EQ(image_file_size(kTmp + "/next.pam"), cv::Size(53, 37));
  EXPECT_EQ(read_grey_image(kTmp + "/next.pam").size(), cv::Size(53, 37));
  const std::string twice = "P7\nWIDTH 1\nHEIGHT 1\nWIDTH 20000\nHEIGHT 20000\nDEPTH 1\nMAXVAL 255\nENDHDR\n";
  write(kTmp + "/twice.pam", {twice.begin(), twice.end()});
  EXPECT_FALSE(image_file_size(kTmp + "/twice.pam"));
  // The Radiance header is read in pieces of 127 bytes, as OpenCV's fgets reads it.
  const std::string hdr = "#?RGBE\n" + std::string(127, 'A') + "FORMAT=32-bit_rle_rgbe\n\n-Y 20000  +X20000\n";
  write(kTmp + "/huge.hdr", {hdr.begin(), hdr.end()});
  EXPECT_EQ(image_file_size(kTmp + "/huge.hdr"), cv::Size(20000, 20000));
  // Sun raster and PFM.
  std::vector<unsigned char> ras(32, 0);
  put_be32(ras, 0, 0x59A66A95), put_be32(ras, 4, 20000), put_be32(ras, 8, 20000), put_be32(ras, 12, 8);
  put_be32(ras, 20, 1);
  write(kTmp + "/huge.ras", ras);
  EXPECT_MENTIONS(refusal(kTmp + "/huge.ras"), "is 20000x20000 pixels, more than the limit");
  const std::string pfm = "PF\n20000 20000\n-1\n";
  write(kTmp + "/huge.pfm", {pfm.begin(), pfm.end()});
  EXPECT_MENTIONS(refusal(kTmp + "/huge.pfm"), "is 20000x20000 pixels, more than the limit");
}

TEST(ImageFile, FormatsOpenCVReadsAndLftagDoesNotAreRefusedByName) {
  // JPEG 2000 and OpenEXR: OpenCV decodes them, and their decoders hold 4 bytes or more a
  // pixel a channel; they are refused by name, with the formats that are read.
  const cv::Mat image(64, 64, CV_8U, cv::Scalar(128));
  const std::string jp2 = kTmp + "/img.jp2", exr = kTmp + "/img.exr";
  ASSERT_TRUE(cv::imwrite(jp2, image));
  ASSERT_TRUE(cv::imwrite(exr, cv::Mat(64, 64, CV_32F, cv::Scalar(0.5))));
  for (const auto& [path, format] : {std::pair(jp2, "is a JPEG 2000 file"), std::pair(exr, "is an OpenEXR file")}) {
    EXPECT_FALSE(cv::imread(path, cv::IMREAD_GRAYSCALE).empty()) << path;  // OpenCV would decode it
    EXPECT_FALSE(image_file_size(path)) << path;
    const std::string e = refusal(path);
    EXPECT_MENTIONS(e, format);
    EXPECT_MENTIONS(e, "which lftag does not read (it reads PNG, JPEG, BMP, PNM");
  }
  // A file OpenCV may take for DICOM (its signature at offset 128) is refused whatever it
  // starts with: OpenCV tries that decoder when the first bytes' one refuses the file.
  std::vector<unsigned char> dicom = huge_webp();
  dicom.resize(200, 0);
  std::copy_n("DICM", 4, dicom.begin() + 128);
  write(kTmp + "/dicom.webp", dicom);
  EXPECT_MENTIONS(refusal(kTmp + "/dicom.webp"), "is a DICOM file");
}

TEST(ImageFile, OnlyRegularFilesAreOpened) {
  // A FIFO would block the open until a writer came; a device is not opened at all.
  const std::string dir = kTmp + "/image-kinds";
  ::mkdir(dir.c_str(), 0700);
  const std::string fifo = dir + "/fifo.png", loop = dir + "/loop.png";
  std::remove(fifo.c_str()), std::remove(loop.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  ASSERT_EQ(::symlink(loop.c_str(), loop.c_str()), 0);
  EXPECT_MENTIONS(error_within([&] { read_grey_image(fifo); }), "is a FIFO");
  EXPECT_MENTIONS(error_within([&] { image_file_size(fifo); }), "is a FIFO");
  EXPECT_MENTIONS(error_within([&] { read_grey_image(dir); }), "is a directory");
  EXPECT_MENTIONS(error_within([&] { read_grey_image("/dev/zero"); }), "'/dev/zero' is a character device");
  EXPECT_MENTIONS(error_within([&] { read_grey_image(loop); }), "is a symbolic link loop");
  EXPECT_MENTIONS(error_within([&] { read_grey_image(dir + "/none.png"); }), "does not exist");
  std::remove(fifo.c_str()), std::remove(loop.c_str()), ::rmdir(dir.c_str());
}
