// SPDX-License-Identifier: LGPL-2.1-or-later
// Border proposals (src/detect/borders.cpp): where a marker's black border may lie, from
// the frame's binary image and grey levels, on markers whose inside the topology loses.
#include <gtest/gtest.h>

#include <functional>
#include <random>

#include <opencv2/imgproc.hpp>

#include "lftag/detector.hpp"
#include "lftag/render.hpp"
#include "lftag/trace.hpp"
#include "scenes.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::BorderProposal;
using lftag::test::random_id;
using lftag::test::rotation;

namespace {

const Camera kCamera = Camera::pinhole(800, 800, 319.5, 239.5, 640, 480);

struct Case {
  cv::Mat1b image;
  MarkerTruth truth;
};

// The printed sheet at ten albedo pixels a unit, with the point of unit (u, v).
struct Sheet {
  cv::Mat1f& albedo;
  static constexpr int kPerUnit = 10, kMargin = 2;
  cv::Point at(double u, double v) const {
    return {int(std::lround((kMargin + u) * kPerUnit)), int(std::lround((kMargin + v) * kPerUnit))};
  }
};

// How a marker is seen: its tilt (degrees, about a random axis, some 25 by default), a
// defocus (Gaussian, px), the sheet bent round a cylinder (radius, m; 0: flat).
struct View {
  double tilt = -1, defocus = 0, bend_radius = 0;
};

// A marker of family n about `pixels` across, turned and tilted, with its white margin
// of two units on a mid-grey ground; `print` edits the printed sheet, `light` the light
// falling on the frame (linear, before the noise and the 8 bits).
Case render(int n, double pixels, std::mt19937_64& rng, const std::function<void(Sheet)>& print = {},
            const std::function<void(cv::Mat1f&, const MarkerTruth&)>& light = {}, View view = {}) {
  std::uniform_real_distribution<double> u(-1, 1);
  SceneMarker m;
  m.family = Family(n);
  m.id = random_id(m.family, rng);
  m.tag_size = 0.1;
  const double z = kCamera.fx * 0.1 / pixels;
  m.tvec = {0.2 * u(rng) * z / 10, 0.2 * u(rng) * z / 10, z};
  const double tilt = view.tilt >= 0 ? view.tilt : 25 + 10 * u(rng), axis = 180 * u(rng);
  m.rvec = rotation(180 * u(rng), tilt * std::cos(axis * CV_PI / 180), tilt * std::sin(axis * CV_PI / 180));
  SceneParams p;
  p.camera = kCamera;
  p.background = 0.35;
  p.noise_sigma = 2;
  const SceneRenderer renderer(p);
  SceneTarget target = to_target(m);
  target.bend_radius = view.bend_radius;
  cv::resize(target.albedo, target.albedo, cv::Size(), Sheet::kPerUnit, Sheet::kPerUnit, cv::INTER_NEAREST);
  target.cell_size /= Sheet::kPerUnit;
  if (print) print(Sheet{target.albedo});
  cv::Mat1f linear = renderer.render_linear({target});
  if (view.defocus > 0) cv::GaussianBlur(linear, linear, cv::Size(), view.defocus);
  Case c{cv::Mat1b(), make_truth(kCamera, m)};
  if (light) light(linear, c.truth);
  c.image = renderer.quantize(linear, rng());
  return c;
}

std::vector<BorderProposal> proposals_of(const cv::Mat1b& image, const std::vector<Family>& families) {
  detail::BinaryImage binary;
  cv::Mat mean;
  detail::threshold_mean(ImageView(image), 16, 4, mean, binary);
  detail::RegionTree tree;
  detail::RegionLabeller().label(binary, tree);
  return detail::propose_borders(tree, ImageView(image), detail::SecondLook{}, families, {});
}

// The largest distance of a proposal's corner from the truth's outer corner, in the
// turn that fits best.
double corner_error(const BorderProposal& p, const MarkerTruth& t) {
  double best = 1e9;
  for (int turn = 0; turn < 4; ++turn) {
    double worst = 0;
    for (int i = 0; i < 4; ++i) worst = std::max(worst, cv::norm(p.corners[(i + turn) % 4] - t.corners[i]));
    best = std::min(best, worst);
  }
  return best;
}

// The proposal at the marker, if any: the one whose corners lie nearest the truth's.
const BorderProposal* at_marker(const std::vector<BorderProposal>& proposals, const MarkerTruth& t) {
  const BorderProposal* best = nullptr;
  for (const BorderProposal& p : proposals)
    if (!best || corner_error(p, t) < corner_error(*best, t)) best = &p;
  return best && corner_error(*best, t) < 0.1 * t.edge_px ? best : nullptr;
}

DetectorParams params_for(int n) {
  DetectorParams params;
  params.families = {Family(n)};
  params.camera = kCamera;
  return params;
}

// How often, of `trials` markers made by `make`, the border is proposed within `reach` of
// the marker's edge (at least 1.5 px) of each outer corner, the detector finds the marker with its id (and by a border
// proposal, which the trace says; and so from its squares' blobs, not its outline), and reads it as another id; and
// how often the frame's own candidates alone (no second look, no border proposal) find it.
struct Tally {
  int proposed = 0, found = 0, by_border = 0, by_border_squares = 0, wrong = 0, by_candidates = 0;
};
Tally tally(int n, int trials, const std::function<Case(std::mt19937_64&)>& make, double reach = 0.02) {
  std::mt19937_64 rng(7 + n);
  Tally t;
  Detector detector(params_for(n));
  DetectorParams plain = params_for(n);
  plain.second_look = false;
  Detector candidates_only(plain);
  for (int k = 0; k < trials; ++k) {
    const Case c = make(rng);
    const std::vector<BorderProposal> proposals = proposals_of(c.image, {Family(n)});
    const BorderProposal* p = at_marker(proposals, c.truth);
    t.proposed += p && corner_error(*p, c.truth) <= std::max(1.5, reach * c.truth.edge_px);
    DetectionTrace trace;
    for (const Detection& d : detector.detect(ImageView(c.image), nullptr, &trace)) {
      if (d.id != c.truth.id) {
        ++t.wrong;
        continue;
      }
      ++t.found;
      const bool by_border = std::any_of(trace.borders.begin(), trace.borders.end(),
                                         [](const BorderVerdict& b) { return b.stage == Stage::detected; });
      t.by_border += by_border;
      t.by_border_squares += by_border && !d.from_outline;
    }
    for (const Detection& d : candidates_only.detect(ImageView(c.image))) t.by_candidates += d.id == c.truth.id;
  }
  return t;
}

}  // namespace

