// SPDX-License-Identifier: LGPL-2.1-or-later
// Reading images from files that anyone may have made: the size in the file's header is
// checked against a pixel limit before any pixel is decoded or allocated.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

namespace lftag {

// 100 megapixels: the largest camera sensors; a 16-bit grey image of this size is 200 MB.
inline constexpr std::uint64_t kMaxImagePixels = 100'000'000;

// Width and height as the header of a PNG, JPEG, BMP, PNM/PAM, PFM, TIFF/BigTIFF, WebP,
// Sun raster or Radiance HDR file gives them, reading only the header; nullopt when the
// format is another or the header does not give them (cut short or malformed). Throws
// std::runtime_error when the path is not a regular file (a FIFO, a directory, a device:
// nothing is opened then) or the file cannot be opened.
std::optional<cv::Size> image_file_size(const std::string& path);

// cv::imread(path, IMREAD_GRAYSCALE) of a file whose header image_file_size reads and
// declares at most `max_pixels` (for TIFF, its tiles or strips too). Everything else is
// refused with std::runtime_error naming the file and why, before OpenCV sees it: a
// larger image (its size and the limit), a format not read here (OpenEXR, JPEG 2000,
// DICOM and any other; the message lists those that are), a header that does not give
// the size, a path that is not a regular file, and a file OpenCV cannot decode.
cv::Mat read_grey_image(const std::string& path, std::uint64_t max_pixels = kMaxImagePixels);

}  // namespace lftag
