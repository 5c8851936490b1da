// SPDX-License-Identifier: LGPL-2.1-or-later
// The clips of the video and field experiments as another experiment can use them
// (tracking): the frames every system's camera delivers, in order, with the truth. The
// clips are drawn and rendered by video.cpp and field.cpp themselves, so that every
// experiment on them sees exactly the same frames.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "experiment.hpp"
#include "system.hpp"

namespace bench {

struct RenderedClip {
  std::string set;        // "tuning" or "validation"
  std::string condition;  // "video", or the field experiment's condition
  int index = 0;          // within its condition and set
  lftag::Camera camera;
  double tag_size = 0;  // metres
  double fps = 30;
  std::vector<std::vector<Pose>> poses;        // [frame][marker]: the truth
  std::vector<std::vector<bool>> visible;      // [frame][marker]: all of the tag in the frame, nothing over it
  std::vector<std::vector<std::string>> ids;   // [system][marker]
  std::vector<std::vector<cv::Mat1b>> images;  // [system][frame]
  int frames() const { return int(poses.size()); }
};

class ClipSource {
 public:
  virtual ~ClipSource() = default;
  virtual int size() const = 0;
  // Clip `clip` (0 <= clip < size()) as `systems` see it. May be called from several
  // threads at once; clips are cheapest to read in index order.
  virtual RenderedClip render(int clip, const std::vector<std::unique_ptr<FiducialSystem>>& systems) = 0;
};

// The video experiment's clips (its quick plan with options.quick). The experiment has
// no split of its own: clips over vtest.avi (a street) are the validation set, as in
// the field experiment, the others (the Megamind clips, tree.avi) the tuning set.
std::unique_ptr<ClipSource> video_clips(const Options& options);
// The field experiment's clips of options.conditions (all when empty; H.264 only where
// GStreamer can code it), `clips` per condition and set, of `frames` frames each.
std::unique_ptr<ClipSource> field_clips(const Options& options, int clips, int frames);

}  // namespace bench