TEST(ProposeBorders, ASharpMarkersBorderIsProposedAtItsOuterCorners) {
  // Found by its candidates, so the detector proposes nothing there; the stage alone does.
  std::mt19937_64 rng(1);
  for (int k = 0; k < 10; ++k) {
    const Case c = render(3 + k % 3, 60 + 10 * k, rng);
    const std::vector<BorderProposal> proposals = proposals_of(c.image, {c.truth.family});
    const BorderProposal* p = at_marker(proposals, c.truth);
    ASSERT_NE(p, nullptr) << k;
    EXPECT_LE(corner_error(*p, c.truth), 1.5) << k;
    EXPECT_TRUE(p->families[std::size_t(c.truth.family.n())]);
    EXPECT_GE(p->evidence->structure, 0.7) << k;  // sharp: about 1
  }
}

TEST(ProposeBorders, SquaresThatTouchEachOtherAndTheBorder) {
  // The marker: a 4x4 of about 100 px at 60 degrees of tilt, defocused by 1.1
  // px, its ink spread by half a unit round its squares (the gaps 1 unit, 1 to 2 px along
  // the tilt): the mean threshold joins squares to each other and to the border, and most
  // are no candidate. Its border is proposed, and it is read.
  const Tally t = tally(4, 30, [](std::mt19937_64& rng) {
    return render(
        4, 105, rng,
        [](Sheet sheet) {
          const int r = int(std::lround(0.7 * Sheet::kPerUnit));
          cv::Mat1f spread;
          cv::erode(sheet.albedo, spread, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
          const cv::Rect inside(sheet.at(2, 2), sheet.at(28, 28));  // the border keeps its outer edge
          spread(inside).copyTo(sheet.albedo(inside));
        },
        {}, View{60, 1.1});
  });
  EXPECT_LE(t.by_candidates, 12) << "the set-up no longer joins the squares";  // 10 of 30
  EXPECT_GE(t.proposed, 20);                                                   // 22
  EXPECT_GE(t.found, 27);                                                      // 28
  EXPECT_GE(t.by_border, 11);  // 14; the second look reads the others from their pieces
  EXPECT_EQ(t.wrong, 0);
}

TEST(ProposeBorders, AShadowEdgeAcrossTheInside) {
  // A hard shadow (0.45 of the light, a 2 px penumbra) whose edge crosses the marker near
  // its centre in any direction: the local threshold draws the edge's dark side into the
  // white interior. The border is proposed all the same, each side against its own margin.
  const Tally t = tally(4, 30, [](std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(-1, 1);
    const double angle = CV_PI * u(rng), offset = 0.15 * u(rng);
    return render(4, 120, rng, {}, [&](cv::Mat1f& linear, const MarkerTruth& truth) {
      const cv::Point2d normal(std::cos(angle), std::sin(angle));
      const cv::Point2d at = truth.center + normal * (offset * truth.edge_px);
      for (int y = 0; y < linear.rows; ++y)
        for (int x = 0; x < linear.cols; ++x) {
          const double d = (cv::Point2d(x, y) - at).dot(normal);  // px past the edge
          linear(y, x) *= float(1 - 0.55 * std::clamp(0.5 + d / 2, 0.0, 1.0));
        }
    });
  });
  EXPECT_GE(t.proposed, 26);           // 28 of 30
  EXPECT_GE(t.found, 28);              // 30: 4 by their candidates, the squares measured against the
  EXPECT_GE(t.by_border, 22);          // paper around each; 26 from the border, the light taken out,
  EXPECT_GE(t.by_border_squares, 22);  // all 26 by their squares in the evened patch (0 when
  EXPECT_EQ(t.wrong, 0);               // the patch keeps the shadow: read from the outline)
}

TEST(ProposeBorders, ABrokenWhiteRing) {
  // A dark stroke from the border across the white ring into the squares (a pen line, a
  // crease's shadow) on every side: the white interior opens into the border.
  const Tally t = tally(3, 30, [](std::mt19937_64& rng) {
    return render(3, 100, rng, [](Sheet sheet) {
      cv::line(sheet.albedo, sheet.at(1, 12), sheet.at(7, 12), 0.05f, Sheet::kPerUnit);
      cv::line(sheet.albedo, sheet.at(12, 1), sheet.at(12, 7), 0.05f, Sheet::kPerUnit);
      cv::line(sheet.albedo, sheet.at(23, 12), sheet.at(17, 12), 0.05f, Sheet::kPerUnit);
    });
  });
  EXPECT_GE(t.proposed, 27);  // 30 of 30
  EXPECT_GE(t.found, 27);     // 30, all read from the border
  EXPECT_EQ(t.wrong, 0);
}

TEST(ProposeBorders, ABentMarker) {
  // A sheet round a cylinder of 0.2 m (a 10 cm marker: 29 degrees of arc): its sides
  // bow, but its border is one region whose hull is close to a quadrilateral.
  const Tally t = tally(
      4, 30,
      [](std::mt19937_64& rng) {
        return render(4, 110, rng, {}, {}, View{-1, 0, 0.2});
      },
      0.05);
  EXPECT_GE(t.proposed, 22);  // 25 of 30 within 5 % of the edge of the flat marker's corners
  EXPECT_GE(t.found, 23);     // 26
  EXPECT_EQ(t.wrong, 0);
}

TEST(ProposeBorders, WhatIsNoMarkersBorderIsNotProposed) {
  cv::Mat1b frame(240, 320, std::uint8_t(120));
  // A solid dark square on paper: no interior.
  cv::rectangle(frame, cv::Rect(10, 10, 90, 90), 230, cv::FILLED);
  cv::rectangle(frame, cv::Rect(25, 25, 60, 60), 20, cv::FILLED);
  // A frame around plain paper: no structure.
  cv::rectangle(frame, cv::Rect(120, 10, 90, 90), 230, cv::FILLED);
  cv::rectangle(frame, cv::Rect(135, 25, 60, 60), 20, 5);
  // Printed letters.
  cv::rectangle(frame, cv::Rect(10, 120, 300, 110), 230, cv::FILLED);
  cv::putText(frame, "onum", cv::Point(20, 200), cv::FONT_HERSHEY_SIMPLEX, 2.5, 20, 6);
  for (int n = 2; n <= 8; ++n) EXPECT_TRUE(proposals_of(frame, {Family(n)}).empty()) << n << "x" << n;
}

TEST(ProposeBorders, TheStructureTellsTheFamily) {
  // A sharp 3x3's border read as a 6x6's would put the cells' cores on the lines between
  // the 3x3's squares: the structure is not the 6x6's.
  std::mt19937_64 rng(3);
  const Case c = render(3, 120, rng);
  const std::vector<BorderProposal> proposals = proposals_of(c.image, {Family(3), Family(6)});
  const BorderProposal* p = at_marker(proposals, c.truth);
  ASSERT_NE(p, nullptr);
  EXPECT_TRUE(p->families[3]);
  EXPECT_FALSE(p->families[6]);
  const std::optional<detail::BorderEvidence> six = detail::border_evidence(ImageView(c.image), p->corners, Family(6));
  ASSERT_TRUE(six);
  EXPECT_LT(six->structure, detail::kMinStructure);
}
