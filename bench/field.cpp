// SPDX-License-Identifier: LGPL-2.1-or-later
// The field experiment (issue 25): markers under conditions no other experiment has, one
// condition per clip, over the kind of scene `video` composites (printed sheets moving
// over opencv-doc's videos and photos, camera shake, mild defocus, noise, JPEG). Each
// condition changes one thing of the plain clips: cast shadows, motion blur with a
// rolling shutter, a pillbox defocus, strong barrel distortion, low light, a Bayer
// sensor, sheets bent round a cylinder, 1080p frames of small markers, crowded frames
// with markers cut by the frame edge, occluders, H.264. The clips are split into a
// tuning set and a validation set with other backgrounds, seeds and marker ids, and
// every row names its set, so that a change tuned on one can be checked on the other.
// Every system sees the same clips, poses, frames and noise; only the marker design
// differs. Frame times are measured afterwards, on one thread, on the first clips of
// every condition and set.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "clip_source.hpp"
#include "csv.hpp"
#include "experiment.hpp"
#include "h264.hpp"
#include "sources.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

constexpr double kTagSize = 0.1;                    // metres
constexpr double kSheet = 1 + 2 * kMarginFraction;  // printed sheet edge over tag size
constexpr int kIdsPerSet = 30;                      // each set its own ids
constexpr int kJpegQuality = 75;
constexpr double kMaxShake = 2;  // pixels the camera shake moves the image, per frame
constexpr double kFps = 30;

enum Condition : int {
  kPlain,
  kShadow,
  kMotion,
  kPillbox,
  kBarrel,
  kLowLight,
  kBayer,
  kBent,
  kSmall,
  kCrowded,
  kOcclusion,
  kH264,
  kH264Small,
  kConditions
};
struct ConditionInfo {
  const char* name;
  int drawn_as;  // the condition whose clips this one repeats with another codec, else itself
  cv::Size size;
};
const ConditionInfo kInfo[kConditions] = {
    {"plain", kPlain, {1280, 720}},       {"shadow", kShadow, {1280, 720}},       {"motion", kMotion, {1280, 720}},
    {"pillbox", kPillbox, {1280, 720}},   {"barrel", kBarrel, {1280, 720}},       {"low-light", kLowLight, {1280, 720}},
    {"bayer", kBayer, {1280, 720}},       {"bent", kBent, {1280, 720}},           {"small-1080p", kSmall, {1920, 1080}},
    {"crowded", kCrowded, {1280, 720}},   {"occlusion", kOcclusion, {1280, 720}}, {"h264", kPlain, {1280, 720}},
    {"h264-1080p", kSmall, {1920, 1080}},
};
const char* const kSets[2] = {"tuning", "validation"};
enum Subset : int { kVisible, kCut, kOccluded, kSubsets };
const char* const kSubsetNames[kSubsets] = {"visible", "cut", "occluded"};

struct Plan {
  int clips, frames;        // per condition and set
  int timed_clips, passes;  // the clips timed per condition and set, and the passes over them
};
constexpr Plan kFull{5, 10, 2, 1}, kQuick{1, 2, 1, 1};
// The acceptance test's: 40 visible markers or more per condition and set (80 at 1080p),
// enough that one marker more or less moves a rate by 2.5 points at most; not timed.
constexpr Plan kAcceptance{2, 5, 0, 1};

// How many sheets a clip holds, how large and how they move.
struct Layout {
  int min_markers, max_markers, min_cut, max_cut;
  double min_edge, max_edge, max_tilt, travel;  // projected tag edge px, degrees, px over the clip
  double gap;                                   // px between the sheets' image boxes
};
Layout layout_of(int drawn_as) {
  switch (drawn_as) {
    case kSmall: return {8, 8, 0, 0, 16, 40, 45, 90, 6};
    case kCrowded: return {6, 10, 1, 3, 30, 110, 60, 40, 4};
    case kBent: return {4, 4, 0, 0, 40, 200, 50, 60, 8};
    case kMotion: return {4, 4, 0, 0, 30, 200, 60, 60, 40};  // room for the blur and the skew
    default: return {4, 4, 0, 0, 30, 200, 60, 60, 4};
  }
}

// What a sheet carries beyond its pose: its bend, its occluder and its shadow. Image-space
// shapes are given relative to the marker's image centre and projected edge, so that
// they follow the sheet through the clip.
struct Extra {
  double bend = 0;            // cylinder radius, metres (0 flat; > 0 centre nearer)
  bool bend_about_x = false;  // the cylinder's axis along the marker's x (else its y)
  bool cut = false;           // placed across the frame edge
  bool occluded = false;
  double occluder_dir = 0, occluder_offset = 0, occluder_tip = 0, occluder_reach = 0, occluder_width = 0;
  double occluder_albedo = 0;
  bool shadowed = false, shadow_band = false;
  double shadow_dir = 0, shadow_offset = 0, shadow_width = 0, shadow_radius = 0;
};

// The motion of a sheet during one frame's exposure: an image velocity that moves it by
// `length` pixels within the exposure, towards `direction` degrees (0 = +x).
struct Motion {
  double length = 0, direction = 0;
};

struct Clip {
  int set = 0, condition = 0, index = 0;  // index within its condition and set
  int drawn_as = 0;                       // the condition whose draws it shares
  int source = 0, start = 0;              // background (a video and its first frame, or a photo)
  lftag::Camera camera;
  int frames = 0;
  double exposure = 1, gradient = 0, light_angle = 0, noise = 0, defocus = 0;
  double shadow_level = kNaN, penumbra = kNaN;                         // shadow
  double exposure_ms = kNaN, readout_ms = kNaN;                        // motion
  double pillbox = kNaN;                                               // pillbox radius, px
  double black = kNaN, white = kNaN, gamma = kNaN, dark_noise = kNaN;  // low light
  cv::Vec3d illuminant{1, 1, 1}, wb_error{1, 1, 1};                    // Bayer, R G B
  bool edge_aware = false;
  int kbps = 0;                             // H.264 at this bitrate; 0: JPEG
  std::vector<cv::Matx33d> shake;           // per frame
  std::vector<std::vector<Pose>> poses;     // per frame and sheet, shake included
  std::vector<Extra> extras;                // per sheet
  std::vector<std::vector<Motion>> motion;  // per frame and sheet (motion only)
};

// The pose of a placement, facing the camera along the line of sight through its image
// point (through the lens distortion, if any), at the distance that gives its edge.
Pose pose_of(const lftag::Camera& camera, const Placement& p) {
  return facing_pose(camera, p.center, p.edge, p.tilt, p.tilt_axis, p.roll, kTagSize);
}

// A small turn of the camera about its centre between frames (none within one).
cv::Matx33d random_shake(const lftag::Camera& camera, std::mt19937_64& rng) {
  const double shift = kMaxShake * std::sqrt(uniform(rng, 0, 1)), direction = uniform(rng, 0, 2 * CV_PI);
  const double dx = shift * std::cos(direction), dy = shift * std::sin(direction);
  return rotation_matrix({-std::atan(dy / camera.fy), std::atan(dx / camera.fx), uniform(rng, -0.5, 0.5) / camera.fx});
}

// A point of the sheet (metres from the marker centre, in its plane) in the marker frame:
// on its cylinder when bent (the renderer's SceneTarget::bend_radius).
cv::Point3d on_sheet(const Extra& e, double x, double y) {
  if (e.bend == 0) return {x, y, 0};
  const double r = e.bend;
  if (e.bend_about_x) return {x, r * std::sin(y / r), r * (1 - std::cos(y / r))};
  return {r * std::sin(x / r), y, r * (1 - std::cos(x / r))};
}

