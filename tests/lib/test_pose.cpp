// SPDX-License-Identifier: LGPL-2.1-or-later
// Final pose from all n^2 centroids (src/detect/pose.cpp), on rendered scenes with known poses.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>

#include "../../src/core/rotation.hpp"
#include "binary.hpp"
#include "lftag/render.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::Candidate;
using lftag::detail::Decoding;
using lftag::detail::KeyPoints;

namespace {

using lftag::test::rotation;
using lftag::test::rotation_error_deg;

struct Case {
  int n;
  TagId id;
  double roll, tilt, pan;
  bool distortion;
  double pixels = 100;  // marker size in the image
  double noise = 0;     // grey levels
};

struct Posed {
  cv::Mat1b image;
  SceneMarker marker;
  MarkerTruth truth;
  Camera camera;
  Candidate candidate;
  Decoding decoding;
};

// Renders the marker, runs the stages before the pose on it (a global threshold between
// ink and paper, the candidate, the true key points, the decoding) and checks that they
// found it.
std::optional<Posed> prepare(const Case& c) {
  Posed p;
  SceneParams sp;
  sp.camera = Camera::pinhole(500, 500, 319.5, 239.5, 640, 480);
  if (c.distortion) sp.camera.distortion = {-0.25, 0.08, 0.001, -0.001, 0};
  sp.background = 0.8;
  sp.noise_sigma = c.noise;
  p.marker.family = Family(c.n);
  p.marker.id = c.id;
  p.marker.tag_size = 0.2;
  p.marker.tvec = {0.05, -0.03, 0.2 * 500 / c.pixels};
  p.marker.rvec = rotation(c.roll, c.tilt, c.pan);
  p.camera = sp.camera;
  const RenderedScene scene = render_scene(sp, {p.marker});
  p.truth = scene.truth[0];
  EXPECT_TRUE(p.truth.fully_visible);

  const cv::Mat1b& image = p.image = scene.image;
  const int level = int(255 * (p.marker.white + p.marker.black) / 2);
  const detail::BinaryImage binary = test::binary_from_mask(image < level);
  detail::RegionTree tree;
  detail::RegionLabeller().label(binary, tree);
  DetectorParams params;
  params.families = {p.marker.family};
  std::vector<Candidate> out;
  DetectionStats stats;
  detail::find_candidates(tree, binary, ImageView(image), params, p.camera, out, stats);
  EXPECT_EQ(out.size(), 1u);
  if (out.size() != 1) return std::nullopt;
  p.candidate = out[0];
  KeyPoints k;
  for (int i = 0; i < 4; ++i) {
    int best = 0;
    for (int j = 1; j < int(p.candidate.blobs.size()); ++j)
      if (cv::norm(p.candidate.blobs[j].centroid - p.truth.keypoints[i]) <
          cv::norm(p.candidate.blobs[best].centroid - p.truth.keypoints[i]))
        best = j;
    k.blob[i] = best;
  }
  const auto d = detail::decode(p.candidate, k, ImageView(image), p.camera, params, stats, nullptr);
  EXPECT_TRUE(d.has_value());
  if (!d) return std::nullopt;
  EXPECT_EQ(d->id, c.id);
  p.decoding = *d;
  return p;
}

DetectorParams pose_params(double tag_size, bool refine = true) {
  DetectorParams params;
  params.tag_size = tag_size;
  params.refine_pose = refine;
  return params;
}

std::string describe(const Case& c) {
  return Family(c.n).name() + " id " + c.id.to_decimal() + " roll " + std::to_string(c.roll) + " tilt " +
         std::to_string(c.tilt) + " pan " + std::to_string(c.pan) + (c.distortion ? " distorted" : "");
}

const Case kCases[] = {
    {3, 6789, 0, 35, 0, false},      {3, 4321, 25, 30, 20, false},
    {3, 16000, -70, 40, -10, false}, {4, 123456, 10, -35, 15, false},
    {4, 98765, 130, 30, -25, false}, {3, 777, 15, 35, 10, true},
    {4, 2718281, -40, 30, 20, true}, {6, TagId::parse("0x1234567890abcdef1"), 60, 35, 0, false, 160},
};

}  // namespace

