// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological connected components in one pass over the runs of the binary image
// (paper IV-B, after SLCCA): regions, their areas, boxes and containment tree. The runs
// are kept row by row with their labels, so the pixels of the few regions that later
// stages look at can be found again without a label image.
//
// Why the parent is known at once: the first pixel of a region (in raster order) has a
// left neighbour of the other colour, and that neighbour's region cannot be enclosed by
// the new one (the column above it reaches the image border without crossing the new
// region), so it encloses it. Provisional labels are numbered in raster order and a union
// keeps the smaller number, so every region keeps the label of its first pixel, and with
// it the right parent.
#include <algorithm>

#include "stages.hpp"

namespace lftag::detail {

int RegionLabeller::find(int x) {
  while (labels_[x].root != x) {
    labels_[x].root = labels_[labels_[x].root].root;  // path halving
    x = labels_[x].root;
  }
  return x;
}

int RegionLabeller::create(bool black, int parent, int y) {
  const int id = int(labels_.size());
  labels_.push_back({id, parent, 0, 1 << 30, y, -1, y, black});
  return id;
}

int RegionLabeller::unite(int a, int b) {
  a = find(a), b = find(b);
  if (a == b) return a;
  if (b < a) std::swap(a, b);
  Label& keep = labels_[a];
  const Label& gone = labels_[b];
  labels_[b].root = a;
  keep.area += gone.area;
  keep.x0 = std::min(keep.x0, gone.x0), keep.x1 = std::max(keep.x1, gone.x1);
  keep.y0 = std::min(keep.y0, gone.y0), keep.y1 = std::max(keep.y1, gone.y1);
  return a;
}

void RegionLabeller::label(const BinaryImage& bin, RegionTree& tree) {
  using Run = RegionTree::Run;
  const int w = bin.width, h = bin.height;
  constexpr int kFrame = RegionTree::kFrame;
  labels_.clear();
  tree.runs.clear();
  tree.row_start.assign(1, 0);
  create(false, -1, 0);  // the white frame around the image: its box grows from nothing
  labels_[kFrame].y0 = 1 << 30;

  std::size_t prev_begin = 0, prev_end = 0;  // the row above, in tree.runs
  bool prev_first_black = false;
  for (int y = 0; y < h; ++y) {
    // Runs of this row from the colour changes, 64 pixels at a time. Colours alternate
    // along a row, starting with the colour of pixel 0.
    const std::size_t begin = tree.runs.size();
    const std::uint64_t* row = bin.row(y);
    const bool first_black = w > 0 && (row[0] & 1);
    int start = 0;
    std::uint64_t carry = 0;  // the pixel left of the word (white left of the image)
    for (int i = 0; i < bin.words_per_row; ++i) {
      const std::uint64_t word = row[i];
      std::uint64_t change = word ^ ((word << 1) | carry);
      carry = word >> 63;
      while (change) {
        const int x = i * 64 + __builtin_ctzll(change);
        change &= change - 1;
        if (x >= w) break;  // padding
        if (x == 0) continue;
        tree.runs.push_back({start, x, -1});
        start = x;
      }
    }
    if (w > 0) tree.runs.push_back({start, w, -1});
    const std::size_t end = tree.runs.size();

    // Connect each run to the touching runs of its colour in the row above: every other
    // run there, from the first of its colour.
    const Run* above = tree.runs.data();
    std::size_t j = prev_begin;
    for (std::size_t i = begin; i < end; ++i) {
      Run& r = tree.runs[i];
      const bool black = (((i - begin) & 1) != 0) != first_black;
      const int reach = black ? 0 : 1;  // white is 8-connected: diagonals touch
      while (j < prev_end && above[j].x1 + reach <= r.x0) ++j;
      std::size_t k = j;
      if (k < prev_end && ((((k - prev_begin) & 1) != 0) != prev_first_black) != black) ++k;
      int label = -1;
      for (; k < prev_end && above[k].x0 < r.x1 + reach; k += 2)
        label = label < 0 ? find(above[k].label) : unite(label, above[k].label);
      if (label < 0) label = create(black, i > begin ? tree.runs[i - 1].label : kFrame, y);
      Label& l = labels_[label];
      l.area += r.x1 - r.x0;
      l.x0 = std::min(l.x0, r.x0), l.x1 = std::max(l.x1, r.x1 - 1), l.y1 = y;
      r.label = label;
    }
    // White touching the image border belongs to the frame.
    if (end > begin) {
      for (std::size_t i : {begin, end - 1})
        if (!labels_[tree.runs[i].label].black) tree.runs[i].label = unite(tree.runs[i].label, kFrame);
      if (y == 0 || y == h - 1)
        for (std::size_t i = begin; i < end; ++i)
          if (!labels_[tree.runs[i].label].black) tree.runs[i].label = unite(tree.runs[i].label, kFrame);
    }
    tree.row_start.push_back(int(end));
    prev_begin = begin, prev_end = end, prev_first_black = first_black;
  }

  // Compact the surviving labels into regions and link the tree.
  tree.regions.clear();
  tree.label_region.assign(labels_.size(), -1);
  for (int l = 0; l < int(labels_.size()); ++l) {
    if (find(l) != l) continue;
    const Label& s = labels_[l];
    tree.label_region[l] = int(tree.regions.size());
    Region r;
    r.black = s.black;
    r.area = s.area;
    if (s.area) r.x0 = s.x0, r.y0 = s.y0, r.x1 = s.x1, r.y1 = s.y1;
    else r.x0 = r.y0 = 0, r.x1 = r.y1 = -1;  // a frame without pixels: an empty box
    tree.regions.push_back(r);
  }
  for (int l = 0; l < int(labels_.size()); ++l) tree.label_region[l] = tree.label_region[find(l)];
  const int n = int(tree.regions.size());
  child_fill_.assign(n + 1, 0);
  for (int l = 0; l < int(labels_.size()); ++l) {
    const int r = tree.label_region[l];
    if (find(l) != l || labels_[l].parent < 0) continue;
    const int p = tree.label_region[labels_[l].parent];
    tree.regions[r].parent = p;
    ++child_fill_[p + 1];
  }
  for (int r = 0; r < n; ++r) {
    child_fill_[r + 1] += child_fill_[r];
    tree.regions[r].first_child = child_fill_[r];
    tree.regions[r].child_count = child_fill_[r + 1] - child_fill_[r];
  }
  tree.children.assign(child_fill_[n], -1);
  for (int r = 0; r < n; ++r)
    if (tree.regions[r].parent >= 0) tree.children[child_fill_[tree.regions[r].parent]++] = r;
}

}  // namespace lftag::detail
