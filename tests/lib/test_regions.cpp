// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological connected components (src/detect/regions.cpp): the region tree.
//
// Connectivity: black regions are 4-connected and white regions 8-connected (the dual
// pair, so that every boundary separates one region from its parent); white touching the
// image border belongs to region 0, the frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <queue>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "binary.hpp"
#include "stages.hpp"

using namespace lftag;
using lftag::detail::BinaryImage;
using lftag::detail::Region;
using lftag::detail::RegionLabeller;
using lftag::detail::RegionTree;

namespace {

constexpr int kFrame = RegionTree::kFrame;

// The runs of region r as (row, x0, x1), top to bottom.
struct RowRun {
  int y, x0, x1;
};
std::vector<RowRun> runs_of(const RegionTree& t, int r) {
  std::vector<RowRun> out;
  t.for_each_run(r, [&](int y, int x0, int x1) { out.push_back({y, x0, x1}); });
  return out;
}

BinaryImage from_mat(const cv::Mat1b& black) { return lftag::test::binary_from_mask(black); }

// '#' black, anything else white.
cv::Mat1b from_rows(const std::vector<std::string>& rows) {
  cv::Mat1b m(int(rows.size()), int(rows[0].size()), uchar(0));
  for (int y = 0; y < m.rows; ++y) {
    EXPECT_EQ(rows[y].size(), rows[0].size());
    for (int x = 0; x < m.cols; ++x) m(y, x) = rows[y][x] == '#' ? 255 : 0;
  }
  return m;
}

struct Labelled {
  BinaryImage binary;
  RegionTree tree;
  cv::Mat1i map;  // region of every pixel, from the run lists
};

// Labels `black` and checks the invariants every tree must satisfy: the run lists tile the
// image exactly, with maximal runs of the region's colour; areas and boxes are those of the
// runs; the frame is white, region 0, without parent; every other region has a parent of
// the other colour, and children lists are the inverse of the parent links.
Labelled label(const cv::Mat1b& black, RegionLabeller* reuse = nullptr) {
  Labelled l;
  l.binary = from_mat(black);
  RegionLabeller own;
  (reuse ? *reuse : own).label(l.binary, l.tree);
  const RegionTree& t = l.tree;
  const int w = black.cols, h = black.rows, n = int(t.regions.size());
  l.map = cv::Mat1i(black.size(), -1);
  EXPECT_GE(n, 1);
  if (n < 1) return l;
  EXPECT_FALSE(t.regions[kFrame].black);
  EXPECT_EQ(t.regions[kFrame].parent, -1);
  std::size_t runs_seen = 0;
  int child_total = 0;
  for (int r = 0; r < n; ++r) {
    const Region& g = t.regions[r];
    int area = 0, x0 = w, y0 = h, x1 = -1, y1 = -1;
    for (const RowRun& run : runs_of(t, r)) {
      if (++runs_seen > t.runs.size()) {
        ADD_FAILURE() << "more runs reported than the tree holds: some belong to two regions";
        return l;
      }
      EXPECT_TRUE(run.y >= 0 && run.y < h && run.x0 >= 0 && run.x0 < run.x1 && run.x1 <= w)
          << "region " << r << " run " << run.y << ": " << run.x0 << ".." << run.x1;
      if (!(run.y >= 0 && run.y < h && run.x0 >= 0 && run.x0 < run.x1 && run.x1 <= w)) return l;
      for (int x = run.x0; x < run.x1; ++x) {
        EXPECT_EQ(l.map(run.y, x), -1) << "pixel (" << x << ", " << run.y << ") in two runs";
        l.map(run.y, x) = r;
        EXPECT_EQ(black(run.y, x) != 0, g.black) << "pixel (" << x << ", " << run.y << ") of region " << r;
      }
      // Maximal: the pixels either side are of the other colour or outside.
      if (run.x0 > 0) {
        EXPECT_NE(black(run.y, run.x0 - 1) != 0, g.black) << "run not maximal";
      }
      if (run.x1 < w) {
        EXPECT_NE(black(run.y, run.x1) != 0, g.black) << "run not maximal";
      }
      area += run.x1 - run.x0;
      x0 = std::min(x0, run.x0), x1 = std::max(x1, run.x1 - 1), y0 = std::min(y0, run.y), y1 = std::max(y1, run.y);
    }
    EXPECT_EQ(g.area, area) << "region " << r;
    if (area > 0) {
      EXPECT_EQ(g.x0, x0) << "region " << r;
      // The frame's top is checked on its own (FrameBoundingBoxIsThatOfItsPixels).
      if (r != kFrame) {
        EXPECT_EQ(g.y0, y0) << "region " << r;
      }
      EXPECT_EQ(g.x1, x1) << "region " << r;
      EXPECT_EQ(g.y1, y1) << "region " << r;
    } else {
      EXPECT_EQ(r, kFrame) << "only the frame may be empty";
    }
    if (r != kFrame) {
      EXPECT_TRUE(g.parent >= 0 && g.parent < n) << "region " << r << " parent " << g.parent;
      if (g.parent >= 0 && g.parent < n) {
        EXPECT_NE(t.regions[g.parent].black, g.black) << "region " << r << " and its parent";
        const int* c = t.children_of(g.parent);
        EXPECT_EQ(std::count(c, c + t.regions[g.parent].child_count, r), 1)
            << "region " << r << " among its parent's children";
      }
    }
    // Its children are a slice of the children array.
    EXPECT_GE(t.first_child(r), 0) << "region " << r;
    EXPECT_LE(t.first_child(r) + g.child_count, int(t.children.size())) << "region " << r;
    for (int i = 0; i < g.child_count; ++i) EXPECT_EQ(t.regions[t.children_of(r)[i]].parent, r);
    child_total += g.child_count;
  }
  EXPECT_EQ(child_total, n - 1);
  EXPECT_EQ(runs_seen, t.runs.size()) << "runs in no region";
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) EXPECT_GE(l.map(y, x), 0) << "pixel (" << x << ", " << y << ") in no run";
  // White on the border is the frame's.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if ((x == 0 || y == 0 || x == w - 1 || y == h - 1) && !black(y, x)) {
        EXPECT_EQ(l.map(y, x), kFrame);
      }
  return l;
}