// The image of the outline of a square of edge `size` centred on the marker, sampled so
// that distortion and bending show.
std::vector<cv::Point2d> outline(const lftag::Camera& camera, const Pose& pose, const Extra& e, double size) {
  const double h = size / 2;
  std::vector<cv::Point3d> points;
  const int steps = 8;
  for (int i = 0; i < steps; ++i) {
    const double f = -h + 2 * h * i / steps;
    for (const cv::Point2d p : {cv::Point2d(f, -h), cv::Point2d(h, f), cv::Point2d(-f, h), cv::Point2d(-h, -f)})
      points.push_back(on_sheet(e, p.x, p.y));
  }
  return camera.project(points, pose.rvec, pose.tvec);
}

cv::Rect2d bounds(const std::vector<cv::Point2d>& points) {
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (const cv::Point2d& c : points)
    x0 = std::min(x0, c.x), y0 = std::min(y0, c.y), x1 = std::max(x1, c.x), y1 = std::max(y1, c.y);
  return {x0, y0, x1 - x0, y1 - y0};
}

bool inside(const cv::Rect2d& box, const lftag::Camera& camera, double margin) {
  return box.x >= margin && box.y >= margin && box.x + box.width <= camera.width - 1 - margin &&
         box.y + box.height <= camera.height - 1 - margin;
}

cv::Point2d center_of(const lftag::Camera& camera, const Pose& pose) {
  return camera.project({{0, 0, 0}}, pose.rvec, pose.tvec)[0];
}

// The tag's corners leave the frame (its centre stays in).
bool is_cut(const lftag::Camera& camera, const Pose& pose, const Extra& e) {
  return !inside(bounds(outline(camera, pose, e, kTagSize)), camera, 0);
}

// Occluder: a bar (a finger, a pen, a cable) reaching in over the marker along its
// direction from `reach` edges out (beyond the tag's corners) to its tip, `tip` edges
// from the marker centre, `offset` edges aside and `width` edges wide. Signed distance
// in pixels (negative inside).
double occluder_distance(const Extra& e, cv::Point2d center, double edge, cv::Point2d p) {
  const double a = e.occluder_dir * CV_PI / 180;
  const cv::Point2d u(std::cos(a), std::sin(a)), n(-u.y, u.x), d = p - center;
  const double along = d.dot(u);
  return std::max({e.occluder_tip * edge - along, along - e.occluder_reach * edge,
                   std::abs(d.dot(n) - e.occluder_offset * edge) - e.occluder_width * edge / 2});
}

// The fraction of the tag the occluder hides (sampled on 24 x 24 points of the tag).
double occluded_fraction(const lftag::Camera& camera, const Pose& pose, const Extra& e) {
  std::vector<cv::Point3d> points;
  const int n = 24;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      points.emplace_back(((i + 0.5) / n - 0.5) * kTagSize, ((j + 0.5) / n - 0.5) * kTagSize, 0);
  const cv::Point2d c = center_of(camera, pose);
  const double edge = edge_px(camera, pose, kTagSize);
  double covered = 0;
  for (const cv::Point2d& p : camera.project(points, pose.rvec, pose.tvec))
    covered += std::clamp(0.5 - occluder_distance(e, c, edge, p), 0.0, 1.0);
  return covered / (n * n);
}

// Shadow of something between the light and the sheet: a band (a pole's shadow) across
// the marker, or the inside of an edge (a half-plane) within a disc about the marker.
// Signed distance in pixels (negative in the shadow).
double shadow_distance(const Extra& e, cv::Point2d center, double edge, cv::Point2d p) {
  const double a = e.shadow_dir * CV_PI / 180;
  const cv::Point2d n(std::cos(a), std::sin(a)), d = p - center;
  if (e.shadow_band) return std::abs(d.dot(n) - e.shadow_offset * edge) - e.shadow_width * edge / 2;
  return std::max(e.shadow_offset * edge - d.dot(n), cv::norm(d) - e.shadow_radius * edge);
}

struct Sources {
  std::vector<Source> all;
  std::vector<int> videos[2], photos[2];  // by set
};

// The split of the backgrounds: vtest.avi (a street) and every other photo (by name) for
// validation; the Megamind clips, tree.avi and the remaining photos for tuning.
Sources split_sources(const std::filesystem::path& dir) {
  Sources s;
  s.all = list_sources(dir);
  int photo = 0;
  for (int i = 0; i < int(s.all.size()); ++i) {
    if (s.all[i].video)
      s.videos[s.all[i].path.filename() == "vtest.avi" ? 1 : 0].push_back(i);
    else
      s.photos[photo++ % 2].push_back(i);
  }
  // Another opencv-doc without vtest.avi: the last video validates.
  if (s.videos[1].empty() && s.videos[0].size() > 1) s.videos[1].push_back(s.videos[0].back()), s.videos[0].pop_back();
  for (int set = 0; set < 2; ++set)
    if (s.photos[set].empty() && s.videos[set].empty())
      throw std::runtime_error("field: too few backgrounds in " + dir.string());
  return s;
}

lftag::Camera camera_of(int drawn_as, cv::Size size, std::mt19937_64& rng) {
  lftag::Camera camera = lftag::Camera::default_for(size.width, size.height);
  if (drawn_as == kBarrel) {
    // A wide lens (85 degrees across) with strong barrel distortion: the frame corners
    // are pulled in by a third. Monotonic over the frame for these ranges.
    const double f = 700.0 * size.width / 1280;
    camera = lftag::Camera::pinhole(f, f, (size.width - 1) / 2.0, (size.height - 1) / 2.0, size.width, size.height);
    camera.distortion = {uniform(rng, -0.34, -0.26), uniform(rng, 0.08, 0.12), 0, 0, 0};
    camera.calibrated = true;
  }
  return camera;
}

