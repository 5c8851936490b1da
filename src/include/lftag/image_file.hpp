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

// Width and height as the header of a PNG, JPEG, BMP, PNM/PAM, TIFF or WebP file gives
// them, reading only the header; nullopt when the format is another or the header is cut
// short. Throws std::runtime_error when the file cannot be opened.
std::optional<cv::Size> image_file_size(const std::string& path);

// cv::imread(path, IMREAD_GRAYSCALE), refusing with std::runtime_error (naming the file,
// its size and the limit) an image whose header declares more than `max_pixels`. Formats
// image_file_size cannot read are left to OpenCV's own limit (2^30 pixels). Throws
// std::runtime_error when the file cannot be opened or decoded.
cv::Mat read_grey_image(const std::string& path, std::uint64_t max_pixels = kMaxImagePixels);

}  // namespace lftag
