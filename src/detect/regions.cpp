// SPDX-License-Identifier: LGPL-2.1-or-later
// Topological connected components in one pass over the runs of the binary image
// (paper IV-B, after SLCCA): regions, their areas, boxes and containment tree. The runs
// are kept row by row with their regions, so the pixels of the few regions that later
// stages look at can be found again without a label image.
//
// Why the parent is known at once: the first pixel of a region (in raster order) has a
// left neighbour of the other colour, and that neighbour's region cannot be enclosed by
// the new one (the column above it reaches the image border without crossing the new
// region), so it encloses it. Provisional labels are numbered in raster order and a union
// keeps the smaller number, so every region keeps the label of its first pixel, and with
// it the right parent.
//
// Memory: the runs and the labels they make are counted before the labelling, so
// every buffer is reserved once, at its size; the labels are the tree's regions, numbered
// down in place at the end; a run is the 4-byte number of its region. No two neighbouring
// runs both make a label (a black run needs white above it, a white one black above it
// and beside it), so below the first row there is at most a label for every other pixel,
// as well as at most a run for every pixel: the 1-px checkerboard, which has both, is the
// worst case, 4 + 28 / 2 bytes a pixel, and 2.4 more for the children and the starts.
#include <stdexcept>

#include "stages.hpp"

namespace lftag::detail {
namespace {

template <class T>
std::size_t capacity_bytes(const std::vector<T>& v) {
  return v.capacity() * sizeof(T);
}

// The pixels of word i of a row `w` pixels wide (its padding cleared).
std::uint64_t valid_bits(int w, int i) {
  const int left = w - 64 * i;
  return left >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << left) - 1;
}

// The runs of one colour (their first pixels in `colour_starts`) that hold a pixel of
// `touch`, 64 pixels at a time: a carry set off just past each start that is not itself
// touching runs over the pixels that are neither starts nor touching, and stops on the
// first that is: a touching pixel for a touched run, the next start for an untouched one.
// `carry` and `seed` cross to the next word of the row.
int touched_runs(std::uint64_t colour_starts, std::uint64_t touch, std::uint64_t& carry, std::uint64_t& seed) {
  const std::uint64_t stops = colour_starts | touch, pass = ~stops, from = colour_starts & ~touch;
  const std::uint64_t seeds = (from << 1) | seed;
  seed = from >> 63;
  const unsigned __int128 sum = static_cast<unsigned __int128>(pass) + (seeds & pass) + carry;
  carry = std::uint64_t(sum >> 64);
  const std::uint64_t first_stop = (std::uint64_t(sum) & stops) | (seeds & stops);
  return count_bits(colour_starts & touch) + count_bits(first_stop & touch & ~colour_starts);
}

// Of the `runs` of a row, those that no run of their colour in the row above touches (black runs
// 4-connected: a black pixel above one of theirs; white ones 8-connected: a white pixel
// above one of theirs or diagonally).
std::size_t untouched_runs(const std::uint64_t* row, const std::uint64_t* above, const std::uint64_t* starts, int w,
                           int wpr, std::size_t runs) {
  std::size_t touched = 0;
  std::uint64_t carry[2] = {}, seed[2] = {};
  for (int i = 0; i < wpr; ++i) {
    if (!starts[i] && !(carry[0] | carry[1] | seed[0] | seed[1])) continue;  // inside a run: nothing to count
    const std::uint64_t valid = valid_bits(w, i), black = row[i], white = ~black & valid;
    const std::uint64_t white_above = ~above[i] & valid;
    const std::uint64_t white_above_left = i > 0 ? ~above[i - 1] >> 63 : 0;  // only the last word has padding
    const std::uint64_t white_above_right = i + 1 < wpr ? ~above[i + 1] & valid_bits(w, i + 1) & 1 : 0;
    const std::uint64_t near_white =
        white_above | (white_above << 1) | white_above_left | (white_above >> 1) | (white_above_right << 63);
    touched += std::size_t(touched_runs(starts[i] & black, black & above[i], carry[0], seed[0]));
    touched += std::size_t(touched_runs(starts[i] & white, white & near_white, carry[1], seed[1]));
  }
  return runs - touched;
}

// Provisional labels with their statistics so far, stored as regions: child_count holds
// the union-find link (never above the label), parent the label left of its first pixel.
class Labels {
 public:
  explicit Labels(std::vector<Region>& labels) : l_(labels) {}