TEST(ProjectPinhole, IsWhatOpenCVProjectsWithoutDistortion) {
  // Random poses in front of the camera and behind it, points on and off the plane:
  // the same bits as cv::projectPoints.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const cv::Matx33d k(900, 0, 641.5, 0, 880, 359.25, 0, 0, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const cv::Vec3d rvec(2 * u(rng), 2 * u(rng), 2 * u(rng)), tvec(u(rng), u(rng), 3 * u(rng) + 0.5);
    std::vector<cv::Point3d> object;
    for (int i = 0; i < 16; ++i) object.emplace_back(0.1 * u(rng), 0.1 * u(rng), i % 4 == 0 ? 0.05 * u(rng) : 0.0);
    std::vector<cv::Point2d> expected;
    cv::projectPoints(object, rvec, tvec, k, cv::noArray(), expected);
    const std::vector<cv::Point2d> got = detail::project_pinhole(object, rvec, tvec, k);
    ASSERT_EQ(got.size(), expected.size());
    for (std::size_t i = 0; i < got.size(); ++i) {
      EXPECT_EQ(got[i].x, expected[i].x) << "trial " << trial << " point " << i;
      EXPECT_EQ(got[i].y, expected[i].y) << "trial " << trial << " point " << i;
    }
  }
}

TEST(Rotation, TurnsAsOpenCVsRodriguesDoes) {
  // Random turns, tiny ones and ones near half a turn (where the axis's sign is free, so
  // the vectors are compared as the rotations they make).
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 300; ++trial) {
    cv::Vec3d axis(u(rng), u(rng), u(rng));
    axis *= 1 / cv::norm(axis);
    const double angles[] = {0, 1e-17, 1e-9, std::abs(u(rng)) * CV_PI, CV_PI - 1e-9, CV_PI};
    const cv::Vec3d rvec = axis * angles[trial % 6];
    cv::Matx33d expected;
    cv::Rodrigues(rvec, expected);
    const cv::Matx33d got = detail::rotation_matrix(rvec);
    EXPECT_LT(cv::norm(got - expected, cv::NORM_INF), 1e-14) << "trial " << trial;
    cv::Matx33d back;
    cv::Rodrigues(detail::rotation_vector(got), back);
    EXPECT_LT(cv::norm(back - expected, cv::NORM_INF), 1e-12) << "trial " << trial;
    if (angles[trial % 6] < CV_PI - 1e-6) {
      EXPECT_LT(cv::norm(detail::rotation_vector(got) - rvec), 1e-12) << "trial " << trial;
    }
  }
}

TEST(Pose, TiltedMarkersGiveTheTruePose) {
  // ~100 px markers tilted 30-40 degrees: rotation within 1 degree, translation within 1 %
  // of the distance, with and without lens distortion.
  for (const Case& c : kCases) {
    const std::string what = describe(c);
    const auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), det))
        << what;
    const double distance = cv::norm(p->marker.tvec);
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 1.0) << what;
    EXPECT_LT(cv::norm(det.tvec - p->marker.tvec), 0.01 * distance)
        << what << ": " << det.tvec << " vs " << p->marker.tvec;
    EXPECT_LT(det.reprojection_error, 0.1) << what;
    // In fact far better on these clean renders, where only the centroids' pixel
    // quantisation remains (and the perspective bias of centroids, which the pose removes).
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 0.15) << what;
    EXPECT_LT(cv::norm(det.tvec - p->marker.tvec), 0.001 * distance) << what;
    EXPECT_LT(det.reprojection_error, 0.05) << what;
    EXPECT_EQ(det.tag_size, p->marker.tag_size);
    EXPECT_TRUE(det.calibrated) << what;
  }
}