std::vector<int> sorted_children(const RegionTree& t, int r) {
  std::vector<int> c(t.children_of(r), t.children_of(r) + t.regions[r].child_count);
  std::sort(c.begin(), c.end());
  return c;
}

// ------------------------------------------------------------------ reference labelling

struct RefRegion {
  bool black = false;
  int area = 0, x0 = 1 << 30, y0 = 1 << 30, x1 = -1, y1 = -1;
  int parent = -1;
};

// Flood fill with the same connectivity; white touching the border merged into region 0;
// the parent of a region is the region of the pixel left of its first pixel (raster order),
// the frame when that pixel is outside the image.
std::vector<RefRegion> reference(const cv::Mat1b& black, cv::Mat1i& labels) {
  const int w = black.cols, h = black.rows;
  labels = cv::Mat1i(black.size(), -1);
  std::vector<RefRegion> regions(1);  // the frame
  std::vector<std::pair<int, int>> first(1, {-1, -1});
  auto border = [&](int x, int y) { return x == 0 || y == 0 || x == w - 1 || y == h - 1; };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (labels(y, x) >= 0) continue;
      const bool b = black(y, x) != 0;
      // Fill the component, then decide its label.
      std::vector<std::pair<int, int>> pixels;
      std::queue<std::pair<int, int>> todo;
      cv::Mat1b seen(black.size(), uchar(0));
      todo.push({x, y});
      seen(y, x) = 1;
      bool touches = false;
      while (!todo.empty()) {
        const auto [px, py] = todo.front();
        todo.pop();
        pixels.push_back({px, py});
        touches |= border(px, py);
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0) continue;
            if (b && dx != 0 && dy != 0) continue;  // black: 4-connected
            const int qx = px + dx, qy = py + dy;
            if (qx < 0 || qy < 0 || qx >= w || qy >= h || seen(qy, qx) || (black(qy, qx) != 0) != b) continue;
            seen(qy, qx) = 1;
            todo.push({qx, qy});
          }
      }
      int id;
      if (!b && touches) {
        id = 0;
      } else {
        id = int(regions.size());
        regions.emplace_back();
        regions.back().black = b;
        first.push_back({x, y});  // the first pixel in raster order
      }
      for (const auto& [px, py] : pixels) {
        labels(py, px) = id;
        RefRegion& r = regions[id];
        ++r.area;
        r.x0 = std::min(r.x0, px), r.x1 = std::max(r.x1, px), r.y0 = std::min(r.y0, py), r.y1 = std::max(r.y1, py);
      }
    }
  for (std::size_t r = 1; r < regions.size(); ++r) {
    const auto [fx, fy] = first[r];
    regions[r].parent = fx == 0 ? 0 : labels(fy, fx - 1);
  }
  return regions;
}

