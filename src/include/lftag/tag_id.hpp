// SPDX-License-Identifier: LGPL-2.1-or-later
// An exact marker id. Ids of the 6x6, 7x7 and 8x8 families need up to 124 bits,
// so an id is a 128-bit value and never passes through a double or a 64-bit integer.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace lftag {

class TagId {
 public:
  constexpr TagId() = default;
  constexpr TagId(std::uint64_t value) : lo_(value) {}  // NOLINT: ids are numbers
  constexpr TagId(std::uint64_t high, std::uint64_t low) : hi_(high), lo_(low) {}

  // Parses decimal digits or a hex number with a "0x" prefix. Throws
  // std::invalid_argument when the text is not a number or exceeds 128 bits.
  static TagId parse(std::string_view text);

  std::string to_decimal() const;
  std::string to_hex() const;  // "0x" followed by lower-case digits

  std::uint64_t high() const { return hi_; }
  std::uint64_t low() const { return lo_; }
  bool fits_u64() const { return hi_ == 0; }
  // True when the id is exactly representable as a JSON/JavaScript number.
  bool fits_53_bits() const { return hi_ == 0 && lo_ < (std::uint64_t{1} << 53); }

  // The base-4 digit k (bits 2k and 2k+1), the data carried by data cell k.
  int digit(int k) const;
  TagId with_digit(int k, int value) const;

  friend bool operator==(TagId a, TagId b) { return a.hi_ == b.hi_ && a.lo_ == b.lo_; }
  friend bool operator!=(TagId a, TagId b) { return !(a == b); }
  friend bool operator<(TagId a, TagId b) { return a.hi_ != b.hi_ ? a.hi_ < b.hi_ : a.lo_ < b.lo_; }
  friend bool operator>(TagId a, TagId b) { return b < a; }
  friend bool operator<=(TagId a, TagId b) { return !(b < a); }
  friend bool operator>=(TagId a, TagId b) { return !(a < b); }

 private:
  std::uint64_t hi_ = 0;
  std::uint64_t lo_ = 0;
};

std::string to_string(TagId id);  // decimal

// Parses a list such as "7", "0x1f" or "1,2,5-9" (ranges only below 2^64). Throws
// std::invalid_argument for bad text, a descending range, or more than `max_ids` ids.
std::vector<TagId> parse_id_list(std::string_view text, std::size_t max_ids = 100000);

}  // namespace lftag