// Draws a clip: everything but the marker design. Clips of a codec twin (h264) are drawn
// exactly as their JPEG originals (the same seed path), then given the other codec.
Clip plan_clip(const Sources& sources, int set, int condition, int index, int frames, std::uint64_t seed) {
  Clip c;
  c.set = set, c.condition = condition, c.index = index, c.frames = frames;
  c.drawn_as = kInfo[condition].drawn_as;
  const cv::Size size = kInfo[condition].size;
  std::mt19937_64 rng = seeded(seed, {0xf1e1d, std::uint64_t(set), std::uint64_t(c.drawn_as), std::uint64_t(index)});
  c.camera = camera_of(c.drawn_as, size, rng);

  // The background: videos and photos in turn.
  const std::vector<int>& videos = sources.videos[set];
  const std::vector<int>& photos = sources.photos[set];
  const bool video = !videos.empty() && (index % 2 == 0 || photos.empty());
  const std::vector<int>& pool = video ? videos : photos;
  c.source = pool[std::size_t(rng() % pool.size())];
  c.start = video ? std::uniform_int_distribution<int>(0, std::max(0, sources.all[c.source].frames - frames))(rng) : 0;

  // The plain clip's conditions, which every condition shares.
  c.exposure = uniform(rng, 0.6, 1.0);
  c.gradient = uniform(rng, 0, 0.4);
  c.light_angle = uniform(rng, 0, 360);
  c.noise = uniform(rng, 1.5, 3);
  c.defocus = uniform(rng, 0, 0.6);
  for (int f = 0; f < frames; ++f) c.shake.push_back(random_shake(c.camera, rng));

  switch (c.drawn_as) {
    case kShadow:
      c.shadow_level = uniform(rng, 0.35, 0.6);
      c.penumbra = uniform(rng, 1, 4);
      break;
    case kMotion:
      c.exposure_ms = uniform(rng, 4, 8);
      c.readout_ms = uniform(rng, 15, 30);
      break;
    case kPillbox:
      c.pillbox = uniform(rng, 1, 3);
      c.defocus = 0;  // the pillbox alone
      break;
    case kLowLight:
      c.black = uniform(rng, 8, 12);
      c.white = uniform(rng, 60, 80);
      c.gamma = uniform(rng, 1.8, 2.4);
      c.dark_noise = uniform(rng, 5, 7);
      break;
    case kBayer: {
      // Grey light in even clips, tinted (warm to cool, a little green or magenta) in odd
      // ones; white balance within 10 % of right in red and blue.
      const double warm = uniform(rng, -1, 1), green = uniform(rng, -0.08, 0.08);
      if (index % 2 == 1) c.illuminant = {1 + 0.45 * warm, 1 + green, 1 - 0.45 * warm};
      c.wb_error = {uniform(rng, 0.9, 1.1), 1, uniform(rng, 0.9, 1.1)};
      c.edge_aware = index % 4 >= 2;
      break;
    }
    default: break;
  }
  if (condition == kH264) c.kbps = 1500;
  if (condition == kH264Small) c.kbps = 3000;

  const Layout layout = layout_of(c.drawn_as);
  const lftag::Camera& camera = c.camera;
  for (int attempt = 0; attempt < 1000; ++attempt) {
    const int count = std::uniform_int_distribution<int>(layout.min_markers, layout.max_markers)(rng);
    const int cuts = std::uniform_int_distribution<int>(layout.min_cut, layout.max_cut)(rng);
    std::vector<double> edges(count);
    for (double& e : edges) e = std::exp(uniform(rng, std::log(layout.min_edge), std::log(layout.max_edge)));
    std::sort(edges.rbegin(), edges.rend());
    std::vector<Extra> extras(count);
    // The cut sheets: any of them, as their sizes come.
    for (int k = 0; k < cuts; ++k) extras[std::size_t(rng() % count)].cut = true;
    for (Extra& e : extras) {
      if (c.drawn_as == kBent) {
        e.bend = uniform(rng, 0.15, 0.4) * (uniform(rng, 0, 1) < 0.7 ? 1 : -1);
        e.bend_about_x = rng() % 2 == 1;
      }
      if (c.drawn_as == kShadow) {
        e.shadowed = true;
        e.shadow_band = rng() % 2 == 1;
        e.shadow_dir = uniform(rng, 0, 360);
        e.shadow_offset = uniform(rng, -0.3, 0.3);
        e.shadow_width = uniform(rng, 0.15, 0.5);
        e.shadow_radius = uniform(rng, 1.3, 2.5);
      }
    }
    if (c.drawn_as == kOcclusion)  // two of the four sheets
      for (int k = 0, done = 0; done < 2 && k < 100; ++k) {
        Extra& e = extras[std::size_t(rng() % count)];
        if (e.occluded) continue;
        e.occluded = true, ++done;
        e.occluder_dir = uniform(rng, 0, 360);
        e.occluder_offset = uniform(rng, -0.3, 0.3);
        e.occluder_width = uniform(rng, 0.2, 0.4);
        e.occluder_reach = uniform(rng, 1.2, 2.1);
        e.occluder_albedo = uniform(rng, 0.15, 0.7);
        e.occluder_tip = uniform(rng, 0.1, 0.4);  // the wanted fraction, made a tip below
      }

    c.poses.assign(frames, {});
    std::vector<std::vector<cv::Rect2d>> boxes(frames);
    int placed = 0;
    for (int m = 0; m < count; ++m) {
      const Extra& e = extras[m];
      for (int k = 0; k < 300 && placed == m; ++k) {
        Placement a{{uniform(rng, 0, camera.width - 1), uniform(rng, 0, camera.height - 1)},
                    edges[m],
                    uniform(rng, 0, layout.max_tilt),
                    uniform(rng, 0, 360),
                    uniform(rng, 0, 360)};
        Placement b = a;
        if (e.cut) {
          // Across one of the frame's edges, the centre within a third of an edge inside.
          const int side = int(rng() % 4);
          const double in = uniform(rng, 0.05, 0.35) * a.edge;
          if (side == 0) a.center.x = in;
          if (side == 1) a.center.x = camera.width - 1 - in;
          if (side == 2) a.center.y = in;
          if (side == 3) a.center.y = camera.height - 1 - in;
          b = a;
          b.roll += uniform(rng, -10, 10);
        } else {
          const double distance = uniform(rng, 0, layout.travel), direction = uniform(rng, 0, 2 * CV_PI);
          b.center += distance * cv::Point2d(std::cos(direction), std::sin(direction));
          b.edge = std::clamp(a.edge * std::exp(uniform(rng, -0.2, 0.2)), layout.min_edge, layout.max_edge);
          b.tilt = std::clamp(a.tilt + uniform(rng, -15, 15), 0.0, layout.max_tilt);
          b.tilt_axis += uniform(rng, -30, 30);
          b.roll += uniform(rng, -30, 30);
        }
        std::vector<Pose> poses;
        std::vector<cv::Rect2d> box;
        for (int f = 0; f < frames; ++f) {
          const double s = frames > 1 ? double(f) / (frames - 1) : 0;
          const Pose p = shaken(pose_of(camera, between(a, b, s)), c.shake[f]);
          cv::Rect2d r = bounds(outline(camera, p, e, kTagSize * kSheet));
          const cv::Point2d center = center_of(camera, p);
          const bool ok = e.cut ? is_cut(camera, p, e) && center.x >= 2 && center.y >= 2 &&
                                      center.x <= camera.width - 3 && center.y <= camera.height - 3
                                : inside(r, camera, 1);
          r = {r.x - layout.gap / 2, r.y - layout.gap / 2, r.width + layout.gap, r.height + layout.gap};
          auto overlaps = [&](const cv::Rect2d& o) { return !(o & r).empty(); };
          if (!ok || std::any_of(boxes[f].begin(), boxes[f].end(), overlaps)) break;
          poses.push_back(p);
          box.push_back(r);
        }
        if (int(poses.size()) < frames) continue;
        for (int f = 0; f < frames; ++f) c.poses[f].push_back(poses[f]), boxes[f].push_back(box[f]);
        ++placed;
      }
      if (placed == m) break;
    }
    if (placed < count) continue;
    c.extras = extras;
    break;
  }
  if (c.extras.empty())
    throw std::logic_error(std::string("field: cannot place the sheets of a ") + kInfo[condition].name + " clip");

  // An occluder's tip, so that it hides the wanted fraction of its tag in the first frame.
  for (std::size_t m = 0; m < c.extras.size(); ++m) {
    Extra& e = c.extras[m];
    if (!e.occluded) continue;
    const double wanted = e.occluder_tip;
    double lo = -0.8, hi = 0.8;  // tip positions (edges from the centre), more to less hidden
    for (int i = 0; i < 30; ++i) {
      e.occluder_tip = (lo + hi) / 2;
      (occluded_fraction(camera, c.poses[0][m], e) > wanted ? lo : hi) = e.occluder_tip;
    }
  }
  if (c.drawn_as == kMotion)
    for (int f = 0; f < frames; ++f) {
      c.motion.emplace_back();
      for (std::size_t m = 0; m < c.extras.size(); ++m)
        c.motion.back().push_back({uniform(rng, 3, 15), uniform(rng, 0, 360)});
    }
  return c;
}

// The sheet as the system's scene target: bent when its extra says so. A sheet bent
// about the marker's x axis is the renderer's bend (about the target's y axis) of the
// marker turned a quarter in its plane: the albedo turned back, the pose turned on.
lftag::SceneTarget sheet_target(const FiducialSystem& system, const std::string& id, const Pose& pose, const Extra& e) {
  lftag::SceneTarget t = system.target(id, kTagSize, pose.rvec, pose.tvec);
  if (e.bend == 0) return t;
  t.bend_radius = e.bend;
  if (e.bend_about_x) {
    // Target point (u, v) is marker point (-v, u).
    cv::rotate(t.albedo, t.albedo, cv::ROTATE_90_COUNTERCLOCKWISE);
    cv::Rodrigues(rotation_matrix(pose.rvec) * rotation_matrix({0, 0, CV_PI / 2}), t.rvec);
  }
  return t;
}