// Compares the library's tree with the reference up to relabelling.
void compare_with_reference(const cv::Mat1b& black, const std::string& what) {
  const Labelled l = label(black);
  if (::testing::Test::HasFailure()) return;
  cv::Mat1i ref_labels;
  const std::vector<RefRegion> ref = reference(black, ref_labels);
  const RegionTree& t = l.tree;
  ASSERT_EQ(t.regions.size(), ref.size()) << what;
  // The same partition of the pixels: a one-to-one map of labels, the frame to the frame.
  std::vector<int> to_lib(ref.size(), -1), to_ref(ref.size(), -1);
  to_lib[0] = 0, to_ref[0] = 0;
  for (int y = 0; y < black.rows; ++y)
    for (int x = 0; x < black.cols; ++x) {
      const int a = ref_labels(y, x), b = l.map(y, x);
      if (to_lib[a] < 0 && to_ref[b] < 0) to_lib[a] = b, to_ref[b] = a;
      ASSERT_EQ(to_lib[a], b) << what << ": pixel (" << x << ", " << y << ")";
      ASSERT_EQ(to_ref[b], a) << what << ": pixel (" << x << ", " << y << ")";
    }
  for (std::size_t a = 0; a < ref.size(); ++a) {
    const int b = to_lib[a];
    ASSERT_GE(b, 0) << what;
    const Region& g = t.regions[b];
    EXPECT_EQ(g.black, ref[a].black) << what;
    EXPECT_EQ(g.area, ref[a].area) << what;
    if (ref[a].area > 0) {
      EXPECT_EQ(cv::Vec3i(g.x0, g.x1, g.y1), cv::Vec3i(ref[a].x0, ref[a].x1, ref[a].y1)) << what;
      if (b != kFrame) {  // the frame's: FrameBoundingBoxIsThatOfItsPixels
        EXPECT_EQ(g.y0, ref[a].y0) << what;
      }
    }
    EXPECT_EQ(g.parent, ref[a].parent < 0 ? -1 : to_lib[ref[a].parent]) << what << ": region " << b;
  }
}

// Independent of how the parent is found: a region is enclosed by its parent (every path
// from outside the image to it crosses the parent: 8-connected paths around a black
// parent, 4-connected around a white one) and touches it.
void expect_enclosed(const Labelled& l, const std::string& what) {
  const RegionTree& t = l.tree;
  const int w = l.map.cols, h = l.map.rows;
  for (int r = 1; r < int(t.regions.size()); ++r) {
    const int p = t.regions[r].parent;
    if (p == kFrame) continue;
    const bool eight = t.regions[p].black;
    cv::Mat1b reached(l.map.size(), uchar(0));
    std::queue<std::pair<int, int>> todo;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if ((x == 0 || y == 0 || x == w - 1 || y == h - 1) && l.map(y, x) != p) reached(y, x) = 1, todo.push({x, y});
    while (!todo.empty()) {
      const auto [x, y] = todo.front();
      todo.pop();
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if ((dx == 0 && dy == 0) || (!eight && dx != 0 && dy != 0)) continue;
          const int qx = x + dx, qy = y + dy;
          if (qx < 0 || qy < 0 || qx >= w || qy >= h || reached(qy, qx) || l.map(qy, qx) == p) continue;
          reached(qy, qx) = 1;
          todo.push({qx, qy});
        }
    }
    bool touches = false, escaped = false;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (l.map(y, x) != r) continue;
        escaped |= reached(y, x) != 0;
        for (const auto& [dx, dy] : {std::pair{1, 0}, std::pair{-1, 0}, std::pair{0, 1}, std::pair{0, -1}}) {
          const int qx = x + dx, qy = y + dy;
          touches |= qx >= 0 && qy >= 0 && qx < w && qy < h && l.map(qy, qx) == p;
        }
      }
    EXPECT_FALSE(escaped) << what << ": region " << r << " is not enclosed by its parent " << p;
    EXPECT_TRUE(touches) << what << ": region " << r << " does not touch its parent " << p;
  }
}

}  // namespace