TEST(Pose, CornersAndCentreAreTheProjectedTruth) {
  for (const Case& c : kCases) {
    const std::string what = describe(c);
    const auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), det));
    ASSERT_EQ(p->truth.corners.size(), 4u);
    // Within 0.1 px (the perspective bias of the blob centroids, up to 0.2 px here, removed).
    for (int i = 0; i < 4; ++i)
      EXPECT_LT(cv::norm(det.corners[i] - p->truth.corners[i]), 0.1) << what << " corner " << i;
    const cv::Point2d centre = p->camera.project({cv::Point3d(0, 0, 0)}, p->marker.rvec, p->marker.tvec)[0];
    EXPECT_LT(cv::norm(det.center - centre), 0.03) << what;
    // The corners are the pose's own projection (distortion included) of the outer border.
    const std::vector<cv::Point2d> own = p->camera.project(
        {cv::Point3d(-0.1, -0.1, 0), cv::Point3d(0.1, -0.1, 0), cv::Point3d(0.1, 0.1, 0), cv::Point3d(-0.1, 0.1, 0)},
        det.rvec, det.tvec);
    for (int i = 0; i < 4; ++i) EXPECT_LT(cv::norm(det.corners[i] - own[i]), 1e-9) << what;
  }
}

TEST(Pose, WithoutRefinementStillClose) {
  for (const Case& c : {kCases[0], kCases[3], kCases[5]}) {
    const std::string what = describe(c);
    const auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(0.2, false), det));
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 2.0) << what;
    EXPECT_LT(cv::norm(det.tvec - p->marker.tvec), 0.02 * cv::norm(p->marker.tvec)) << what;
  }
}

TEST(Pose, CalibratedFlagFollowsTheCamera) {
  const auto p = prepare(kCases[1]);
  ASSERT_TRUE(p);
  Camera guessed = p->camera;
  guessed.calibrated = false;
  Detection a, b;
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(0.2), a));
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, guessed, pose_params(0.2), b));
  EXPECT_TRUE(a.calibrated);
  EXPECT_FALSE(b.calibrated);
  // The flag is all that differs.
  EXPECT_EQ(a.rvec, b.rvec);
  EXPECT_EQ(a.tvec, b.tvec);
}

TEST(Pose, TranslationScalesWithTheTagSize) {
  const auto p = prepare(kCases[2]);
  ASSERT_TRUE(p);
  Detection small, large;
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(0.2), small));
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(0.5), large));
  EXPECT_EQ(large.tag_size, 0.5);
  EXPECT_LT(rotation_error_deg(small.rvec, large.rvec), 1e-6);
  EXPECT_LT(cv::norm(large.tvec - small.tvec * 2.5), 1e-6 * cv::norm(large.tvec));
  // The image of the marker does not depend on the size assumed.
  for (int i = 0; i < 4; ++i) EXPECT_LT(cv::norm(large.corners[i] - small.corners[i]), 1e-6);
  EXPECT_LT(cv::norm(large.center - small.center), 1e-6);
}

TEST(Pose, AFocalLengthGuessKeepsTheImageButNotTheDistance) {
  // The default camera's guessed focal length (the frame width, 640 instead of 500): the
  // reprojected border still sits on the marker, the distance scales with the focal length.
  const auto p = prepare(kCases[0]);
  ASSERT_TRUE(p);
  const Camera guess = Camera::default_for(640, 480);
  // The candidate's points are undistorted pixels of the true camera; with no distortion
  // they are the same for the guess.
  Detection det;
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, guess, pose_params(0.2), det));
  EXPECT_FALSE(det.calibrated);
  EXPECT_NEAR(det.tvec[2], p->marker.tvec[2] * 640 / 500, 0.05 * p->marker.tvec[2] * 640 / 500);
  EXPECT_LT(det.reprojection_error, 0.2);
  for (int i = 0; i < 4; ++i) EXPECT_LT(cv::norm(det.corners[i] - p->truth.corners[i]), 1.5) << "corner " << i;
}

