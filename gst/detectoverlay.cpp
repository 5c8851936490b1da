// SPDX-License-Identifier: LGPL-2.1-or-later
#include "detectoverlay.h"

#include <algorithm>

#include <opencv2/imgproc.hpp>

#include "detectmetas.h"

// The layer is handed to GStreamer as its native ARGB, which is BGRA in memory (OpenCV's
// channel order) only on little-endian machines.
#if G_BYTE_ORDER != G_LITTLE_ENDIAN
#error "lftagdetect's overlay assumes a little-endian machine"
#endif

namespace lftag::gst {
namespace {

// Where the layer was drawn on: near the marker (`near`) if the drawing stays inside it,
// else anywhere (a long label, long axes).
cv::Rect drawn_extent(const cv::Mat4b& layer, cv::Mat1b& alpha, const cv::Rect& near) {
  const cv::Rect all(0, 0, layer.cols, layer.rows);
  const cv::Rect window = near & all;
  cv::extractChannel(layer(window), alpha, 3);
  const cv::Rect box = cv::boundingRect(alpha) + window.tl();
  const bool inside = !box.empty() && (box.x > window.x || window.x == 0) && (box.y > window.y || window.y == 0) &&
                      (box.br().x < window.br().x || window.br().x == all.br().x) &&
                      (box.br().y < window.br().y || window.br().y == all.br().y);
  if (inside || window == all) return box;
  cv::extractChannel(layer, alpha, 3);
  return cv::boundingRect(alpha);
}

// A copy of part of the layer as an overlay rectangle at its place in the frame.
GstVideoOverlayRectangle* overlay_rectangle(const cv::Mat4b& layer, const cv::Rect& box) {
  GstBuffer* pixels = gst_buffer_new_allocate(nullptr, gsize(box.area()) * 4, nullptr);
  gst_buffer_add_video_meta(pixels, GST_VIDEO_FRAME_FLAG_NONE, GST_VIDEO_OVERLAY_COMPOSITION_FORMAT_RGB, box.width,
                            box.height);
  GstMapInfo map;
  gst_buffer_map(pixels, &map, GST_MAP_WRITE);
  layer(box).copyTo(cv::Mat4b(box.height, box.width, reinterpret_cast<cv::Vec4b*>(map.data)));
  gst_buffer_unmap(pixels, &map);
  // Anti-aliased strokes on a transparent layer come out with premultiplied alpha.
  GstVideoOverlayRectangle* rectangle = gst_video_overlay_rectangle_new_raw(
      pixels, box.x, box.y, box.width, box.height, GST_VIDEO_OVERLAY_FORMAT_FLAG_PREMULTIPLIED_ALPHA);
  gst_buffer_unref(pixels);
  return rectangle;
}

}  // namespace

GstVideoOverlayComposition* DetectOverlay::compose(int width, int height, const DrawOptions& options,
                                                   const Camera& camera, const std::vector<Detection>& detections) {
  if (layer_.rows != height || layer_.cols != width) layer_ = cv::Mat4b(height, width, cv::Vec4b::all(0));
  GstVideoOverlayComposition* composition = gst_video_overlay_composition_new(nullptr);
  for (const Detection& d : detections) {
    cv::Mat layer = layer_;
    draw_detections(layer, {d}, camera, options);
    const cv::Rect corners = bounding_box(d, width, height);
    const int margin = std::max({corners.width, corners.height, std::min(width, height) / 8});
    const cv::Rect near(corners.x - margin, corners.y - margin, corners.width + 2 * margin,
                        corners.height + 2 * margin);
    const cv::Rect box = drawn_extent(layer_, alpha_, near);
    if (box.empty()) continue;
    GstVideoOverlayRectangle* rectangle = overlay_rectangle(layer_, box);
    gst_video_overlay_composition_add_rectangle(composition, rectangle);
    gst_video_overlay_rectangle_unref(rectangle);
    layer_(box).setTo(cv::Scalar::all(0));
  }
  return composition;
}

void DetectOverlay::reset() {
  layer_.release();
  alpha_.release();
}

bool downstream_takes_compositions(GstPad* srcpad, GstCaps* caps) {
  if (!caps) return false;
  GstQuery* query = gst_query_new_allocation(caps, FALSE);
  const bool takes = gst_pad_peer_query(srcpad, query) &&
                     gst_query_find_allocation_meta(query, GST_VIDEO_OVERLAY_COMPOSITION_META_API_TYPE, nullptr);
  gst_query_unref(query);
  return takes;
}

void attach_composition(GstBuffer* buffer, GstVideoOverlayComposition* composition) {
  GstVideoOverlayCompositionMeta* existing = gst_buffer_get_video_overlay_composition_meta(buffer);
  if (!existing) {
    gst_buffer_add_video_overlay_composition_meta(buffer, composition);
    return;
  }
  GstVideoOverlayComposition* both = gst_video_overlay_composition_copy(existing->overlay);
  for (guint i = 0; i < gst_video_overlay_composition_n_rectangles(composition); ++i)
    gst_video_overlay_composition_add_rectangle(both, gst_video_overlay_composition_get_rectangle(composition, i));
  gst_buffer_remove_meta(buffer, &existing->meta);
  gst_buffer_add_video_overlay_composition_meta(buffer, both);
  gst_video_overlay_composition_unref(both);
}

}  // namespace lftag::gst