TEST(Regions, NestedRingsFormAChain) {
  const cv::Mat1b image = from_rows({
      ".............",
      ".###########.",
      ".#.........#.",
      ".#.#######.#.",
      ".#.#.....#.#.",
      ".#.#.###.#.#.",
      ".#.#.#.#.#.#.",
      ".#.#.###.#.#.",
      ".#.#.....#.#.",
      ".#.#######.#.",
      ".#.........#.",
      ".###########.",
      ".............",
  });
  const Labelled l = label(image);
  const RegionTree& t = l.tree;
  ASSERT_EQ(t.regions.size(), 7u);
  // From the outside in: frame, black ring, white ring, ..., the white centre pixel.
  const int areas[7] = {48, 40, 32, 24, 16, 8, 1};
  int expected_parent = -1;
  for (int depth = 0; depth < 7; ++depth) {
    const int r = l.map(depth, depth);
    SCOPED_TRACE("depth " + std::to_string(depth));
    const Region& g = t.regions[r];
    EXPECT_EQ(g.black, depth % 2 == 1);
    EXPECT_EQ(g.area, areas[depth]);
    EXPECT_EQ(cv::Vec4i(g.x0, g.y0, g.x1, g.y1), cv::Vec4i(depth, depth, 12 - depth, 12 - depth));
    EXPECT_EQ(g.parent, expected_parent);
    EXPECT_EQ(g.child_count, depth < 6 ? 1 : 0);
    if (depth < 6) {
      EXPECT_EQ(t.children_of(r)[0], l.map(depth + 1, depth + 1));
    }
    expected_parent = r;
  }
  EXPECT_EQ(l.map(0, 0), kFrame);
  expect_enclosed(l, "rings");
}

TEST(Regions, WhiteRegionWithBlackChildren) {
  const cv::Mat1b image = from_rows({
      "................",
      ".##############.",
      ".#............#.",
      ".#.##...#.....#.",
      ".#.##....#....#.",
      ".#............#.",
      ".#..###.....#.#.",
      ".#..#.......#.#.",
      ".#............#.",
      ".##############.",
      "................",
  });
  const Labelled l = label(image);
  const RegionTree& t = l.tree;
  ASSERT_EQ(t.regions.size(), 8u);  // frame, box, room and five children
  const int box = l.map(1, 1), room = l.map(2, 2);
  EXPECT_TRUE(t.regions[box].black);
  EXPECT_EQ(t.regions[box].parent, kFrame);
  EXPECT_EQ(t.regions[box].area, 2 * 14 + 2 * 7);
  EXPECT_EQ(sorted_children(t, kFrame), std::vector<int>{box});
  EXPECT_EQ(sorted_children(t, box), std::vector<int>{room});
  const Region& w = t.regions[room];
  EXPECT_FALSE(w.black);
  EXPECT_EQ(cv::Vec4i(w.x0, w.y0, w.x1, w.y1), cv::Vec4i(2, 2, 13, 8));
  EXPECT_EQ(w.area, 12 * 7 - 12);
  ASSERT_EQ(w.child_count, 5);
  // Square, two diagonal pixels (separate), an L and a bar.
  const std::map<std::pair<int, int>, std::pair<int, cv::Vec4i>> kids = {{{3, 3}, {4, {3, 3, 4, 4}}},
                                                                         {{8, 3}, {1, {8, 3, 8, 3}}},
                                                                         {{9, 4}, {1, {9, 4, 9, 4}}},
                                                                         {{4, 6}, {4, {4, 6, 6, 7}}},
                                                                         {{12, 6}, {2, {12, 6, 12, 7}}}};
  std::vector<int> expected;
  for (const auto& [at, what] : kids) {
    const int r = l.map(at.second, at.first);
    expected.push_back(r);
    const Region& g = t.regions[r];
    EXPECT_TRUE(g.black);
    EXPECT_EQ(g.parent, room);
    EXPECT_EQ(g.area, what.first) << at.first << ", " << at.second;
    EXPECT_EQ(cv::Vec4i(g.x0, g.y0, g.x1, g.y1), what.second);
    EXPECT_EQ(g.child_count, 0);
  }
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(sorted_children(t, room), expected);
  expect_enclosed(l, "room");
}