TEST(Pose, BothSolutionsOfATiltedMarkerAndWhichFitsBetter) {
  // ~100 px markers tilted 30 to 40 degrees: the other solution (the marker tilted the
  // other way) fits the centroids far worse (a ratio of 48 to 1,041 here) and is 60
  // degrees or more from the truth.
  for (const Case& c : kCases) {
    const std::string what = describe(c);
    const auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), det));
    EXPECT_GT(det.ambiguity_ratio, 20) << what;
    EXPECT_GT(det.alternative_reprojection_error, 0.5) << what;
    EXPECT_NEAR(det.ambiguity_ratio, det.alternative_reprojection_error / det.reprojection_error,
                1e-9 * det.ambiguity_ratio)
        << what;
    EXPECT_GT(rotation_error_deg(det.alternative_rvec, p->marker.rvec), 30) << what;
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 1.0) << what;
    EXPECT_GT(det.alternative_tvec[2], 0) << what;
  }
}

TEST(Pose, ASmallMarkerSeenFaceOnIsAmbiguous) {
  // 3x3 and 4x4 markers of 24 to 30 px, 3 to 4 degrees off face on: the flip fits the
  // centroids almost as well (ratios of 1.13, 2.63 and 1.006 here), which the ratio says;
  // the one chosen is within 1.5 degrees of the truth, and where the tilt shows (4
  // degrees) the other is not.
  struct Small {
    Case c;
    bool flip_shows;
  };
  for (const Small& s : {Small{{3, 6789, 20, 4, 0, false, 24}, true}, Small{{4, 123456, -35, 0, 4, false, 24}, true},
                         Small{{3, 4321, 70, 3, 3, false, 30}, false}}) {
    const std::string what = describe(s.c);
    const auto p = prepare(s.c);
    ASSERT_TRUE(p) << what;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), det));
    // Under 1 only where the squares' inks chose, within the shape choice ratio (1.006
    // here: the inks chose the other, 0.994).
    const double shapes = DetectorParams{}.shape_choice_ratio;
    EXPECT_GT(det.ambiguity_ratio, 1 / shapes) << what;
    EXPECT_LT(det.ambiguity_ratio, 3) << what;
    EXPECT_GT(det.alternative_reprojection_error, det.reprojection_error / shapes) << what;
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 1.5) << what;
    if (s.flip_shows) {
      EXPECT_GT(rotation_error_deg(det.alternative_rvec, p->marker.rvec), 4) << what;
    }
  }
}

