// SPDX-License-Identifier: LGPL-2.1-or-later
// Working maps whose memory a thread keeps for its next frame (not part of the API).
//
// An outline reading builds a dozen maps the size of the marker and its blur, and drops
// them a few milliseconds later. Memory that large is given back to the system when it
// is freed and comes back as fresh pages, each a page fault when first written: in an
// lftagdetect pipeline over shadowed markers read from their outlines, 180 faults a
// frame and about 6 % of the element's time. Maps made here take their memory from
// the buffers their thread freed before.
#pragma once

#include <opencv2/core.hpp>

namespace lftag::detail {

// The allocator of recycled maps: a Mat whose `allocator` is this one before it is
// created (or an OpenCV function's output, so prepared) keeps its buffer on its thread
// once released, up to a bound per thread; the next map of no more than that size, at
// most twice smaller, takes it.
cv::MatAllocator* recycling_allocator();

// An uninitialised map of `size` from the recycled buffers.
cv::Mat1f recycled_map(cv::Size size);
// `size` filled with `value`.
cv::Mat1f recycled_map(cv::Size size, float value);
// A copy of `m`.
cv::Mat1f recycled_copy(const cv::Mat1f& m);

}  // namespace lftag::detail
