// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the image reader of `lftag detect`, lftag::image_file_size and
// lftag::read_grey_image (src/core/image_file.cpp), on arbitrary bytes as a file. The size
// reader must not crash or throw on a file it can open; read_grey_image must refuse with
// std::runtime_error, never another exception, and never return an image of more
// pixels than the limit. An image it decodes from a header image_file_size read has
// that header's size (or its transpose: JPEG and TIFF orientation tags turn it), so that
// the limit checked is the size decoded.
//
// Each input is written to a memory file (memfd) read back by its /proc/self/fd path:
// the reader's API takes a path, and nothing goes to disk.
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>

#include "check.hpp"
#include "lftag/image_file.hpp"

using lftag::fuzz::check;

namespace {

// Small, so that a header's lie costs milliseconds to decode: 512 x 512.
constexpr std::uint64_t kMaxPixels = 1 << 18;

int file = -1;
std::string path;

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  file = memfd_create("fuzz_image_header", 0);
  if (file < 0) {
    std::perror("memfd_create");
    std::abort();
  }
  path = "/proc/self/fd/" + std::to_string(file);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  check(ftruncate(file, 0) == 0 && pwrite(file, data, size, 0) == ssize_t(size), "cannot write the memory file");

  const std::optional<cv::Size> header = lftag::image_file_size(path);
  if (header) check(header->width >= 0 && header->height >= 0, "a negative size");
  cv::Mat grey;
  try {
    grey = lftag::read_grey_image(path, kMaxPixels);
  } catch (const std::runtime_error&) {
    return 0;
  }
  check(!grey.empty() && grey.type() == CV_8UC1, "an empty or not grey image read");
  if (header) {
    if (grey.total() > kMaxPixels)
      std::fprintf(stderr, "a %dx%d image read, the limit is %llu pixels\n", grey.cols, grey.rows,
                   static_cast<unsigned long long>(kMaxPixels));
    check(grey.total() <= kMaxPixels, "an image over the limit read");
    const bool same = grey.cols == header->width && grey.rows == header->height;
    const bool turned = grey.cols == header->height && grey.rows == header->width;
    if (!same && !turned)
      std::fprintf(stderr, "the header says %dx%d, the image decoded is %dx%d\n", header->width, header->height,
                   grey.cols, grey.rows);
    check(same || turned, "the header's size is not the image's");
  }
  return 0;
}