namespace {

// A marker whose centroids cannot tell its two poses apart: each centroid halfway
// between its projections under the truth and under the truth's flip (the other
// solution of IPPE on the true projections), and its ink the foreshortening of
// `inked_by` predicts (area over depth cubed). Face-on ambiguity, made exact.
struct Constructed {
  Candidate candidate;
  Decoding decoding;
  Camera camera = Camera::pinhole(500, 500, 319.5, 239.5, 640, 480);
  cv::Vec3d rvec, tvec, flip_rvec, flip_tvec;
};

Constructed constructed(bool inked_by_truth) {
  Constructed k;
  const Family f(3);
  k.decoding.id = TagId(6789);
  k.rvec = rotation(20, 35, 10);
  k.tvec = {0.01, -0.02, 0.2 * 500 / 24};  // a 24 px marker of 0.2 m
  std::vector<cv::Point3d> object;
  for (int g = 0; g < f.cell_count(); ++g)
    object.push_back(f.to_marker_frame(f.center(g, f.is_baseline(g) ? 0 : k.decoding.id.digit(f.data_index(g))), 0.2));
  std::vector<cv::Point2d> truth, flip;
  cv::projectPoints(object, k.rvec, k.tvec, k.camera.matrix(), cv::noArray(), truth);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::solvePnPGeneric(object, truth, k.camera.matrix(), cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
  EXPECT_EQ(rvecs.size(), 2u);
  const int other = rotation_error_deg(cv::Vec3d(rvecs[0]), k.rvec) < 0.01 ? 1 : 0;
  k.flip_rvec = cv::Vec3d(rvecs[other]), k.flip_tvec = cv::Vec3d(tvecs[other]);
  EXPECT_GT(rotation_error_deg(k.flip_rvec, k.rvec), 20);
  cv::projectPoints(object, k.flip_rvec, k.flip_tvec, k.camera.matrix(), cv::noArray(), flip);
  cv::Matx33d r;
  cv::Rodrigues(inked_by_truth ? k.rvec : k.flip_rvec, r);
  const cv::Vec3d t = inked_by_truth ? k.tvec : k.flip_tvec;
  k.candidate.family = f;
  for (int g = 0; g < f.cell_count(); ++g) {
    detail::Blob b;
    b.point = b.centroid = (truth[g] + flip[g]) / 2;
    const UnitRect s = f.square(g, f.is_baseline(g) ? 0 : k.decoding.id.digit(f.data_index(g)));
    const double z = (r * cv::Vec3d(object[g].x, object[g].y, object[g].z) + t)[2];
    b.mass = 200 * s.width * s.height / (z * z * z);
    k.candidate.blobs.push_back(b);
    k.decoding.blob_of_cell.push_back(g);
  }
  return k;
}

}  // namespace

TEST(Pose, TheSquaresForeshorteningChoosesWhereTheCentroidsCannot) {
  // Tilted 35 degrees, but each centroid halfway between the truth's and the flip's: the
  // two solutions fit the centroids alike (a ratio near 1), and the squares' inks, made
  // by the truth's or by the flip's foreshortening, choose the one that made them.
  for (const bool by_truth : {true, false}) {
    const Constructed k = constructed(by_truth);
    const cv::Vec3d& made = by_truth ? k.rvec : k.flip_rvec;
    const cv::Vec3d& other = by_truth ? k.flip_rvec : k.rvec;
    DetectorParams params = pose_params(0.2);
    params.shape_choice_ratio = 1.5;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(k.candidate, k.decoding, k.camera, params, det));
    EXPECT_LT(det.ambiguity_ratio, 1.5) << by_truth;
    EXPECT_GT(det.ambiguity_ratio, 1 / 1.5) << by_truth;
    EXPECT_LT(rotation_error_deg(det.rvec, made), rotation_error_deg(det.rvec, other)) << by_truth;
    EXPECT_LT(rotation_error_deg(det.alternative_rvec, other), rotation_error_deg(det.alternative_rvec, made))
        << by_truth;
    // By the centroids alone the two choices are the same whichever foreshortening made
    // the inks: the inks are all that changed.
    params.shape_choice_ratio = 0;
    Detection plain;
    ASSERT_TRUE(detail::estimate_pose(k.candidate, k.decoding, k.camera, params, plain));
    EXPECT_GE(plain.ambiguity_ratio, 1) << by_truth;
    const Constructed swapped = constructed(!by_truth);
    Detection plain_swapped;
    ASSERT_TRUE(detail::estimate_pose(swapped.candidate, swapped.decoding, swapped.camera, params, plain_swapped));
    EXPECT_EQ(plain.rvec, plain_swapped.rvec) << by_truth;
  }
}

TEST(Pose, TheShapesDoNotOverruleCentroidsThatDecide) {
  // The tilted 100 px markers' centroids decide (ratios of 20 and more): a shape choice
  // ratio of 3 leaves the choice to them, whatever the inks.
  for (const Case& c : kCases) {
    const std::string what = describe(c);
    auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    for (detail::Blob& b : p->candidate.blobs) b.mass = 1 + std::fmod(b.point.x * 7.3, 1.0);  // unrelated inks
    DetectorParams params = pose_params(p->marker.tag_size);
    params.shape_choice_ratio = 3;
    Detection det;
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, params, det)) << what;
    EXPECT_GT(det.ambiguity_ratio, 20) << what;
    EXPECT_LT(rotation_error_deg(det.rvec, p->marker.rvec), 1.0) << what;
  }
}

TEST(Pose, WithoutInksTheCentroidsChoose) {
  // An outline reading's blobs have no ink: the shapes cannot choose, and the pose is the
  // centroids' choice whatever the ratio asked.
  const Constructed k = constructed(true);
  Candidate inkless = k.candidate;
  for (detail::Blob& b : inkless.blobs) b.mass = 0;
  DetectorParams params = pose_params(0.2);
  Detection plain, asked;
  params.shape_choice_ratio = 0;
  ASSERT_TRUE(detail::estimate_pose(inkless, k.decoding, k.camera, params, plain));
  params.shape_choice_ratio = std::numeric_limits<double>::infinity();
  ASSERT_TRUE(detail::estimate_pose(inkless, k.decoding, k.camera, params, asked));
  EXPECT_EQ(plain.rvec, asked.rvec);
  EXPECT_GE(asked.ambiguity_ratio, 1);
}

