// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological connected components in one pass over the runs of the binary image
// (paper IV-B, after SLCCA): regions, their areas, boxes, run lists and containment tree.
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
  labels_.push_back({id, parent, 0, 1 << 30, y, -1, y, -1, -1, black});
  return id;
}

int RegionLabeller::unite(int a, int b) {
  a = find(a), b = find(b);
  if (a == b) return a;
  if (b < a) std::swap(a, b);
  Label& keep = labels_[a];
  Label& gone = labels_[b];
  gone.root = a;
  keep.area += gone.area;
  keep.x0 = std::min(keep.x0, gone.x0), keep.x1 = std::max(keep.x1, gone.x1);
  keep.y0 = std::min(keep.y0, gone.y0), keep.y1 = std::max(keep.y1, gone.y1);
  if (gone.head >= 0) {
    if (keep.tail < 0) keep.head = gone.head;
    else (*runs_)[keep.tail].next = gone.head;
    keep.tail = gone.tail;
  }
  return a;
}

void RegionLabeller::add_run(int l, int y, int x0, int x1) {
  Label& r = labels_[l];
  r.area += x1 - x0;
  r.x0 = std::min(r.x0, x0), r.x1 = std::max(r.x1, x1 - 1), r.y1 = y;
  const int idx = int(runs_->size());
  runs_->push_back({y, x0, x1, -1});
  if (r.tail < 0) r.head = idx;
  else (*runs_)[r.tail].next = idx;
  r.tail = idx;
}

void RegionLabeller::label(const BinaryImage& bin, RegionTree& tree) {
  const int w = bin.width, h = bin.height;
  constexpr int kFrame = RegionTree::kFrame;
  labels_.clear();
  prev_.clear();
  tree.runs.clear();
  runs_ = &tree.runs;
  create(false, -1, 0);  // the white frame around the image

  for (int y = 0; y < h; ++y) {
    // Runs of this row from the colour changes, 64 pixels at a time.
    cur_.clear();
    const std::uint64_t* row = bin.row(y);
    int start = 0;
    bool black = w > 0 && (row[0] & 1);
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
        cur_.push_back({start, x, -1, black});
        start = x;
        black = !black;
      }
    }
    if (w > 0) cur_.push_back({start, w, -1, black});

    // Connect each run to the touching runs of its colour in the row above.
    std::size_t j = 0;
    for (std::size_t i = 0; i < cur_.size(); ++i) {
      RowRun& r = cur_[i];
      const int reach = r.black ? 0 : 1;  // white is 8-connected: diagonals touch
      while (j < prev_.size() && prev_[j].x1 + reach <= r.x0) ++j;
      int label = -1;
      for (std::size_t k = j; k < prev_.size() && prev_[k].x0 < r.x1 + reach; ++k) {
        if (prev_[k].black != r.black) continue;
        label = label < 0 ? find(prev_[k].label) : unite(label, prev_[k].label);
      }
      if (label < 0) label = create(r.black, i > 0 ? cur_[i - 1].label : kFrame, y);
      // White touching the image border belongs to the frame.
      if (!r.black && (y == 0 || y == h - 1 || r.x0 == 0 || r.x1 == w)) label = unite(label, kFrame);
      r.label = label;
      add_run(label, y, r.x0, r.x1);
    }
    std::swap(prev_, cur_);
  }

  // Compact the surviving labels into regions and link the tree.
  tree.regions.clear();
  region_of_.assign(labels_.size(), -1);
  for (int l = 0; l < int(labels_.size()); ++l) {
    if (find(l) != l) continue;
    const Label& s = labels_[l];
    region_of_[l] = int(tree.regions.size());
    Region r;
    r.black = s.black;
    r.area = s.area;
    r.x0 = s.area ? s.x0 : 0, r.y0 = s.y0, r.x1 = s.x1, r.y1 = s.y1;
    r.first_run = s.head;
    tree.regions.push_back(r);
  }
  const int n = int(tree.regions.size());
  child_fill_.assign(n + 1, 0);
  for (int l = 0; l < int(labels_.size()); ++l) {
    const int r = region_of_[l];
    if (r < 0 || labels_[l].parent < 0) continue;
    const int p = region_of_[find(labels_[l].parent)];
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