  int find(int x) {
    while (l_[x].child_count != x) {
      l_[x].child_count = l_[l_[x].child_count].child_count;  // path halving
      x = l_[x].child_count;
    }
    return x;
  }

  int create(bool black, int parent, int y) {
    Region& l = l_.emplace_back();
    const int id = int(l_.size()) - 1;
    l.child_count = id, l.parent = parent, l.black = black;
    l.x0 = 1 << 30, l.x1 = -1, l.y0 = l.y1 = y;
    return id;
  }

  int unite(int a, int b) {
    a = find(a), b = find(b);
    if (a == b) return a;
    if (b < a) std::swap(a, b);
    Region& keep = l_[a];
    const Region& gone = l_[b];
    l_[b].child_count = a;
    keep.area += gone.area;
    keep.x0 = std::min(keep.x0, gone.x0), keep.x1 = std::max(keep.x1, gone.x1);
    keep.y0 = std::min(keep.y0, gone.y0), keep.y1 = std::max(int(keep.y1), int(gone.y1));
    return a;
  }

 private:
  std::vector<Region>& l_;
};

}  // namespace

std::size_t RegionTree::bytes_reserved() const {
  return capacity_bytes(regions) + capacity_bytes(children) + capacity_bytes(starts) + capacity_bytes(runs_before) +
         capacity_bytes(runs) + capacity_bytes(child_base);
}