// Rolling shutter and motion blur: row y is exposed from y / H * readout for `exposure`
// seconds, while each sheet moves with its own image velocity. The frame is drawn in
// bands of 4 rows (each at its middle row's time: the skew between bands is under a
// pixel), each band averaged over sub-exposures, with its own camera (the principal
// point moved) so that the renderer draws only those rows. A sheet's truth is its pose
// when its centre's row is half exposed. Rows no sheet comes near are the background.
cv::Mat1f render_rolling(const Clip& c, int f, const cv::Mat1b& background,
                         const std::vector<lftag::SceneTarget>& targets) {
  const lftag::Camera& camera = c.camera;
  const double exposure = c.exposure_ms / 1000, readout = c.readout_ms / 1000;
  const int rows = camera.height;
  cv::Mat1f out;
  background.convertTo(out, CV_32F);  // the renderer's background at exposure 1
  std::vector<cv::Vec3d> velocity;
  std::vector<double> truth_time;
  std::vector<std::pair<int, int>> reach;  // rows a sheet can touch, first and last
  for (std::size_t m = 0; m < targets.size(); ++m) {
    const Pose& p = c.poses[f][m];
    const Motion& motion = c.motion[f][m];
    const double speed = motion.length / exposure, a = motion.direction * CV_PI / 180;  // px / s
    velocity.emplace_back(speed * std::cos(a) * p.tvec[2] / camera.fx, speed * std::sin(a) * p.tvec[2] / camera.fy, 0);
    truth_time.push_back(center_of(camera, p).y / rows * readout + exposure / 2);
    // Its rows at its truth, stretched by the skew (under a fifth at these speeds) and
    // the blur.
    const cv::Rect2d box = bounds(outline(camera, p, c.extras[m], kTagSize * kSheet));
    const double grow = 0.25 * box.height + motion.length + 4;
    reach.emplace_back(int(std::floor(box.y - grow)), int(std::ceil(box.y + box.height + grow)));
  }
  constexpr int kBand = 4;
  for (int y0 = 0; y0 < rows; y0 += kBand) {
    const int h = std::min(kBand, rows - y0);
    std::vector<std::size_t> near;  // the sheets this band can show
    double longest = 0;
    for (std::size_t m = 0; m < targets.size(); ++m)
      if (reach[m].first < y0 + h && reach[m].second >= y0)
        near.push_back(m), longest = std::max(longest, c.motion[f][m].length);
    if (near.empty()) continue;
    lftag::SceneParams params;
    params.camera = camera;
    params.camera.cy = camera.cy - y0;
    params.camera.height = h;
    params.photo = background.rowRange(y0, y0 + h);
    params.supersample = 4;  // the sub-exposures average the rest
    const lftag::SceneRenderer renderer(params);
    const int samples = std::clamp(int(std::ceil(1.25 * longest)), 6, 20);  // under 0.8 px apart
    const double start = (y0 + (h - 1) / 2.0) / rows * readout;
    cv::Mat1f sum(h, camera.width, 0.0f);
    std::vector<lftag::SceneTarget> moved;
    for (std::size_t m : near) moved.push_back(targets[m]);
    for (int k = 0; k < samples; ++k) {
      const double t = start + (k + 0.5) / samples * exposure;
      for (std::size_t i = 0; i < near.size(); ++i)
        moved[i].tvec = targets[near[i]].tvec + velocity[near[i]] * (t - truth_time[near[i]]);
      sum += renderer.render_linear(moved);
    }
    out.rowRange(y0, y0 + h) = sum / samples;
  }
  return out;
}

// A disc of `radius` pixels, each tap its covered area (16 x 16 samples), summing to 1.
cv::Mat1f pillbox_kernel(double radius) {
  const int half = int(std::ceil(radius));
  cv::Mat1f k(2 * half + 1, 2 * half + 1, 0.0f);
  const int n = 16;
  for (int y = 0; y < k.rows; ++y)
    for (int x = 0; x < k.cols; ++x)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const double dx = x - half - 0.5 + (i + 0.5) / n, dy = y - half - 0.5 + (j + 0.5) / n;
          if (dx * dx + dy * dy <= radius * radius) k(y, x) += 1.0f;
        }
  return k / cv::sum(k)[0];
}

// One frame's light: the clip's exposure and gradient, and the shadows.
cv::Mat1f light_map(const Clip& c, int f) {
  const int w = c.camera.width, h = c.camera.height;
  cv::Mat1f light(h, w);
  const double a = c.light_angle * CV_PI / 180, ca = std::cos(a), sa = std::sin(a);
  const double extent = std::abs(w * ca) + std::abs(h * sa);
  // Low light is set by its own black and white levels, not the exposure.
  const double exposure = c.drawn_as == kLowLight ? 1.0 : c.exposure;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      light(y, x) = float(exposure * (1 + c.gradient * ((x - w / 2.0) * ca + (y - h / 2.0) * sa) / extent));
  if (c.drawn_as != kShadow) return light;
  std::vector<cv::Point2d> centers;
  std::vector<double> edges;
  for (const Pose& p : c.poses[f])
    centers.push_back(center_of(c.camera, p)), edges.push_back(edge_px(c.camera, p, kTagSize));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double shade = 0;  // how far into a shadow: 0 lit, 1 fully in it; a linear penumbra
      for (std::size_t m = 0; m < centers.size(); ++m) {
        const double d = shadow_distance(c.extras[m], centers[m], edges[m], cv::Point2d(x, y));
        shade = std::max(shade, std::clamp(0.5 - d / c.penumbra, 0.0, 1.0));
      }
      light(y, x) *= float(1 - (1 - c.shadow_level) * shade);
    }
  return light;
}

// The scene as the lens delivers it (grey levels, not yet a sensor's): the sheets over the
// background, occluders, light and shadows, then defocus.
// `renderer` draws the frame's background (all but motion, which draws its own bands).
cv::Mat1f optics(const Clip& c, int f, const lftag::SceneRenderer* renderer, const cv::Mat1b& background,
                 const cv::Mat1f& light, const std::vector<lftag::SceneTarget>& targets) {
  cv::Mat1f image = renderer ? renderer->render_linear(targets) : render_rolling(c, f, background, targets);
  for (std::size_t m = 0; m < c.extras.size(); ++m) {
    const Extra& e = c.extras[m];
    if (!e.occluded) continue;
    const cv::Point2d center = center_of(c.camera, c.poses[f][m]);
    const double edge = edge_px(c.camera, c.poses[f][m], kTagSize);
    const float albedo = float(255 * e.occluder_albedo);
    const double r = (e.occluder_reach + e.occluder_width + 0.1) * edge + 2;  // the bar lies within
    const cv::Rect box = cv::Rect(cv::Point(int(center.x - r), int(center.y - r)),
                                  cv::Point(int(center.x + r) + 1, int(center.y + r) + 1)) &
                         cv::Rect(0, 0, image.cols, image.rows);
    for (int y = box.y; y < box.y + box.height; ++y)
      for (int x = box.x; x < box.x + box.width; ++x) {
        const float cover = float(std::clamp(0.5 - occluder_distance(e, center, edge, cv::Point2d(x, y)), 0.0, 1.0));
        if (cover > 0) image(y, x) = image(y, x) * (1 - cover) + albedo * cover;
      }
  }
  cv::multiply(image, light, image);
  if (c.drawn_as == kPillbox)
    cv::filter2D(image, image, -1, pillbox_kernel(c.pillbox), cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
  else if (c.defocus > 0.05)
    cv::GaussianBlur(image, image, cv::Size(), c.defocus);
  return image;
}

cv::Mat1f gaussian_noise(cv::Size size, double sigma, std::uint64_t seed) {
  cv::Mat1f noise(size);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, sigma);
  return noise;
}

cv::Mat1b jpeg(const cv::Mat& image) {
  std::vector<std::uint8_t> bytes;
  cv::imencode(".jpg", image, bytes, {cv::IMWRITE_JPEG_QUALITY, kJpegQuality});
  return cv::imdecode(bytes, cv::IMREAD_GRAYSCALE);
}

