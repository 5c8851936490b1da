// SPDX-License-Identifier: LGPL-2.1-or-later
// Markers in real video: printed sheets composited into opencv-doc's marker-free videos at
// 1280x720, four per frame, moving smoothly through one-second clips (30 frames), seen in
// perspective with camera shake, defocus, uneven light, exposure drift, sensor noise and
// JPEG compression. Every system sees the same clips, poses, frames and conditions; only
// the marker design differs. Recall, wrong detections, pose error and wrong choices of the
// planar pose's two solutions (trial.hpp's wrong_choice) per system, overall and by
// projected edge and by tilt.
#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <tuple>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "clip_source.hpp"
#include "csv.hpp"
#include "experiment.hpp"
#include "sources.hpp"
#include "systems.hpp"
#include "trial.hpp"

namespace bench {
namespace {

const cv::Size kFrameSize{1280, 720};
constexpr int kMarkers = 4;                         // per frame
constexpr double kTagSize = 0.1;                    // metres; only the poses' scale depends on it
constexpr double kSheet = 1 + 2 * kMarginFraction;  // printed sheet edge over tag size
constexpr double kMinEdge = 30, kMaxEdge = 220;     // projected tag edge, pixels (mean of four sides)
constexpr double kMaxTilt = 60;                     // degrees between the sheet's normal and the line of sight
constexpr double kMaxShake = 5;                     // pixels the camera shake moves the image, per frame
constexpr double kMaxDefocus = 1.5;                 // Gaussian sigma, pixels
constexpr double kMinNoise = 2, kMaxNoise = 4;      // grey levels
constexpr double kMaxGradient = 0.6;                // SceneParams::light_gradient
constexpr int kJpegQuality = 60;
constexpr double kGap = 4;  // pixels between the sheets' image boxes

struct Plan {
  int clips, frames;  // frames per clip
};
constexpr Plan kFull{24, 30}, kQuick{1, 10};

const std::vector<double> kEdgeBins{30, 60, 100, 160, 220};  // pixels
const std::vector<double> kTiltBins{0, 30, 45, 60};          // degrees

Placement random_placement(std::mt19937_64& rng, double edge) {
  return {{uniform(rng, 0, kFrameSize.width - 1), uniform(rng, 0, kFrameSize.height - 1)},
          edge,
          uniform(rng, 0, kMaxTilt),
          uniform(rng, 0, 360),
          uniform(rng, 0, 360)};
}

// Where the sheet has moved to at the end of the clip: up to 200 px away, 30 % nearer or
// farther, tilted by up to 20 degrees more or less, turned by up to 45 degrees.
Placement moved(const Placement& a, std::mt19937_64& rng) {
  Placement b = a;
  const double distance = uniform(rng, 0, 200), direction = uniform(rng, 0, 2 * CV_PI);
  b.center += distance * cv::Point2d(std::cos(direction), std::sin(direction));
  b.edge = std::clamp(a.edge * std::exp(uniform(rng, -0.3, 0.3)), kMinEdge, kMaxEdge);
  b.tilt = std::clamp(a.tilt + uniform(rng, -20, 20), 0.0, kMaxTilt);
  b.tilt_axis += uniform(rng, -45, 45);
  b.roll += uniform(rng, -45, 45);
  return b;
}

// The pose of a placement: facing the camera along the line of sight, tilted, rolled, at
// the distance along that line that gives the wanted edge.
Pose pose_of(const lftag::Camera& camera, const Placement& p) {
  const cv::Vec3d ray =
      cv::normalize(cv::Vec3d((p.center.x - camera.cx) / camera.fx, (p.center.y - camera.cy) / camera.fy, 1));
  const cv::Vec3d axis = cv::Vec3d(0, 0, 1).cross(ray);
  const double turn = std::asin(std::min(1.0, cv::norm(axis)));
  const cv::Matx33d to_ray = rotation_matrix(turn > 1e-12 ? axis * (turn / cv::norm(axis)) : cv::Vec3d());
  const double d = CV_PI / 180;
  const cv::Matx33d tilt =
      rotation_matrix(cv::Vec3d(std::cos(p.tilt_axis * d), std::sin(p.tilt_axis * d), 0) * (p.tilt * d));
  Pose pose;
  cv::Rodrigues(to_ray * tilt * rotation_matrix({0, 0, p.roll * d}), pose.rvec);
  // The edge is nearly inverse to the distance (not quite, once tilted): a few corrections.
  double distance = camera.fx * kTagSize / p.edge;
  for (int i = 0; i < 3; ++i) {
    pose.tvec = ray * distance;
    distance *= edge_px(camera, pose, kTagSize) / p.edge;
  }
  pose.tvec = ray * distance;
  return pose;
}

// Camera shake: a small turn of the camera about its centre, so that the truth stays exact
// for the markers and the background (a distant scene) moves by a homography. Up to
// kMaxShake - 1 px of shift in any direction and a roll moving the frame corners by up
// to 1 px.
cv::Matx33d random_shake(const lftag::Camera& camera, std::mt19937_64& rng) {
  const double shift = (kMaxShake - 1) * std::sqrt(uniform(rng, 0, 1)), direction = uniform(rng, 0, 2 * CV_PI);
  const double roll = uniform(rng, -1, 1) / std::hypot(camera.cx, camera.cy);
  const double dx = shift * std::cos(direction), dy = shift * std::sin(direction);
  return rotation_matrix({-std::atan(dy / camera.fy), std::atan(dx / camera.fx), roll});
}

// The image box of a sheet (tag and margin), or an empty box when it leaves the frame.
cv::Rect2d sheet_box(const lftag::Camera& camera, const Pose& pose) {
  const double h = kTagSize * kSheet / 2;
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (const cv::Point2d& c : camera.project({{-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0}}, pose.rvec, pose.tvec))
    x0 = std::min(x0, c.x), y0 = std::min(y0, c.y), x1 = std::max(x1, c.x), y1 = std::max(y1, c.y);
  if (x0 < 1 || y0 < 1 || x1 > camera.width - 2 || y1 > camera.height - 2) return {};
  return {x0 - kGap / 2, y0 - kGap / 2, x1 - x0 + kGap, y1 - y0 + kGap};
}

// One clip: a stretch of one video and everything drawn for it.
struct Clip {
  int source = 0, start = 0;  // video and its first frame
  double defocus = 0, noise = 0, gradient = 0, light_angle = 0;
  double exposure = 1, drift = 0, drift_phase = 0;  // exposure * (1 + drift * sin(...)) per frame
  std::vector<cv::Matx33d> shake;                   // per frame
  std::vector<std::vector<Pose>> poses;             // per frame and marker, shake included
};

// Draws a clip. Sheets are placed largest first; a placement that leaves the frame or
// overlaps an earlier sheet in any frame is drawn again, and a clip where one cannot be
// placed is drawn again whole with new sizes.
Clip plan_clip(const lftag::Camera& camera, const std::vector<Source>& videos, int clip, int frames,
               std::uint64_t seed) {
  std::mt19937_64 rng = seeded(seed, {0x71de0, std::uint64_t(clip)});
  Clip c;
  c.source = clip % int(videos.size());
  c.start = std::uniform_int_distribution<int>(0, std::max(0, videos[c.source].frames - frames))(rng);
  c.defocus = uniform(rng, 0, kMaxDefocus);
  c.noise = uniform(rng, kMinNoise, kMaxNoise);
  c.gradient = uniform(rng, 0, kMaxGradient);
  c.light_angle = uniform(rng, 0, 360);
  c.exposure = uniform(rng, 0.6, 1.0);
  c.drift = uniform(rng, 0, 0.1);
  c.drift_phase = uniform(rng, 0, 2 * CV_PI);
  for (int f = 0; f < frames; ++f) c.shake.push_back(random_shake(camera, rng));

  for (int attempt = 0; attempt < 1000; ++attempt) {
    std::vector<double> edges(kMarkers);
    for (double& e : edges) e = std::exp(uniform(rng, std::log(kMinEdge), std::log(kMaxEdge)));
    std::sort(edges.rbegin(), edges.rend());
    c.poses.assign(frames, {});
    std::vector<std::vector<cv::Rect2d>> boxes(frames);
    int placed = 0;
    for (int m = 0; m < kMarkers; ++m) {
      for (int k = 0; k < 300 && placed == m; ++k) {
        const Placement a = random_placement(rng, edges[m]), b = moved(a, rng);
        std::vector<Pose> poses;
        std::vector<cv::Rect2d> box;
        for (int f = 0; f < frames; ++f) {
          const double s = frames > 1 ? double(f) / (frames - 1) : 0;
          const Pose p = shaken(pose_of(camera, between(a, b, s)), c.shake[f]);
          const cv::Rect2d r = sheet_box(camera, p);
          auto overlaps = [&](const cv::Rect2d& o) { return !(o & r).empty(); };
          if (r.empty() || std::any_of(boxes[f].begin(), boxes[f].end(), overlaps)) break;
          poses.push_back(p);
          box.push_back(r);
        }
        if (int(poses.size()) < frames) continue;
        for (int f = 0; f < frames; ++f) c.poses[f].push_back(poses[f]), boxes[f].push_back(box[f]);
        ++placed;
      }
      if (placed == m) break;
    }
    if (placed == kMarkers) return c;
  }
  throw std::logic_error("video: cannot place the sheets of clip " + std::to_string(clip));
}

// The frame the sheets are composited over: the video frame scaled to cover the frame
// size, moved by the camera shake (K S K^-1: a turn of the camera about its centre).
cv::Mat1b background(const cv::Mat1b& frame, const lftag::Camera& camera, const cv::Matx33d& shake) {
  const cv::Matx33d k = camera.matrix();
  cv::Mat1b out;
  cv::warpPerspective(cover(frame, kFrameSize), out, cv::Mat(k * shake * k.inv()), kFrameSize, cv::INTER_LINEAR,
                      cv::BORDER_REFLECT);
  return out;
}

// Optics, sensor and codec after the scene: defocus, noise and 8 bits (the renderer's
// quantize, seeded per frame so that every system gets the same noise), then JPEG.
cv::Mat1b camera_output(const lftag::SceneRenderer& renderer, cv::Mat1f linear, double defocus,
                        std::uint64_t noise_seed) {
  if (defocus > 0.05) cv::GaussianBlur(linear, linear, cv::Size(), defocus);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", renderer.quantize(linear, noise_seed), jpeg, {cv::IMWRITE_JPEG_QUALITY, kJpegQuality});
  return cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE);
}

// One marker in one frame, as the truth has it and as one system saw it.
struct Truth {
  double edge, tilt, distance;
};
struct Seen {
  bool found = false;
  int wrong = 0;  // wrong detections in the frame whose centre is nearest this marker
  double rotation_deg = kNaN, translation_m = kNaN, depth_m = kNaN;
  double alternative_rotation_deg = kNaN;   // of the planar pose's other solution
  bool wrong_choice = false, flip = false;  // trial.hpp's
};

// The same slot carries the same marker through a clip; ids repeat after kIds slots.
constexpr int kIds = 30;
const std::string& marker_id(const std::vector<std::string>& ids, int clip, int slot) {
  return ids[std::size_t(clip * kMarkers + slot) % ids.size()];
}

struct Job {
  int clip, frame;
};

// The renderer of frame f of a clip: its lighting over the shaken video frame `source`.
lftag::SceneRenderer frame_renderer(const Clip& clip, int f, int frames, const cv::Mat1b& source,
                                    const lftag::Camera& camera) {
  lftag::SceneParams params;
  params.camera = camera;
  params.photo = background(source, camera, clip.shake[f]);
  params.exposure = clip.exposure * (1 + clip.drift * std::sin(2 * CV_PI * f / frames + clip.drift_phase));
  params.light_gradient = clip.gradient;
  params.light_angle_deg = clip.light_angle;
  params.noise_sigma = clip.noise;
  return lftag::SceneRenderer(params);
}

// One noise field per frame for every system (non-zero: zero selects params.seed).
std::uint64_t frame_noise_seed(std::uint64_t seed, int clip, int f) {
  return seeded(seed, {0x7015e, std::uint64_t(clip), std::uint64_t(f)})() | 1;
}

// Frame f of a clip as `system`'s camera delivers it, its markers `frame_ids` by slot.
cv::Mat1b frame_image(const lftag::SceneRenderer& renderer, const Clip& clip, int f, const FiducialSystem& system,
                      const std::vector<std::string>& frame_ids, std::uint64_t noise_seed) {
  std::vector<lftag::SceneTarget> targets;
  for (int m = 0; m < kMarkers; ++m)
    targets.push_back(system.target(frame_ids[m], kTagSize, clip.poses[f][m].rvec, clip.poses[f][m].tvec));
  return camera_output(renderer, renderer.render_linear(targets), clip.defocus, noise_seed);
}

int bin_of(const std::vector<double>& edges, double value) {
  const auto it = std::upper_bound(edges.begin() + 1, edges.end() - 1, value);
  return int(it - edges.begin()) - 1;  // values beyond the ends count in the end bins
}

std::string bin_name(const std::vector<double>& edges, int b) {
  auto text = [](double v) { return std::to_string(int(std::lround(v))); };
  return text(edges[b]) + "-" + text(edges[b + 1]);
}

// The frame as the system saw it, for a look at what it missed: named by system, clip
// and frame, with each missed slot and the image point of its centre in the name.
void save_miss(const std::filesystem::path& dir, const std::string& system, const Job& job, const cv::Mat1b& image,
               const std::vector<cv::Point2d>& centers, const std::vector<Seen>& seen) {
  std::string name = system + "-clip" + std::to_string(job.clip) + "-frame" + std::to_string(job.frame);
  for (int m = 0; m < kMarkers; ++m)
    if (!seen[m].found) {
      const cv::Point2d& c = centers[m];
      name += "-missed" + std::to_string(m) + "@" + std::to_string(int(std::lround(c.x))) + "," +
              std::to_string(int(std::lround(c.y)));
    }
  cv::imwrite((dir / (name + ".png")).string(), image);
}

std::vector<Source> video_sources(const Options& options) {
  std::vector<Source> videos;
  for (const Source& s : list_sources(options.data))
    if (s.video) videos.push_back(s);
  if (videos.empty()) throw std::runtime_error("no videos in " + options.data.string() + " (install opencv-doc)");
  return videos;
}

class VideoClips final : public ClipSource {
 public:
  explicit VideoClips(const Options& options)
      : plan_(options.quick ? kQuick : kFull),
        seed_(options.seed),
        videos_(video_sources(options)),
        camera_(lftag::Camera::default_for(kFrameSize.width, kFrameSize.height)),
        reader_(videos_) {
    for (int c = 0; c < plan_.clips; ++c) clips_.push_back(plan_clip(camera_, videos_, c, plan_.frames, seed_));
    // Videos are read forward: clip indices in the order of their source and start.
    for (int c = 0; c < plan_.clips; ++c) order_.push_back(c);
    std::sort(order_.begin(), order_.end(), [&](int a, int b) {
      return std::make_pair(clips_[a].source, clips_[a].start) < std::make_pair(clips_[b].source, clips_[b].start);
    });
  }
  int size() const override { return plan_.clips; }
  RenderedClip render(int index, const std::vector<std::unique_ptr<FiducialSystem>>& systems) override {
    const int c = order_[std::size_t(index)];
    const Clip& clip = clips_[c];
    RenderedClip out;
    out.set = videos_[clip.source].path.filename() == "vtest.avi" ? "validation" : "tuning";
    out.condition = "video";
    out.index = c;
    out.camera = camera_;
    out.tag_size = kTagSize;
    out.fps = 30;
    out.poses = clip.poses;
    out.visible.assign(clip.poses.size(), std::vector<bool>(kMarkers, true));
    for (const auto& system : systems) {
      const std::vector<std::string> test_ids = system->marker_ids(kIds, seed_);
      out.ids.emplace_back();
      for (int m = 0; m < kMarkers; ++m) out.ids.back().push_back(marker_id(test_ids, c, m));
    }
    out.images.resize(systems.size());
    for (int f = 0; f < plan_.frames; ++f) {
      cv::Mat1b frame;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        frame = reader_.read(clip.source, clip.start + f);
      }
      const lftag::SceneRenderer renderer = frame_renderer(clip, f, plan_.frames, frame, camera_);
      const std::uint64_t noise = frame_noise_seed(seed_, c, f);
      for (std::size_t s = 0; s < systems.size(); ++s)
        out.images[s].push_back(frame_image(renderer, clip, f, *systems[s], out.ids[s], noise));
    }
    return out;
  }