TEST(Pose, RefinementReachesTheLeastSquaresOptimum) {
  // The nine centres of a 3x3's squares, 25 to 120 px across at 720p, face on to 40
  // degrees of tilt, with 0.05 to 0.4 px of noise: from both of IPPE's solutions the
  // refinement ends where OpenCV's Levenberg-Marquardt run to exhaustion does, or lower.
  // With its default criteria that one stops short of it on some, nearly face on.
  const cv::Matx33d k(1280, 0, 640, 0, 1280, 360, 0, 0, 1);
  std::vector<cv::Point3d> object;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) object.emplace_back(-0.1 + 0.1 * c + 0.01 * (r % 2), -0.1 + 0.1 * r, 0);
  const auto cost = [&](const cv::Vec3d& rvec, const cv::Vec3d& tvec, const std::vector<cv::Point2d>& observed) {
    std::vector<cv::Point2d> projected;
    cv::projectPoints(object, rvec, tvec, k, cv::noArray(), projected);
    double sum = 0;
    for (std::size_t i = 0; i < observed.size(); ++i) sum += std::pow(cv::norm(projected[i] - observed[i]), 2);
    return sum;
  };
  int cases = 0, short_of_it = 0;
  std::mt19937 seed(3);
  std::normal_distribution<double> unit_noise(0, 1);
  for (const double pixels : {25.0, 40.0, 70.0, 120.0})
    for (const double tilt : {0.0, 2.0, 5.0, 10.0, 20.0, 40.0})
      for (const double noise : {0.05, 0.15, 0.4}) {
        const double radians = tilt * CV_PI / 180;
        const cv::Vec3d rvec(radians, 0.3 * radians, 0.4), tvec(0.1, -0.05, 0.25 * 1280 / pixels);
        std::vector<cv::Point2d> observed;
        cv::projectPoints(object, rvec, tvec, k, cv::noArray(), observed);
        for (cv::Point2d& o : observed) o += noise * cv::Point2d(unit_noise(seed), unit_noise(seed));
        std::vector<cv::Mat> rvecs, tvecs;
        cv::solvePnPGeneric(object, observed, k, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
        for (std::size_t s = 0; s < rvecs.size(); ++s) {
          const std::string what = std::to_string(pixels) + " px, tilt " + std::to_string(tilt) + ", noise " +
                                   std::to_string(noise) + ", solution " + std::to_string(s);
          cv::Vec3d r(rvecs[s]), t(tvecs[s]), r_cv = r, t_cv = t, r_default = r, t_default = t;
          detail::refine_pose(object, observed, k, r, t);
          cv::solvePnPRefineLM(object, observed, k, cv::noArray(), r_cv, t_cv,
                               cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100000, 1e-15));
          cv::solvePnPRefineLM(object, observed, k, cv::noArray(), r_default, t_default);
          const double ours = cost(r, t, observed), optimum = cost(r_cv, t_cv, observed);
          EXPECT_LE(ours, optimum * (1 + 1e-6) + 1e-12) << what;
          EXPECT_GT(t[2], 0) << what;
          ++cases;
          short_of_it += cost(r_default, t_default, observed) > optimum * 1.001;
        }
      }
  EXPECT_EQ(cases, 144);
  EXPECT_GT(short_of_it, 0);  // as refine_pose's comment says
}