TEST(Regions, FrameHoldsEverythingOnTheBorder) {
  const cv::Mat1b image = from_rows({
      "..#.....",
      "..#.###.",
      "..#.#.#.",
      "###.###.",
      "........",
      "##......",
      ".#......",
  });
  const Labelled l = label(image);
  const RegionTree& t = l.tree;
  ASSERT_EQ(t.regions.size(), 5u);
  // The walled-off top-left corner and the single white corner pixel bottom left are the
  // frame's, as is the white on the right.
  EXPECT_EQ(l.map(0, 0), kFrame);
  EXPECT_EQ(l.map(1, 1), kFrame);
  EXPECT_EQ(l.map(6, 0), kFrame);
  EXPECT_EQ(l.map(4, 7), kFrame);
  const int bar = l.map(0, 2), ring = l.map(1, 4), hole = l.map(2, 5), corner = l.map(5, 0);
  EXPECT_EQ(t.regions[bar].parent, kFrame);
  EXPECT_EQ(t.regions[bar].area, 6);
  EXPECT_EQ(t.regions[ring].parent, kFrame);
  EXPECT_EQ(t.regions[hole].parent, ring);
  EXPECT_EQ(t.regions[hole].area, 1);
  EXPECT_EQ(t.regions[corner].parent, kFrame);
  EXPECT_EQ(t.regions[corner].area, 3);
  EXPECT_EQ(t.regions[kFrame].area, 56 - 6 - 8 - 1 - 3);
  EXPECT_EQ(cv::Vec4i(t.regions[kFrame].x0, t.regions[kFrame].y0, t.regions[kFrame].x1, t.regions[kFrame].y1),
            cv::Vec4i(0, 0, 7, 6));
  std::vector<int> top = {bar, ring, corner};
  std::sort(top.begin(), top.end());
  EXPECT_EQ(sorted_children(t, kFrame), top);
  expect_enclosed(l, "border");
}

TEST(Regions, FrameBoundingBoxIsThatOfItsPixels) {
  // Row 0 black: the frame's pixels start on row 1, so its box is (0, 1) - (4, 3).
  const Labelled l = label(from_rows({"#####", ".....", ".###.", "....."}));
  const Region& f = l.tree.regions[kFrame];
  EXPECT_EQ(f.area, 5 + 2 + 5);
  EXPECT_EQ(cv::Vec4i(f.x0, f.y0, f.x1, f.y1), cv::Vec4i(0, 1, 4, 3));
  // Only column 3 white: x0 = x1 = 3 already follow the pixels, y0 must as well.
  const Labelled c = label(from_rows({"###.", "####", "###."}));
  const Region& g = c.tree.regions[kFrame];
  EXPECT_EQ(g.area, 2);
  EXPECT_EQ(cv::Vec4i(g.x0, g.y0, g.x1, g.y1), cv::Vec4i(3, 0, 3, 2));
  const Labelled d = label(from_rows({"####", "####", "##.."}));
  const Region& e = d.tree.regions[kFrame];
  EXPECT_EQ(cv::Vec4i(e.x0, e.y0, e.x1, e.y1), cv::Vec4i(2, 2, 3, 2));
}