 private:
  Plan plan_;
  std::uint64_t seed_;
  std::vector<Source> videos_;
  lftag::Camera camera_;
  std::vector<Clip> clips_;
  std::vector<int> order_;
  std::mutex mutex_;  // guards the reader
  FrameReader reader_;
};

}  // namespace

std::unique_ptr<ClipSource> video_clips(const Options& options) { return std::make_unique<VideoClips>(options); }

bool run_video(const Options& options) {
  const Plan plan = options.quick ? kQuick : kFull;
  const std::vector<Source> videos = video_sources(options);
  const lftag::Camera camera = lftag::Camera::default_for(kFrameSize.width, kFrameSize.height);

  std::vector<Clip> clips;
  for (int c = 0; c < plan.clips; ++c) clips.push_back(plan_clip(camera, videos, c, plan.frames, options.seed));
  std::vector<Job> jobs;
  for (int c = 0; c < plan.clips; ++c)
    for (int f = 0; f < plan.frames; ++f) jobs.push_back({c, f});
  // Videos are read forward: take the frames in the order of their source and position.
  std::sort(jobs.begin(), jobs.end(), [&](const Job& a, const Job& b) {
    return std::make_tuple(clips[a.clip].source, clips[a.clip].start + a.frame, a.clip) <
           std::make_tuple(clips[b.clip].source, clips[b.clip].start + b.frame, b.clip);
  });

  const int n = int(options.systems.size());
  std::vector<std::vector<Truth>> truth(jobs.size());
  // job, system, marker
  std::vector<std::vector<std::vector<Seen>>> seen(jobs.size(), std::vector<std::vector<Seen>>(n));
  std::vector<std::vector<std::string>> ids(n);
  std::vector<std::string> families(n);
  std::vector<std::map<std::string, double>> counters(n);
  FrameReader reader(videos);
  std::mutex mutex;  // guards the reader, the next job and the tallies
  std::size_t next = 0;
  parallel_for(options.threads, options.threads, [&](int, int) {
    std::vector<std::unique_ptr<FiducialSystem>> systems;
    std::vector<std::vector<std::string>> test_ids;
    for (int s = 0; s < n; ++s) {
      systems.push_back(make_system(options.systems[s]));
      systems.back()->set_camera(camera, kTagSize);
      systems.back()->reset_counters();
      test_ids.push_back(systems.back()->marker_ids(kIds, options.seed));
    }
    for (;;) {
      std::size_t j;
      cv::Mat1b frame;
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (next == jobs.size()) break;
        j = next++;
        frame = reader.read(clips[jobs[j].clip].source, clips[jobs[j].clip].start + jobs[j].frame);
        if (next % 60 == 0)
          progress("video: " + std::to_string(next) + " / " + std::to_string(jobs.size()) + " frames");
      }
      const Clip& clip = clips[jobs[j].clip];
      const int f = jobs[j].frame;
      const std::vector<Pose>& poses = clip.poses[f];
      const lftag::SceneRenderer renderer = frame_renderer(clip, f, plan.frames, frame, camera);
      const std::uint64_t noise_seed = frame_noise_seed(options.seed, jobs[j].clip, f);

      std::vector<cv::Point2d> centers;
      std::vector<double> tolerances;
      for (const Pose& p : poses) {
        truth[j].push_back({edge_px(camera, p, kTagSize), tilt_deg(p), cv::norm(p.tvec)});
        centers.push_back(camera.project({{0, 0, 0}}, p.rvec, p.tvec)[0]);
        tolerances.push_back(std::max(2.0, truth[j].back().edge / 4));  // as score()
      }
      for (int s = 0; s < n; ++s) {
        FiducialSystem& system = *systems[s];
        std::vector<std::string> frame_ids;
        for (int m = 0; m < kMarkers; ++m) frame_ids.push_back(marker_id(test_ids[s], jobs[j].clip, m));
        const cv::Mat1b image = frame_image(renderer, clip, f, system, frame_ids, noise_seed);
        const std::vector<Detected> detections = system.detect(image);
        std::vector<Seen>& out = seen[j][s];
        out.resize(kMarkers);
        for (int m = 0; m < kMarkers; ++m) {
          const Outcome o = score(detections, frame_ids[m], poses[m], kTagSize, camera);
          out[m].found = o.found;
          out[m].rotation_deg = o.rotation_error_deg;
          out[m].translation_m = o.translation_error_m;
          out[m].depth_m = o.depth_error_m;
          out[m].alternative_rotation_deg = o.alternative_rotation_error_deg;
          out[m].wrong_choice = wrong_choice(o);
          out[m].flip = flipped(o);
        }
        if (!options.save_misses.empty() && std::any_of(out.begin(), out.end(), [](const Seen& o) { return !o.found; }))
          save_miss(options.save_misses, options.systems[s], jobs[j], image, centers, out);
        // score() counts the other markers' detections as wrong for each marker; in a frame
        // of several, a detection is wrong when it is none of them. It is charged to the
        // marker it lies nearest.
        for (const Detected& d : detections) {
          int nearest = 0;
          bool matched = false;
          for (int m = 0; m < kMarkers; ++m) {
            const double distance = cv::norm(d.center - centers[m]);
            matched = matched || (d.id == frame_ids[m] && distance <= tolerances[m]);
            if (distance < cv::norm(d.center - centers[nearest])) nearest = m;
          }
          if (!matched) ++out[nearest].wrong;
        }
      }
    }
    std::lock_guard<std::mutex> lock(mutex);
    for (int s = 0; s < n; ++s) {
      for (const auto& [name, value] : systems[s]->counters()) counters[s][name] += value;
      families[s] = systems[s]->family();
      ids[s] = test_ids[s];
    }
  });

  Csv clips_csv(options.out / "video_clips.csv",
                {"clip", "video", "start_frame", "frames", "defocus_sigma_px", "noise_sigma", "light_gradient",
                 "light_angle_deg", "exposure", "exposure_drift"});
  for (int c = 0; c < plan.clips; ++c) {
    const Clip& k = clips[c];
    clips_csv.row(c, videos[k.source].path.filename().string(), k.start, plan.frames, k.defocus, k.noise, k.gradient,
                  k.light_angle, k.exposure, k.drift);
  }
  Csv markers_csv(options.out / "video.csv",
                  {"system", "family", "clip", "frame", "marker", "id", "edge_px", "tilt_deg", "distance_m", "found",
                   "wrong", "translation_error_m", "translation_error_pct", "depth_error_pct", "rotation_error_deg",
                   "alternative_rotation_error_deg", "wrong_choice"});
  Csv summary_csv(options.out / "video_summary.csv",
                  {"system", "family", "bin_kind", "bin", "markers", "found", "recall_pct", "wrong", "with_pose",
                   "median_translation_pct", "p90_translation_pct", "median_rotation_deg", "wrong_choices", "flips"});
  Csv counters_csv(options.out / "video_counters.csv", {"system", "frames", "counter", "value"});
  // Tallies per bin: "all", then the edge bins, then the tilt bins.
  struct Tally {
    int markers = 0, found = 0, wrong = 0, wrong_choices = 0, flips = 0;
    std::vector<double> translation_pct, rotation_deg;
  };
  const int edge_bins = int(kEdgeBins.size()) - 1, tilt_bins = int(kTiltBins.size()) - 1;
  for (int s = 0; s < n; ++s) {
    const std::string& name = options.systems[s];
    std::vector<Tally> tally(1 + edge_bins + tilt_bins);
    for (std::size_t j = 0; j < jobs.size(); ++j)
      for (int m = 0; m < kMarkers; ++m) {
        const Truth& t = truth[j][m];
        const Seen& o = seen[j][s][m];
        const double relative = 100 * o.translation_m / t.distance;
        markers_csv.row(name, families[s], jobs[j].clip, jobs[j].frame, m, marker_id(ids[s], jobs[j].clip, m), t.edge,
                        t.tilt, t.distance, int(o.found), o.wrong, o.translation_m, relative,
                        100 * o.depth_m / t.distance, o.rotation_deg, o.alternative_rotation_deg, int(o.wrong_choice));
        for (int b : {0, 1 + bin_of(kEdgeBins, t.edge), 1 + edge_bins + bin_of(kTiltBins, t.tilt)}) {
          Tally& k = tally[b];
          ++k.markers;
          k.found += o.found;
          k.wrong += o.wrong;
          k.wrong_choices += o.wrong_choice;
          k.flips += o.flip;
          if (o.found && std::isfinite(o.rotation_deg) && std::isfinite(relative)) {
            k.translation_pct.push_back(relative);
            k.rotation_deg.push_back(o.rotation_deg);
          }
        }
      }
    for (int b = 0; b < int(tally.size()); ++b) {
      const Tally& k = tally[b];
      const bool edge = b >= 1 && b <= edge_bins;
      const std::string kind = b == 0 ? "all" : edge ? "edge_px" : "tilt_deg";
      const std::string bin = b == 0 ? "all"
                              : edge ? bin_name(kEdgeBins, b - 1)
                                     : bin_name(kTiltBins, b - 1 - edge_bins);
      summary_csv.row(name, families[s], kind, bin, k.markers, k.found, k.markers ? 100.0 * k.found / k.markers : kNaN,
                      k.wrong, int(k.translation_pct.size()), quantile(k.translation_pct, 0.5),
                      quantile(k.translation_pct, 0.9), quantile(k.rotation_deg, 0.5), k.wrong_choices, k.flips);
    }
    for (const auto& [counter, value] : counters[s]) counters_csv.row(name, int(jobs.size()), counter, value);
  }
  return true;
}

}  // namespace bench