// A colour camera: the grey scene under the clip's light through an RGGB mosaic (raw
// sensitivities R 0.5, G 1, B 0.65 of the brightest), noise, 8 bits, white-balance gains
// on the raw (right within the clip's error), OpenCV's demosaicing (bilinear or edge
// aware), then a colour JPEG read back as grey, as a user of a colour camera gets it.
cv::Mat1b bayer_camera(const Clip& c, const cv::Mat1f& scene, const cv::Mat1f& noise) {
  const cv::Vec3d sensitivity(0.5, 1.0, 0.65);
  cv::Vec3d response;
  for (int k = 0; k < 3; ++k) response[k] = c.illuminant[k] * sensitivity[k];
  const double top = std::max({response[0], response[1], response[2]});
  cv::Mat1f raw(scene.size());
  for (int y = 0; y < scene.rows; ++y)
    for (int x = 0; x < scene.cols; ++x) {
      const int channel = (y % 2) + (x % 2);  // RGGB: 0 red, 1 green, 2 blue
      raw(y, x) = float(scene(y, x) * 0.95 * response[channel] / top);
    }
  raw += noise;
  cv::Mat1b raw8;
  raw.convertTo(raw8, CV_8U);
  for (int y = 0; y < raw8.rows; ++y)
    for (int x = 0; x < raw8.cols; ++x) {
      const int channel = (y % 2) + (x % 2);
      const double gain = response[1] / response[channel] * c.wb_error[channel];
      raw8(y, x) = cv::saturate_cast<std::uint8_t>(raw8(y, x) * gain);
    }
  cv::Mat bgr;
  cv::cvtColor(raw8, bgr, c.edge_aware ? cv::COLOR_BayerRGGB2BGR_EA : cv::COLOR_BayerRGGB2BGR);
  return jpeg(bgr);
}

// The sensor and, but for H.264 (coded per clip), the codec: noise and 8 bits, with the
// low-light tone curve (ink at the black level, paper at the white one, a gamma between
// them, then the noise) or the Bayer camera, then JPEG.
// `noise`: the frame's sensor noise, the same for every system.
cv::Mat1b sensor(const Clip& c, const cv::Mat1f& scene, const cv::Mat1f& noise) {
  if (c.drawn_as == kBayer) return bayer_camera(c, scene, noise);
  cv::Mat1f image;
  if (c.drawn_as == kLowLight) {
    image.create(scene.size());
    const double ink = 255 * kInk, paper = 255 * kPaper;
    for (int y = 0; y < scene.rows; ++y)
      for (int x = 0; x < scene.cols; ++x) {
        const double v = std::max(0.0, (scene(y, x) - ink) / (paper - ink));
        image(y, x) = float(c.black + (c.white - c.black) * std::pow(v, 1 / c.gamma));
      }
    image += noise;
  } else {
    image = scene + noise;
  }
  cv::Mat1b out;
  image.convertTo(out, CV_8U);
  return c.kbps > 0 ? out : jpeg(out);
}

// The background of frame f: the source frame covering the frame size, moved by the
// camera shake.
cv::Mat1b background(const cv::Mat1b& frame, const Clip& c, int f) {
  const cv::Size size(c.camera.width, c.camera.height);
  const cv::Matx33d k = c.camera.matrix();
  cv::Mat1b out;
  cv::warpPerspective(cover(frame, size), out, cv::Mat(k * c.shake[f] * k.inv()), size, cv::INTER_LINEAR,
                      cv::BORDER_REFLECT);
  return out;
}

const std::string& marker_id(const std::vector<std::string>& ids, const Clip& c, int slot) {
  // Codec twins share their originals' ids; the same clip index in another condition
  // starts elsewhere in the set's ids.
  const int uid = c.drawn_as * 97 + c.index;
  return ids[std::size_t(uid * 7 + slot) % ids.size()];
}

// The frames of one clip as every system's camera delivers them: [system][frame].
// Each system's frames of the clip, and after them the clip's marker-free twin: the same
// frames with blank sheets (paper only) where the markers were, for the false positives.
std::vector<std::vector<cv::Mat1b>> render_clip(const Clip& c, const std::vector<cv::Mat1b>& source_frames,
                                                const std::vector<std::unique_ptr<FiducialSystem>>& systems,
                                                const std::vector<std::vector<std::string>>& ids, std::uint64_t seed) {
  std::vector<std::vector<cv::Mat1b>> out(systems.size() + 1);
  // One renderer per clip, over each frame's background in turn: with lens distortion,
  // tracing the pixel corners back is much of a frame's work. Bent sheets are drawn
  // with 4 x 4 samples at their edges (ray and cylinder meet at every sample).
  std::unique_ptr<lftag::SceneRenderer> base;
  if (c.drawn_as != kMotion) {
    lftag::SceneParams params;
    params.camera = c.camera;
    if (c.drawn_as == kBent) params.supersample = 4;
    base = std::make_unique<lftag::SceneRenderer>(params);
  }
  for (int f = 0; f < c.frames; ++f) {
    const cv::Mat1b back = background(source_frames[std::size_t(f)], c, f);
    const cv::Mat1f light = light_map(c, f);
    std::unique_ptr<lftag::SceneRenderer> renderer;
    if (base) renderer = std::make_unique<lftag::SceneRenderer>(base->with_photo(back));
    // One noise field per frame for every system (and for a codec twin and its original).
    const std::uint64_t noise_seed = seeded(
        seed, {0xf1e1e, std::uint64_t(c.set), std::uint64_t(c.drawn_as), std::uint64_t(c.index), std::uint64_t(f)})();
    const cv::Mat1f noise = gaussian_noise(back.size(), c.drawn_as == kLowLight ? c.dark_noise : c.noise, noise_seed);
    for (std::size_t s = 0; s < systems.size(); ++s) {
      std::vector<lftag::SceneTarget> targets;
      for (std::size_t m = 0; m < c.extras.size(); ++m)
        targets.push_back(sheet_target(*systems[s], marker_id(ids[s], c, int(m)), c.poses[f][m], c.extras[m]));
      out[s].push_back(sensor(c, optics(c, f, renderer.get(), back, light, targets), noise));
    }
    std::vector<lftag::SceneTarget> blank;
    for (std::size_t m = 0; m < c.extras.size(); ++m) {
      lftag::SceneTarget t = sheet_target(*systems[0], marker_id(ids[0], c, int(m)), c.poses[f][m], c.extras[m]);
      double paper = 0;
      cv::minMaxLoc(t.albedo, nullptr, &paper);
      t.albedo.setTo(paper);
      blank.push_back(std::move(t));
    }
    out.back().push_back(sensor(c, optics(c, f, renderer.get(), back, light, blank), noise));
  }
  if (c.kbps > 0)
    for (auto& frames : out) frames = h264_round_trip(frames, c.kbps, int(kFps));
  return out;
}

// One marker in one frame, as the truth has it and as each system saw it.
struct Truth {
  int subset = kVisible;
  double edge = 0, tilt = 0, distance = 0, blur = kNaN, bend = kNaN, occluded = kNaN;
  cv::Point2d center;  // image of the tag's centre, pixels
};
struct Seen {
  bool found = false;
  int wrong = 0;  // detections in the frame that are no marker of it, charged to the nearest
  double rotation_deg = kNaN, translation_m = kNaN;
};

// Scores one frame's detections against all its markers (cut and occluded ones too: a
// detection of them is not wrong).
// A wrong detection, for a look at what it was: its id and centre, the marker it lies
// nearest and how far from that marker's centre, in projected edges.
struct Wrong {
  std::string id;
  cv::Point2d center;
  int nearest = 0;
  double distance_edges = 0;
};