TEST(Regions, UniformImages) {
  for (const cv::Size s : {cv::Size(1, 1), cv::Size(64, 1), cv::Size(65, 3), cv::Size(130, 5)}) {
    const Labelled white = label(cv::Mat1b(s, uchar(0)));
    ASSERT_EQ(white.tree.regions.size(), 1u);
    EXPECT_EQ(white.tree.regions[0].area, s.area());
    EXPECT_EQ(white.tree.regions[0].child_count, 0);

    // All black: an empty frame around one black region.
    const Labelled black = label(cv::Mat1b(s, uchar(255)));
    ASSERT_EQ(black.tree.regions.size(), 2u);
    EXPECT_EQ(black.tree.regions[0].area, 0);
    EXPECT_EQ(black.tree.regions[1].area, s.area());
    EXPECT_TRUE(black.tree.regions[1].black);
    EXPECT_EQ(black.tree.regions[1].parent, kFrame);
    EXPECT_EQ(cv::Vec4i(black.tree.regions[1].x0, black.tree.regions[1].y0, black.tree.regions[1].x1,
                        black.tree.regions[1].y1),
              cv::Vec4i(0, 0, s.width - 1, s.height - 1));
    EXPECT_EQ(sorted_children(black.tree, kFrame), std::vector<int>{1});
  }
}

TEST(Regions, BlackIsFourConnected) {
  // Black pixels touching only at a corner are two regions, here and inside a white room.
  const Labelled a = label(from_rows({"#.", ".#"}));
  ASSERT_EQ(a.tree.regions.size(), 3u);
  EXPECT_NE(a.map(0, 0), a.map(1, 1));
  EXPECT_EQ(a.map(0, 1), kFrame);
  EXPECT_EQ(a.map(1, 0), kFrame);
  for (int r : {a.map(0, 0), a.map(1, 1)}) {
    EXPECT_EQ(a.tree.regions[r].area, 1);
    EXPECT_EQ(a.tree.regions[r].parent, kFrame);
  }
  const Labelled b = label(from_rows({
      "#######",
      "#.....#",
      "#.#...#",
      "#..#..#",
      "#...#.#",
      "#.....#",
      "#######",
  }));
  ASSERT_EQ(b.tree.regions.size(), 6u);  // frame (empty), box, room, three pixels
  const int room = b.map(1, 1);
  EXPECT_EQ(b.tree.regions[room].child_count, 3);
  for (int i = 2; i <= 4; ++i) {
    EXPECT_EQ(b.tree.regions[b.map(i, i)].area, 1);
    EXPECT_EQ(b.tree.regions[b.map(i, i)].parent, room);
  }
  // The frame is empty, but still the root.
  EXPECT_EQ(b.tree.regions[kFrame].area, 0);
  EXPECT_EQ(b.tree.regions[b.map(0, 0)].parent, kFrame);
  expect_enclosed(b, "diagonal black");
}

TEST(Regions, WhiteIsEightConnected) {
  // A black ring missing one corner: the white inside touches the white outside only
  // diagonally, and is one region with it (the frame); the ring stays one region.
  const Labelled a = label(from_rows({
      ".......",
      ".#####.",
      ".#...#.",
      ".#...#.",
      ".#...#.",
      ".####..",
      ".......",
  }));
  ASSERT_EQ(a.tree.regions.size(), 2u);
  EXPECT_EQ(a.map(3, 3), kFrame);
  EXPECT_EQ(a.tree.regions[1].area, 15);
  // Two white rooms in a black block meeting at a corner are one region.
  const Labelled b = label(from_rows({
      "########",
      "#..#####",
      "#..#####",
      "###..###",
      "###..###",
      "########",
  }));
  ASSERT_EQ(b.tree.regions.size(), 3u);
  const int room = b.map(1, 1);
  EXPECT_EQ(b.map(3, 3), room);
  EXPECT_EQ(b.tree.regions[room].area, 8);
  EXPECT_EQ(b.tree.regions[room].parent, b.map(0, 0));
  expect_enclosed(b, "diagonal white");
}

