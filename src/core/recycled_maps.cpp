// SPDX-License-Identifier: LGPL-2.1-or-later
#include "recycled_maps.hpp"

#include <cstddef>
#include <cstring>
#include <map>

namespace lftag::detail {
namespace {

// What one thread keeps: at most this many bytes, enough for the maps of the largest
// marker an outline reading takes (OutlineReading's box of at most 2^20 pixels) several
// times over, and nothing once the thread ends.
constexpr std::size_t kMaxKeptBytes = std::size_t(32) << 20;
// Each buffer's capacity sits in a header this long before its data, which keeps the
// data aligned as cv::fastMalloc aligns it.
constexpr std::size_t kHeader = 64;

std::size_t& capacity_of(unsigned char* data) { return *reinterpret_cast<std::size_t*>(data - kHeader); }

class Kept {
 public:
  Kept() = default;
  Kept(const Kept&) = delete;
  Kept& operator=(const Kept&) = delete;
  ~Kept() {
    for (const auto& [capacity, data] : by_capacity_) cv::fastFree(data - kHeader);
  }

  unsigned char* take(std::size_t bytes) {
    // The smallest kept buffer that holds `bytes`, unless it is more than twice as large.
    if (const auto it = by_capacity_.lower_bound(bytes); it != by_capacity_.end() && it->first <= 2 * bytes) {
      unsigned char* data = it->second;
      bytes_ -= it->first;
      by_capacity_.erase(it);
      return data;
    }
    auto* data = static_cast<unsigned char*>(cv::fastMalloc(bytes + kHeader)) + kHeader;
    capacity_of(data) = bytes;
    return data;
  }

  void give_back(unsigned char* data) {
    const std::size_t capacity = capacity_of(data);
    if (bytes_ + capacity > kMaxKeptBytes) {
      cv::fastFree(data - kHeader);
      return;
    }
    by_capacity_.emplace(capacity, data);
    bytes_ += capacity;
  }

 private:
  std::multimap<std::size_t, unsigned char*> by_capacity_;
  std::size_t bytes_ = 0;
};

Kept& kept() {
  thread_local Kept buffers;
  return buffers;
}

class RecyclingAllocator final : public cv::MatAllocator {
 public:
  cv::UMatData* allocate(int dims, const int* sizes, int type, void* data0, std::size_t* step, cv::AccessFlag,
                         cv::UMatUsageFlags) const override {
    // Dense rows, the last dimension's elements adjacent, as every Mat the library makes.
    std::size_t bytes = CV_ELEM_SIZE(type);
    for (int i = dims - 1; i >= 0; --i) {
      if (step) {
        if (data0 && step[i] != cv::Mat::AUTO_STEP)
          bytes = step[i];  // the caller's own layout over its own data
        else
          step[i] = bytes;
      }
      bytes *= std::size_t(sizes[i]);
    }
    auto* u = new cv::UMatData(this);  // owned by the Mat, released through deallocate
    u->data = u->origdata = data0 ? static_cast<unsigned char*>(data0) : kept().take(bytes);
    u->size = bytes;
    if (data0) u->flags |= cv::UMatData::USER_ALLOCATED;
    return u;
  }

  bool allocate(cv::UMatData* u, cv::AccessFlag, cv::UMatUsageFlags) const override { return u != nullptr; }

  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    CV_Assert(u->urefcount == 0 && u->refcount == 0);
    if (!(u->flags & cv::UMatData::USER_ALLOCATED) && u->origdata) kept().give_back(u->origdata);
    delete u;
  }
};

}  // namespace

cv::MatAllocator* recycling_allocator() {
  static RecyclingAllocator allocator;
  return &allocator;
}

cv::Mat1f recycled_map(cv::Size size) {
  cv::Mat1f m;
  m.allocator = recycling_allocator();
  m.create(size);
  return m;
}

cv::Mat1f recycled_map(cv::Size size, float value) {
  cv::Mat1f m = recycled_map(size);
  m.setTo(value);
  return m;
}

cv::Mat1f recycled_copy(const cv::Mat1f& m) {
  cv::Mat1f out = recycled_map(m.size());
  m.copyTo(out);
  return out;
}

}  // namespace lftag::detail