std::vector<Seen> score_frame(const std::vector<Detected>& detections, const Clip& c, int f,
                              const std::vector<std::string>& frame_ids, std::vector<Wrong>& wrongs) {
  const std::size_t n = c.extras.size();
  std::vector<Seen> out(n);
  std::vector<cv::Point2d> centers;
  std::vector<double> tolerances;
  for (std::size_t m = 0; m < n; ++m) {
    const Pose& p = c.poses[f][m];
    const Outcome o = score(detections, frame_ids[m], p, kTagSize, c.camera);
    out[m].found = o.found;
    out[m].rotation_deg = o.rotation_error_deg;
    out[m].translation_m = o.translation_error_m;
    centers.push_back(center_of(c.camera, p));
    tolerances.push_back(std::max(2.0, edge_px(c.camera, p, kTagSize) / 4));  // as score()
  }
  for (const Detected& d : detections) {
    std::size_t nearest = 0;
    bool matched = false;
    for (std::size_t m = 0; m < n; ++m) {
      const double distance = cv::norm(d.center - centers[m]);
      matched = matched || (d.id == frame_ids[m] && distance <= tolerances[m]);
      if (distance < cv::norm(d.center - centers[nearest])) nearest = m;
    }
    if (matched) continue;
    ++out[nearest].wrong;
    wrongs.push_back({d.id, d.center, int(nearest),
                      cv::norm(d.center - centers[nearest]) / edge_px(c.camera, c.poses[f][nearest], kTagSize)});
  }
  return out;
}

std::vector<Truth> truth_of(const Clip& c, int f) {
  std::vector<Truth> out;
  for (std::size_t m = 0; m < c.extras.size(); ++m) {
    const Pose& p = c.poses[f][m];
    const Extra& e = c.extras[m];
    Truth t;
    t.edge = edge_px(c.camera, p, kTagSize);
    t.center = center_of(c.camera, p);
    t.tilt = tilt_deg(p);
    t.distance = cv::norm(p.tvec);
    if (e.bend != 0) t.bend = e.bend;
    if (!c.motion.empty()) t.blur = c.motion[f][m].length;
    if (e.occluded) t.occluded = 100 * occluded_fraction(c.camera, p, e);
    t.subset = e.cut && is_cut(c.camera, p, e) ? kCut : e.occluded ? kOccluded : kVisible;
    out.push_back(t);
  }
  return out;
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The clips of the chosen conditions (all when none are named), `clips` per condition
// and set; the H.264 conditions only where GStreamer can code them.
std::vector<Clip> plan_clips(const Options& options, const Sources& sources, int clips_per_condition, int frames) {
  const std::string no_h264 = h264_unavailable();
  if (!no_h264.empty()) progress("field: the H.264 conditions are left out: " + no_h264);

  std::vector<bool> chosen(kConditions, options.conditions.empty());
  for (const std::string& name : options.conditions) {
    const auto info =
        std::find_if(std::begin(kInfo), std::end(kInfo), [&](const ConditionInfo& i) { return name == i.name; });
    if (info == std::end(kInfo)) {
      std::string known;
      for (const ConditionInfo& i : kInfo) known += std::string(known.empty() ? "" : ", ") + i.name;
      throw std::invalid_argument("field: unknown condition '" + name + "' (known: " + known + ")");
    }
    chosen[std::size_t(info - std::begin(kInfo))] = true;
  }
  std::vector<Clip> clips;
  for (int set = 0; set < 2; ++set)
    for (int condition = 0; condition < kConditions; ++condition) {
      if (!chosen[std::size_t(condition)]) continue;
      if ((condition == kH264 || condition == kH264Small) && !no_h264.empty()) continue;
      for (int i = 0; i < clips_per_condition; ++i)
        clips.push_back(plan_clip(sources, set, condition, i, frames, options.seed));
    }
  return clips;
}

// Marker `slot` of every clip of `set` for `system`: each set its own ids, kIdsPerSet of
// them, or half of a smaller dictionary's (AprilTag 16h5 and LFTag 2x2 have 30 and 16).
std::vector<std::string> set_ids(const FiducialSystem& system, int set, std::uint64_t seed) {
  const std::vector<std::string> all = system.marker_ids(2 * kIdsPerSet, seed);
  const std::ptrdiff_t per_set = std::ptrdiff_t(all.size() / 2);
  if (per_set == 0) throw std::runtime_error(system.name() + ": too few ids for a tuning and a validation set");
  return {all.begin() + set * per_set, all.begin() + (set + 1) * per_set};
}

class FieldClips final : public ClipSource {
 public:
  FieldClips(const Options& options, int clips, int frames)
      : seed_(options.seed), sources_(split_sources(options.data)), reader_(sources_.all) {
    clips_ = plan_clips(options, sources_, clips, frames);
    order_.resize(clips_.size());
    std::iota(order_.begin(), order_.end(), 0);
    std::stable_sort(order_.begin(), order_.end(), [&](int a, int b) {
      return std::make_pair(clips_[a].source, clips_[a].start) < std::make_pair(clips_[b].source, clips_[b].start);
    });
  }
  int size() const override { return int(clips_.size()); }
  RenderedClip render(int index, const std::vector<std::unique_ptr<FiducialSystem>>& systems) override {
    const Clip& c = clips_[std::size_t(order_[std::size_t(index)])];
    RenderedClip out;
    out.set = kSets[c.set];
    out.condition = kInfo[c.condition].name;
    out.index = c.index;
    out.camera = c.camera;
    out.tag_size = kTagSize;
    out.fps = kFps;
    out.poses = c.poses;
    for (int f = 0; f < c.frames; ++f) {
      out.visible.emplace_back();
      for (const Truth& t : truth_of(c, f)) out.visible.back().push_back(t.subset == kVisible);
    }
    std::vector<std::vector<std::string>> ids;
    for (const auto& system : systems) {
      ids.push_back(set_ids(*system, c.set, seed_));
      out.ids.emplace_back();
      for (std::size_t m = 0; m < c.extras.size(); ++m) out.ids.back().push_back(marker_id(ids.back(), c, int(m)));
    }
    std::vector<cv::Mat1b> frames;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (int f = 0; f < c.frames; ++f)
        frames.push_back(reader_.read(c.source, sources_.all[c.source].video ? c.start + f : 0));
    }
    out.images = render_clip(c, frames, systems, ids, seed_);
    return out;
  }

 private:
  std::uint64_t seed_;
  Sources sources_;
  std::vector<Clip> clips_;
  std::vector<int> order_;
  std::mutex mutex_;  // guards the reader
  FrameReader reader_;
};

}  // namespace

std::unique_ptr<ClipSource> field_clips(const Options& options, int clips, int frames) {
  return std::make_unique<FieldClips>(options, clips, frames);
}