TEST(Regions, RegionsThatMergeLaterKeepTheirParent) {
  // A black U whose arms begin as separate runs and join at the bottom, enclosing a white
  // pocket with a black dot; a white region with two arms merging below a black bar.
  const cv::Mat1b image = from_rows({
      "...................",
      ".#....#....#######.",
      ".#....#....#.....#.",
      ".#.##.#....#.###.#.",
      ".#....#....#.#...#.",
      ".######....#.#.#.#.",
      "...........#.....#.",
      "...........#######.",
  });
  const Labelled l = label(image);
  compare_with_reference(image, "merge");
  const RegionTree& t = l.tree;
  const int u = l.map(1, 1);
  EXPECT_EQ(l.map(1, 6), u);
  EXPECT_EQ(t.regions[u].area, 5 + 5 + 4);
  EXPECT_EQ(l.map(3, 3), l.map(3, 4));
  EXPECT_EQ(t.regions[l.map(3, 3)].parent, kFrame);  // the U is open at the top
  const int box = l.map(1, 11), room = l.map(2, 12);
  EXPECT_EQ(t.regions[room].parent, box);
  EXPECT_EQ(t.regions[room].area, 5 * 5 - 5 - 1);
  EXPECT_EQ(t.regions[l.map(3, 13)].parent, room);  // the hook
  EXPECT_EQ(t.regions[l.map(5, 15)].parent, room);  // the dot
  EXPECT_EQ(t.regions[room].child_count, 2);
  expect_enclosed(l, "merge");
}

TEST(Regions, LabellerCanBeReused) {
  RegionLabeller labeller;
  std::mt19937 rng(99);
  for (int i = 0; i < 20; ++i) {
    const int w = 1 + int(rng() % 150), h = 1 + int(rng() % 40);
    cv::Mat1b image(h, w);
    for (auto& p : image) p = rng() % 100 < 45 ? 255 : 0;
    const Labelled fresh = label(image);
    const Labelled again = label(image, &labeller);
    ASSERT_EQ(fresh.tree.regions.size(), again.tree.regions.size());
    EXPECT_EQ(cv::norm(fresh.map, again.map, cv::NORM_INF), 0.0);
    for (std::size_t r = 0; r < fresh.tree.regions.size(); ++r) {
      EXPECT_EQ(fresh.tree.regions[r].parent, again.tree.regions[r].parent);
      EXPECT_EQ(fresh.tree.regions[r].area, again.tree.regions[r].area);
    }
  }
}

