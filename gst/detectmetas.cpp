// SPDX-License-Identifier: LGPL-2.1-or-later
#include "detectmetas.h"

#include <algorithm>
#include <cmath>

#include "metaconversion.h"

namespace lftag::gst {
namespace {

// Removes what an earlier analysis of this buffer attached (a second LFTagMeta would hide
// behind the first); returns the next free region-of-interest id.
gint clear_metas(GstBuffer* buffer) {
  struct Scan {
    GQuark lftag = g_quark_from_static_string("lftag");
    gint next_id = 0;
  } scan;
  gst_buffer_foreach_meta(
      buffer,
      [](GstBuffer*, GstMeta** meta, gpointer data) -> gboolean {
        Scan& scan = *static_cast<Scan*>(data);
        if ((*meta)->info == detection_meta_info()) {
          *meta = nullptr;
        } else if ((*meta)->info->api == GST_VIDEO_REGION_OF_INTEREST_META_API_TYPE) {
          auto* roi = reinterpret_cast<GstVideoRegionOfInterestMeta*>(*meta);
          if (roi->roi_type == scan.lftag)
            *meta = nullptr;
          else
            scan.next_id = std::max(scan.next_id, roi->id + 1);
        }
        return TRUE;
      },
      &scan);
  return scan.next_id;
}

}  // namespace

cv::Rect bounding_box(const Detection& d, int width, int height) {
  double x0 = G_MAXDOUBLE, y0 = G_MAXDOUBLE, x1 = -G_MAXDOUBLE, y1 = -G_MAXDOUBLE;
  for (const cv::Point2d& p : d.corners) {
    x0 = std::min(x0, p.x), x1 = std::max(x1, p.x);
    y0 = std::min(y0, p.y), y1 = std::max(y1, p.y);
  }
  // Pixel i spans [i - 0.5, i + 0.5).
  const int left = std::max(0, int(std::floor(x0 + 0.5)));
  const int top = std::max(0, int(std::floor(y0 + 0.5)));
  const int right = std::min(width - 1, int(std::floor(x1 + 0.5)));
  const int bottom = std::min(height - 1, int(std::floor(y1 + 0.5)));
  return cv::Rect(left, top, std::max(0, right - left + 1), std::max(0, bottom - top + 1));
}

void attach_detections(GstBuffer* buffer, int width, int height, const std::vector<Detection>& detections,
                       const std::vector<TrackInfo>* tracks) {
  const gint first_id = clear_metas(buffer);
  add_detection_meta(buffer, width, height, detections, true, tracks);
  for (std::size_t i = 0; i < detections.size(); ++i) {
    const cv::Rect box = bounding_box(detections[i], width, height);
    GstVideoRegionOfInterestMeta* roi =
        gst_buffer_add_video_region_of_interest_meta(buffer, "lftag", box.x, box.y, box.width, box.height);
    roi->id = first_id + gint(i);
    roi->parent_id = -1;
    GstStructure* param = detection_structure(detections[i], tracks ? &(*tracks)[i] : nullptr);
    gst_structure_set_name(param, "lftag");
    gst_video_region_of_interest_meta_add_param(roi, param);
  }
}

void attach_unanalysed(GstBuffer* buffer, int width, int height) {
  clear_metas(buffer);
  add_detection_meta(buffer, width, height, {}, false);
}

}  // namespace lftag::gst