void RegionLabeller::label(const BinaryImage& bin, RegionTree& tree) {
  const int w = bin.width, h = bin.height, wpr = bin.words_per_row;
  constexpr int kFrame = RegionTree::kFrame;
  tree.width = w, tree.words_per_row = wpr;

  // Where runs start, 64 pixels at a time: where a pixel's colour differs from its left
  // neighbour's, and at x = 0. Then the labels: a run makes one when no run of its colour
  // in the row above touches it.
  const std::size_t words = std::size_t(wpr) * h;
  reserve_for_frame(tree.starts, words);
  reserve_for_frame(tree.runs_before, words + 1);
  tree.starts.resize(words);
  tree.runs_before.resize(words + 1);
  std::size_t total = 0, labels_made = 1;  // the frame's
  const std::uint64_t last_valid = wpr > 0 ? valid_bits(w, wpr - 1) : 0;
  for (int y = 0; y < h; ++y) {
    const std::uint64_t* row = bin.row(y);
    std::uint64_t* starts = tree.starts.data() + std::size_t(y) * wpr;
    std::uint64_t carry = 0;  // white left of the image
    for (int i = 0; i < wpr; ++i) {
      const std::uint64_t word = row[i];
      std::uint64_t s = word ^ ((word << 1) | carry);
      carry = word >> 63;
      if (i == 0) s |= 1;
      starts[i] = i < wpr - 1 ? s : s & last_valid;
      tree.runs_before[std::size_t(y) * wpr + i] = int(total);
      if (starts[i]) total += std::size_t(count_bits(starts[i]));
    }
    const std::size_t row_runs = total - (wpr > 0 ? std::size_t(tree.runs_before[std::size_t(y) * wpr]) : 0);
    labels_made += y == 0 ? row_runs : untouched_runs(row, bin.row(y - 1), starts, w, wpr, row_runs);
    if (total >= std::size_t(1) << 30)
      throw std::length_error("the binary image has 2^30 runs or more: too large to label");
  }
  tree.runs_before[words] = int(total);

  reserve_for_frame(tree.runs, total);
  tree.runs.resize(total);
  reserve_for_frame(tree.regions, labels_made);
  tree.regions.clear();
  for (std::vector<int>& x : row_x_) reserve_for_frame(x, std::size_t(w) + 1);
  Labels labels(tree.regions);
  labels.create(false, -1, 0);  // the white frame around the image: its box grows from nothing
  tree.regions[kFrame].y0 = 1 << 30;

  std::vector<int>* above_x = &row_x_[0];
  std::vector<int>* this_x = &row_x_[1];
  int prev_begin = 0, prev_count = 0;  // the row above's runs, in tree.runs
  bool prev_first_black = false;
  for (int y = 0; y < h; ++y) {
    // Colours alternate along a row, starting with the colour of pixel 0.
    std::vector<int>& xs = *this_x;
    xs.clear();
    const std::size_t row_word = std::size_t(y) * wpr;
    for (int i = 0; i < wpr; ++i)
      for (std::uint64_t s = tree.starts[row_word + i]; s; s &= s - 1) xs.push_back(i * 64 + __builtin_ctzll(s));
    xs.push_back(w);
    const int begin = wpr > 0 ? tree.runs_before[row_word] : 0, count = int(xs.size()) - 1;
    const bool first_black = w > 0 && (bin.row(y)[0] & 1);
    int* run = tree.runs.data() + begin;
    const int* up = tree.runs.data() + prev_begin;
    const std::vector<int>& ax = *above_x;

    // Connect each run to the touching runs of its colour in the row above: every other
    // run there, from the first of its colour.
    int j = 0;
    for (int i = 0; i < count; ++i) {
      const int x0 = xs[i], x1 = xs[i + 1];
      const bool black = ((i & 1) != 0) != first_black;
      const int reach = black ? 0 : 1;  // white is 8-connected: diagonals touch
      while (j < prev_count && ax[j + 1] + reach <= x0) ++j;
      int k = j;
      if (k < prev_count && (((k & 1) != 0) != prev_first_black) != black) ++k;
      int label = -1;
      for (; k < prev_count && ax[k] < x1 + reach; k += 2)
        label = label < 0 ? labels.find(up[k]) : labels.unite(label, up[k]);
      if (label < 0) label = labels.create(black, i > 0 ? run[i - 1] : kFrame, y);
      Region& l = tree.regions[label];
      l.area += x1 - x0;
      l.x0 = std::min(l.x0, x0), l.x1 = std::max(l.x1, x1 - 1), l.y1 = y;
      run[i] = label;
    }
    // White touching the image border belongs to the frame.
    if (count > 0) {
      for (int i : {0, count - 1})
        if (!tree.regions[run[i]].black) run[i] = labels.unite(run[i], kFrame);
      if (y == 0 || y == h - 1)
        for (int i = 0; i < count; ++i)
          if (!tree.regions[run[i]].black) run[i] = labels.unite(run[i], kFrame);
    }
    prev_begin = begin, prev_count = count, prev_first_black = first_black;
    std::swap(above_x, this_x);
  }

  // Number the roots in raster order: a label's link becomes its root's region. Links
  // point down, so the link's own is already a region when a label is reached.
  std::vector<Region>& regions = tree.regions;
  const int n_labels = int(regions.size());
  int n = 0;
  for (int l = 0; l < n_labels; ++l) {
    Region& s = regions[l];
    s.child_count = s.child_count == l ? n++ : regions[s.child_count].child_count;
  }
  for (int& r : tree.runs) r = regions[r].child_count;
  // A root is the first label of its region: its parent label becomes a region, then it
  // moves down to its region's place (never above its own).
  for (int l = 0, next = 0; l < n_labels; ++l) {
    if (regions[l].child_count != next) continue;
    ++next;
    if (regions[l].parent >= 0) regions[l].parent = regions[regions[l].parent].child_count;
  }
  for (int l = 0, next = 0; l < n_labels; ++l) {
    if (regions[l].child_count != next) continue;
    Region r = regions[l];
    r.child_count = 0;
    if (!r.area) r.x0 = r.y0 = 0, r.x1 = r.y1 = -1;  // a frame without pixels: an empty box
    regions[next++] = r;
  }
  regions.resize(n);

  // Children, grouped by parent: each group's last place counts the group's children
  // placed so far until its last child takes it.
  for (int r = 1; r < n; ++r) ++regions[regions[r].parent].child_count;
  reserve_for_frame(tree.child_base, std::size_t(n) / 8 + 1);
  tree.child_base.assign(std::size_t(n) / 8 + 1, 0);
  for (int r = 0, placed = 0; r < n; ++r) {
    if ((r & 7) == 0) tree.child_base[r >> 3] = placed;
    placed += regions[r].child_count;
  }
  reserve_for_frame(tree.children, std::size_t(std::max(n - 1, 0)));
  tree.children.assign(std::size_t(std::max(n - 1, 0)), 0);
  for (int r = 1; r < n; ++r) {
    const int p = regions[r].parent, count = regions[p].child_count;
    int* group = tree.children.data() + tree.first_child(p);
    int& placed = group[count - 1];
    if (placed == count - 1) {
      placed = r;
    } else {
      group[placed] = r;
      ++placed;
    }
  }
}

}  // namespace lftag::detail