TEST(Regions, RandomImagesMatchAFloodFillReference) {
  std::mt19937 rng(2024);
  const int widths[] = {1, 2, 3, 5, 8, 13, 31, 63, 64, 65, 100, 129};
  const int heights[] = {1, 2, 3, 7, 12, 20};
  const int densities[] = {5, 20, 40, 50, 60, 80, 95};  // percent black
  int images = 0;
  for (int w : widths)
    for (int h : heights)
      for (int d : densities)
        for (int rep = 0; rep < 5; ++rep) {
          cv::Mat1b image(h, w);
          for (auto& p : image) p = int(rng() % 100) < d ? 255 : 0;
          const std::string what = std::to_string(w) + "x" + std::to_string(h) + " density " + std::to_string(d) +
                                   " #" + std::to_string(rep);
          compare_with_reference(image, what);
          if (w * h <= 400) expect_enclosed(label(image), what);
          ++images;
          if (::testing::Test::HasFailure()) return;
        }
  // Blocky images: random rectangles and rings, so that regions nest several levels deep.
  for (int i = 0; i < 1000; ++i) {
    const int w = 4 + int(rng() % 70), h = 4 + int(rng() % 30);
    cv::Mat1b image(h, w, uchar(rng() % 2 ? 255 : 0));
    for (int k = int(rng() % 12); k >= 0; --k) {
      const int x0 = int(rng() % w), y0 = int(rng() % h);
      const int x1 = std::min(w, x0 + 1 + int(rng() % 20)), y1 = std::min(h, y0 + 1 + int(rng() % 12));
      const uchar v = rng() % 2 ? 255 : 0;
      if (rng() % 2)
        image(cv::Range(y0, y1), cv::Range(x0, x1)).setTo(v);
      else
        cv::rectangle(image, cv::Point(x0, y0), cv::Point(x1 - 1, y1 - 1), cv::Scalar(v), 1);
    }
    for (int k = int(rng() % 8); k > 0; --k) image(int(rng() % h), int(rng() % w)) ^= 255;
    const std::string what = "blocky " + std::to_string(i) + " (" + std::to_string(w) + "x" + std::to_string(h) + ")";
    compare_with_reference(image, what);
    if (w * h <= 900) expect_enclosed(label(image), what);
    ++images;
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(images, 3000);
}

// The worst case for memory: a 1-px checkerboard, a run at every pixel and a region at every
// other (each black pixel is a 4-connected region of its own; the white is the frame).
// The labelling's buffers, from their capacities: at most the 20.5 bytes a pixel that
// docs/reliability.md ("Memory per pixel") states (they were about 55).
TEST(Regions, CheckerboardTakesAtMostTwentyBytesAPixel) {
  const int w = 2000, h = 2000;
  BinaryImage binary;
  binary.width = w, binary.height = h, binary.words_per_row = (w + 63) / 64;
  binary.bits.assign(std::size_t(binary.words_per_row) * h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = y & 1; x < w; x += 2)
      binary.bits[std::size_t(y) * binary.words_per_row + (x >> 6)] |= std::uint64_t{1} << (x & 63);
  RegionLabeller labeller;
  RegionTree t;
  labeller.label(binary, t);
  const double per_pixel = double(t.bytes_reserved() + labeller.bytes_reserved()) / (double(w) * h);
  EXPECT_LE(per_pixel, 20.5);

  // The tree is still right: the frame and every black pixel alone, in raster order.
  ASSERT_EQ(t.regions.size(), std::size_t(w) * h / 2 + 1);
  EXPECT_EQ(t.runs.size(), std::size_t(w) * h);
  EXPECT_EQ(t.regions[kFrame].area, w * h / 2);
  EXPECT_EQ(t.regions[kFrame].child_count, w * h / 2);
  const int* children = t.children_of(kFrame);
  for (int r = 1; r < int(t.regions.size()); ++r) {
    const Region& g = t.regions[r];
    const int x = 2 * ((r - 1) % (w / 2)) + ((r - 1) / (w / 2) & 1), y = (r - 1) / (w / 2);
    ASSERT_TRUE(g.black && g.area == 1 && g.parent == kFrame && g.child_count == 0) << "region " << r;
    ASSERT_EQ(cv::Vec4i(g.x0, g.y0, g.x1, g.y1), cv::Vec4i(x, y, x, y)) << "region " << r;
    ASSERT_EQ(children[r - 1], r);
  }
  for (const int r : {1, 2, w / 2 + 1, int(t.regions.size()) - 1}) {
    const std::vector<RowRun> runs = runs_of(t, r);
    ASSERT_EQ(runs.size(), 1u);
    EXPECT_EQ(cv::Vec3i(runs[0].y, runs[0].x0, runs[0].x1),
              cv::Vec3i(t.regions[r].y0, t.regions[r].x0, t.regions[r].x0 + 1));
  }
  std::size_t frame_runs = 0;
  t.for_each_run(kFrame, [&](int, int x0, int x1) { frame_runs += x1 - x0 == 1; });
  EXPECT_EQ(frame_runs, std::size_t(w) * h / 2);

  // A plain frame after it: the checkerboard's 82 MB are let go, but for buffers of about
  // a megabyte (kept for the second looks' patches).
  labeller.label(from_mat(cv::Mat1b(480, 640, uchar(0))), t);
  EXPECT_LT(t.bytes_reserved() + labeller.bytes_reserved(), std::size_t(4) << 20);
  EXPECT_EQ(t.regions.size(), 1u);
}