bool run_field(const Options& options) {
  const Plan plan = options.quick ? kQuick : options.acceptance ? kAcceptance : kFull;
  const Sources sources = split_sources(options.data);
  const std::vector<Clip> clips = plan_clips(options, sources, plan.clips, plan.frames);
  // Videos are read forward: clips in the order of their source and first frame.
  std::vector<int> order(clips.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return std::make_pair(clips[a].source, clips[a].start) < std::make_pair(clips[b].source, clips[b].start);
  });

  const int n = int(options.systems.size());
  const int threads = std::max(1, options.threads);
  // Every worker its own systems; ids per system and set.
  std::vector<std::vector<std::unique_ptr<FiducialSystem>>> workers(threads);
  for (auto& w : workers)
    for (const std::string& name : options.systems) w.push_back(make_system(name));
  std::vector<std::string> families;
  std::vector<std::vector<std::vector<std::string>>> ids(2, std::vector<std::vector<std::string>>(n));  // set, system
  for (int s = 0; s < n; ++s) {
    families.push_back(workers[0][s]->family());
    for (int set = 0; set < 2; ++set) ids[set][s] = set_ids(*workers[0][s], set, options.seed);
  }
  auto frame_ids = [&](const Clip& c, int s) {
    std::vector<std::string> v;
    for (std::size_t m = 0; m < c.extras.size(); ++m) v.push_back(marker_id(ids[c.set][s], c, int(m)));
    return v;
  };

  FrameReader reader(sources.all);
  std::mutex mutex;  // guards the reader and the progress count
  auto source_frames = [&](const Clip& c) {
    std::lock_guard<std::mutex> lock(mutex);
    std::vector<cv::Mat1b> v;
    for (int f = 0; f < c.frames; ++f)
      v.push_back(reader.read(c.source, sources.all[c.source].video ? c.start + f : 0));
    return v;
  };

  // Accuracy: every clip, on all workers. [clip][frame] truths, [clip][frame][system] seen.
  std::vector<std::vector<std::vector<Truth>>> truths(clips.size());
  std::vector<std::vector<std::vector<std::vector<Seen>>>> seen(clips.size());
  std::vector<std::vector<std::vector<std::vector<Wrong>>>> wrongs(clips.size());
  // [clip][frame][system] every detection, for the confidences of right and wrong ids.
  std::vector<std::vector<std::vector<std::vector<Detected>>>> detections(clips.size());
  // [clip][frame][system] detections in the clip's marker-free twin: false positives.
  std::vector<std::vector<std::vector<int>>> false_positives(clips.size());
  int done = 0;
  // The quick plan's few frames are kept for the timing instead of being drawn again.
  const bool keep = options.quick;
  std::map<std::size_t, std::vector<std::vector<cv::Mat1b>>> kept;  // by clip
  parallel_for(int(clips.size()), threads, [&](int k, int worker) {
    const Clip& c = clips[std::size_t(order[std::size_t(k)])];
    const std::size_t ci = std::size_t(order[std::size_t(k)]);
    std::vector<std::unique_ptr<FiducialSystem>>& systems = workers[std::size_t(worker)];
    for (auto& s : systems) s->set_camera(c.camera, kTagSize);
    std::vector<std::vector<std::string>> clip_ids;
    for (int s = 0; s < n; ++s) clip_ids.push_back(ids[c.set][s]);
    auto images = render_clip(c, source_frames(c), systems, clip_ids, options.seed);
    truths[ci].resize(c.frames);
    seen[ci].assign(c.frames, std::vector<std::vector<Seen>>(n));
    wrongs[ci].assign(c.frames, std::vector<std::vector<Wrong>>(n));
    detections[ci].assign(c.frames, std::vector<std::vector<Detected>>(n));
    false_positives[ci].assign(c.frames, std::vector<int>(n, 0));
    for (int f = 0; f < c.frames; ++f) {
      for (int s = 0; s < n; ++s) false_positives[ci][f][s] = int(systems[s]->detect(images[n][f]).size());
      truths[ci][f] = truth_of(c, f);
      for (int s = 0; s < n; ++s) {
        const std::vector<std::string> fid = frame_ids(c, s);
        detections[ci][f][s] = systems[s]->detect(images[s][f]);
        seen[ci][f][s] = score_frame(detections[ci][f][s], c, f, fid, wrongs[ci][f][s]);
        if (options.save_misses.empty()) continue;
        bool missed = false;
        for (std::size_t m = 0; m < fid.size(); ++m)
          missed |= !seen[ci][f][s][m].found && truths[ci][f][m].subset == kVisible;
        const std::string name = options.systems[s] + "-field-" + kSets[c.set] + "-" + kInfo[c.condition].name +
                                 "-clip" + std::to_string(c.index) + "-frame" + std::to_string(f);
        if (missed) cv::imwrite((options.save_misses / (name + ".png")).string(), images[s][f]);
        if (!wrongs[ci][f][s].empty())
          cv::imwrite((options.save_misses / (name + "-wrong.png")).string(), images[s][f]);
      }
    }
    std::lock_guard<std::mutex> lock(mutex);
    if (keep && c.index < plan.timed_clips) kept[ci] = std::move(images);
    if (++done % 10 == 0 || done == int(clips.size()))
      progress("field: " + std::to_string(done) + " / " + std::to_string(clips.size()) + " clips");
  });

  // Timing: the first clips of every condition and set, rendered a few at a time on all
  // workers (in the order their sources are read), then detected on this thread alone,
  // the systems' order turned from frame to frame. [system][condition][set] samples, ms.
  std::vector<std::vector<std::vector<std::vector<double>>>> times(
      n, std::vector<std::vector<std::vector<double>>>(kConditions, std::vector<std::vector<double>>(2)));
  std::vector<int> timed;
  for (int i : order)
    if (clips[std::size_t(i)].index < plan.timed_clips) timed.push_back(i);
  progress("field: timing " + std::to_string(timed.size()) + " clips on one thread");
  bool warm = false;
  for (std::size_t first = 0; first < timed.size(); first += std::size_t(threads)) {
    const std::size_t count = std::min(std::size_t(threads), timed.size() - first);
    std::vector<std::vector<std::vector<cv::Mat1b>>> images(count);
    parallel_for(int(count), threads, [&](int k, int worker) {
      const Clip& c = clips[std::size_t(timed[first + std::size_t(k)])];
      std::vector<std::vector<std::string>> clip_ids;
      for (int s = 0; s < n; ++s) clip_ids.push_back(ids[c.set][s]);
      const auto found = kept.find(std::size_t(timed[first + std::size_t(k)]));
      images[std::size_t(k)] =
          found != kept.end() ? std::move(found->second)
                              : render_clip(c, source_frames(c), workers[std::size_t(worker)], clip_ids, options.seed);
    });
    std::vector<std::unique_ptr<FiducialSystem>>& systems = workers[0];
    for (std::size_t k = 0; k < count; ++k) {
      const Clip& c = clips[std::size_t(timed[first + k])];
      for (auto& s : systems) s->set_camera(c.camera, kTagSize);
      if (!warm)  // first calls allocate and fill caches
        for (int s = 0; s < n; ++s) systems[s]->detect(images[k][s][0]);
      warm = true;
      for (int pass = 0; pass < plan.passes; ++pass)
        for (int f = 0; f < c.frames; ++f)
          for (int i = 0; i < n; ++i) {
            const int s = (i + f + pass) % n;
            const auto start = std::chrono::steady_clock::now();
            systems[s]->detect(images[k][s][f]);
            times[s][c.condition][c.set].push_back(elapsed_ms(start));
          }
    }
  }

  // Rows.
  Csv clips_csv(options.out / "field_clips.csv", {"set",
                                                  "condition",
                                                  "clip",
                                                  "background",
                                                  "start_frame",
                                                  "width",
                                                  "height",
                                                  "frames",
                                                  "markers",
                                                  "fx",
                                                  "k1",
                                                  "k2",
                                                  "exposure",
                                                  "light_gradient",
                                                  "noise_sigma",
                                                  "defocus_sigma_px",
                                                  "codec",
                                                  "kbps",
                                                  "shadow_level",
                                                  "penumbra_px",
                                                  "exposure_ms",
                                                  "readout_ms",
                                                  "pillbox_radius_px",
                                                  "black",
                                                  "white",
                                                  "gamma",
                                                  "dark_noise_sigma",
                                                  "illuminant_r",
                                                  "illuminant_g",
                                                  "illuminant_b",
                                                  "wb_error_r",
                                                  "wb_error_b",
                                                  "demosaic"});
  for (const Clip& c : clips) {
    const bool k = c.camera.has_distortion();
    clips_csv.row(kSets[c.set], kInfo[c.condition].name, c.index, sources.all[c.source].path.filename().string(),
                  c.start, c.camera.width, c.camera.height, c.frames, int(c.extras.size()), c.camera.fx,
                  k ? c.camera.distortion[0] : kNaN, k ? c.camera.distortion[1] : kNaN,
                  c.drawn_as == kLowLight ? kNaN : c.exposure, c.gradient, c.drawn_as == kLowLight ? kNaN : c.noise,
                  c.defocus, c.kbps > 0 ? "h264" : "jpeg", c.kbps, c.shadow_level, c.penumbra, c.exposure_ms,
                  c.readout_ms, c.pillbox, c.black, c.white, c.gamma, c.dark_noise,
                  c.drawn_as == kBayer ? c.illuminant[0] : kNaN, c.drawn_as == kBayer ? c.illuminant[1] : kNaN,
                  c.drawn_as == kBayer ? c.illuminant[2] : kNaN, c.drawn_as == kBayer ? c.wb_error[0] : kNaN,
                  c.drawn_as == kBayer ? c.wb_error[2] : kNaN,
                  c.drawn_as == kBayer ? (c.edge_aware ? "edge-aware" : "bilinear") : "");
  }
  Csv markers_csv(options.out / "field.csv", {"system",
                                              "family",
                                              "set",
                                              "condition",
                                              "clip",
                                              "frame",
                                              "marker",
                                              "id",
                                              "subset",
                                              "x",
                                              "y",
                                              "edge_px",
                                              "tilt_deg",
                                              "distance_m",
                                              "blur_px",
                                              "bend_radius_m",
                                              "occluded_pct",
                                              "found",
                                              "wrong",
                                              "translation_error_m",
                                              "translation_error_pct",
                                              "rotation_error_deg"});
  Csv summary_csv(
      options.out / "field_summary.csv",
      {"system", "family", "set", "condition", "subset", "frames", "markers", "found", "recall_pct", "wrong",
       "with_pose", "median_translation_pct", "p90_translation_pct", "median_rotation_deg", "p90_rotation_deg"});
  Csv times_csv(options.out / "field_times.csv", {"system", "family", "set", "condition", "width", "height", "frames",
                                                  "samples", "mean_ms", "median_ms", "p99_ms"});
  Csv wrong_csv(options.out / "field_wrong.csv",
                {"system", "family", "set", "condition", "clip", "frame", "id", "x", "y", "nearest_marker",
                 "nearest_id", "nearest_subset", "nearest_edge_px", "distance_edges"});
  // Every detection with the system's confidence in it: where a bound on it would stop the
  // wrong ids, and what it would cost (choose it on the tuning set, check it on the other).
  Csv detections_csv(options.out / "field_detections.csv",
                     {"system", "family", "set", "condition", "clip", "frame", "id", "right", "path", "confidence"});
  for (int s = 0; s < n; ++s)
    for (std::size_t ci = 0; ci < clips.size(); ++ci) {
      const Clip& c = clips[ci];
      const std::vector<std::string> fid = frame_ids(c, s);
      for (int f = 0; f < c.frames; ++f)
        for (const Detected& d : detections[ci][f][s])
          detections_csv.row(options.systems[s], families[s], kSets[c.set], kInfo[c.condition].name, c.index, f, d.id,
                             int(std::find(fid.begin(), fid.end(), d.id) != fid.end()), d.path, d.confidence);
    }
  // The marker-free twins: every detection is a false positive.
  Csv fp_csv(options.out / "field_fp.csv",
             {"system", "family", "set", "condition", "frames", "false_positives", "frames_with_false_positives"});
  for (int s = 0; s < n; ++s)
    for (int set = 0; set < 2; ++set)
      for (int condition = 0; condition < kConditions; ++condition) {
        int frames = 0, fp = 0, with = 0;
        for (std::size_t ci = 0; ci < clips.size(); ++ci) {
          const Clip& c = clips[ci];
          if (c.set != set || c.condition != condition) continue;
          for (int f = 0; f < c.frames; ++f) {
            ++frames;
            fp += false_positives[ci][f][s];
            with += false_positives[ci][f][s] > 0;
          }
        }
        if (frames > 0)
          fp_csv.row(options.systems[s], families[s], kSets[set], kInfo[condition].name, frames, fp, with);
      }
  struct Tally {
    int frames = 0, markers = 0, found = 0, wrong = 0;
    std::vector<double> translation_pct, rotation_deg;
  };
  for (int s = 0; s < n; ++s) {
    const std::string& name = options.systems[s];
    for (std::size_t ci = 0; ci < clips.size(); ++ci) {
      const Clip& c = clips[ci];
      const std::vector<std::string> fid = frame_ids(c, s);
      for (int f = 0; f < c.frames; ++f)
        for (const Wrong& w : wrongs[ci][f][s])
          wrong_csv.row(name, families[s], kSets[c.set], kInfo[c.condition].name, c.index, f, w.id, w.center.x,
                        w.center.y, w.nearest, fid[std::size_t(w.nearest)],
                        kSubsetNames[truths[ci][f][std::size_t(w.nearest)].subset],
                        truths[ci][f][std::size_t(w.nearest)].edge, w.distance_edges);
    }
    // [set][condition + 1 for all][subset]
    std::vector<std::vector<std::vector<Tally>>> tally(
        2, std::vector<std::vector<Tally>>(kConditions + 1, std::vector<Tally>(kSubsets)));
    for (std::size_t ci = 0; ci < clips.size(); ++ci) {
      const Clip& c = clips[ci];
      const std::vector<std::string> fid = frame_ids(c, s);
      for (int f = 0; f < c.frames; ++f) {
        std::vector<Tally*> in_frame;  // the tallies this frame has a marker in
        for (std::size_t m = 0; m < fid.size(); ++m) {
          const Truth& t = truths[ci][f][m];
          const Seen& o = seen[ci][f][s][m];
          const double relative = 100 * o.translation_m / t.distance;
          markers_csv.row(name, families[s], kSets[c.set], kInfo[c.condition].name, c.index, f, int(m), fid[m],
                          kSubsetNames[t.subset], t.center.x, t.center.y, t.edge, t.tilt, t.distance, t.blur, t.bend,
                          t.occluded, int(o.found), o.wrong, o.translation_m, relative, o.rotation_deg);
          for (int cond : {c.condition, int(kConditions)}) {
            if (cond == kConditions && t.subset != kVisible) continue;  // "all": visible markers only
            Tally& k = tally[c.set][cond][t.subset];
            if (std::find(in_frame.begin(), in_frame.end(), &k) == in_frame.end()) in_frame.push_back(&k), ++k.frames;
            ++k.markers;
            k.found += o.found;
            k.wrong += o.wrong;
            if (o.found && std::isfinite(o.rotation_deg) && std::isfinite(relative)) {
              k.translation_pct.push_back(relative);
              k.rotation_deg.push_back(o.rotation_deg);
            }
          }
        }
      }
    }
    for (int set = 0; set < 2; ++set)
      for (int cond = 0; cond <= kConditions; ++cond)
        for (int sub = 0; sub < kSubsets; ++sub) {
          const Tally& k = tally[set][cond][sub];
          if (k.markers == 0) continue;
          summary_csv.row(name, families[s], kSets[set], cond == kConditions ? "all" : kInfo[cond].name,
                          kSubsetNames[sub], k.frames, k.markers, k.found, 100.0 * k.found / k.markers, k.wrong,
                          int(k.translation_pct.size()), quantile(k.translation_pct, 0.5),
                          quantile(k.translation_pct, 0.9), quantile(k.rotation_deg, 0.5),
                          quantile(k.rotation_deg, 0.9));
        }
    for (int cond = 0; cond < kConditions; ++cond) {
      // Per set, then both sets together.
      std::vector<double> both = times[s][cond][0];
      both.insert(both.end(), times[s][cond][1].begin(), times[s][cond][1].end());
      for (int set = 0; set < 3; ++set) {
        const std::vector<double>& v = set < 2 ? times[s][cond][set] : both;
        if (v.empty()) continue;
        const double mean = std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
        times_csv.row(name, families[s], set < 2 ? kSets[set] : "both", kInfo[cond].name, kInfo[cond].size.width,
                      kInfo[cond].size.height, int(v.size()) / plan.passes, int(v.size()), mean, quantile(v, 0.5),
                      quantile(v, 0.99));
      }
    }
  }
  return true;
}

}  // namespace bench