TEST(Pose, TheBordersStrokeSharpensANoisyPose) {
  // 30 3x3 and 4x4 markers of 60 to 100 px, tilted up to 40 degrees, under noise of 10
  // grey levels: refined on the border's stroke as well as the centroids, the median
  // distance error falls by a third or more, and no marker's pose gets much worse.
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> with, without;
  for (int k = 0; k < 30; ++k) {
    const Family f(3 + k % 2);
    const Case c{f.n(), test::random_id(f, rng), 180 * u(rng), 40 * u(rng), 20 * u(rng), false, 80 + 20 * u(rng), 10};
    const std::string what = describe(c);
    const auto p = prepare(c);
    ASSERT_TRUE(p) << what;
    const detail::BorderEdges edges =
        detail::border_edges(ImageView(p->image), p->camera, f, p->decoding.homography, p->marker.tag_size);
    ASSERT_GT(edges.points.size(), 40u) << what;
    Detection joint, alone;
    ASSERT_TRUE(
        detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), joint, edges));
    ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, pose_params(p->marker.tag_size), alone));
    const double distance = cv::norm(p->marker.tvec);
    with.push_back(std::abs(cv::norm(joint.tvec) - distance) / distance);
    without.push_back(std::abs(cv::norm(alone.tvec) - distance) / distance);
    EXPECT_LT(with.back(), without.back() + 0.002) << what;
  }
  std::sort(with.begin(), with.end());
  std::sort(without.begin(), without.end());
  EXPECT_LT(with[15], without[15] * 2 / 3) << with[15] << " against " << without[15];
}

TEST(Pose, WhereTheStrokeDisagreesWithTheCentroidsTheCentroidsPoseStands) {
  // A marker whose border's stroke is seen 3 % further out than the centroids place it
  // (the sides of a sheet bent on a cylinder do so, nearer the camera than the plane
  // through the centroids): the centroids would fit far worse than their noise, so the
  // pose is theirs alone. The same stroke where the centroids put it refines the pose.
  auto p = prepare(kCases[1]);
  ASSERT_TRUE(p);
  std::mt19937_64 rng(23);
  std::normal_distribution<double> noise(0, 0.05);
  for (detail::Blob& b : p->candidate.blobs) b.point += cv::Point2d(noise(rng), noise(rng));
  const Family& f = p->marker.family;
  const auto stroke = [&](double scale) {
    detail::BorderEdges edges;
    const double s = f.side();
    for (int i = 0; i <= 16; ++i) {
      const double t = 3 + (s - 6) * i / 16;
      for (const cv::Point2d u : {cv::Point2d(t, 1), cv::Point2d(s - 1, t), cv::Point2d(t, s - 1), cv::Point2d(1, t)}) {
        const cv::Point3d object = f.to_marker_frame(u, p->marker.tag_size);
        const cv::Point3d seen =
            f.to_marker_frame((u - cv::Point2d(s / 2, s / 2)) * scale + cv::Point2d(s / 2, s / 2), p->marker.tag_size);
        const std::vector<cv::Point2d> q = p->camera.project({seen}, p->marker.rvec, p->marker.tvec);
        const cv::Point3d along = u.y == 1 || u.y == s - 1 ? cv::Point3d(1e-3, 0, 0) : cv::Point3d(0, 1e-3, 0);
        const std::vector<cv::Point2d> a = p->camera.project({object, object + along}, p->marker.rvec, p->marker.tvec);
        cv::Point2d normal(-(a[1] - a[0]).y, (a[1] - a[0]).x);
        edges.sides.push_back({object, q[0] + cv::Point2d(noise(rng), noise(rng)), normal / cv::norm(normal)});
      }
    }
    edges.noise = 0.05;
    return edges;
  };
  const DetectorParams params = pose_params(p->marker.tag_size);
  Detection alone, bent, flat;
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, params, alone));
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, params, bent, stroke(1.03)));
  ASSERT_TRUE(detail::estimate_pose(p->candidate, p->decoding, p->camera, params, flat, stroke(1.0)));
  EXPECT_EQ(bent.rvec, alone.rvec);
  EXPECT_EQ(bent.tvec, alone.tvec);
  EXPECT_NE(flat.tvec, alone.tvec);
  const double distance = cv::norm(p->marker.tvec);
  EXPECT_LT(cv::norm(flat.tvec - p->marker.tvec), 0.002 * distance);
  // The reprojection error and the ambiguity ratio stay the centroids' own fits'.
  EXPECT_EQ(flat.reprojection_error, alone.reprojection_error);
  EXPECT_EQ(flat.ambiguity_ratio, alone.ambiguity_ratio);
}
