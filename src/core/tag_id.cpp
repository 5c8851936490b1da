// SPDX-License-Identifier: LGPL-2.1-or-later
#include "lftag/tag_id.hpp"

#include <algorithm>
#include <stdexcept>

namespace lftag {
namespace {

using u128 = unsigned __int128;

u128 to_u128(TagId id) { return (u128(id.high()) << 64) | id.low(); }
TagId from_u128(u128 v) { return TagId(std::uint64_t(v >> 64), std::uint64_t(v)); }

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string_view trim(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t')) text.remove_suffix(1);
  return text;
}

}  // namespace

TagId TagId::parse(std::string_view text) {
  const std::string quoted = "'" + std::string(text) + "'";
  const bool hex = text.size() > 2 && text[0] == '0' && (text[1] == 'x' || text[1] == 'X');
  const std::string_view digits = hex ? text.substr(2) : text;
  if (digits.empty()) throw std::invalid_argument("id " + quoted + " is not a number");
  const unsigned base = hex ? 16 : 10;
  const u128 max = ~u128(0);
  u128 value = 0;
  for (char c : digits) {
    const int d = hex_value(c);
    if (d < 0 || unsigned(d) >= base)
      throw std::invalid_argument("id " + quoted + " is not a " + (hex ? "hexadecimal" : "decimal") + " number");
    if (value > (max - unsigned(d)) / base) throw std::invalid_argument("id " + quoted + " does not fit in 128 bits");
    value = value * base + unsigned(d);
  }
  return from_u128(value);
}

std::string TagId::to_decimal() const {
  u128 v = to_u128(*this);
  std::string out;
  do {
    out.push_back(char('0' + int(v % 10)));
    v /= 10;
  } while (v != 0);
  std::reverse(out.begin(), out.end());
  return out;
}

std::string TagId::to_hex() const {
  static const char kDigits[] = "0123456789abcdef";
  u128 v = to_u128(*this);
  std::string out;
  do {
    out.push_back(kDigits[int(v & 15)]);
    v >>= 4;
  } while (v != 0);
  std::reverse(out.begin(), out.end());
  return "0x" + out;
}

int TagId::digit(int k) const {
  if (k < 0 || k >= 64) throw std::out_of_range("id digit index out of range");
  return int((to_u128(*this) >> (2 * k)) & 3);
}

TagId TagId::with_digit(int k, int value) const {
  if (k < 0 || k >= 64 || value < 0 || value > 3) throw std::out_of_range("id digit index or value out of range");
  const u128 mask = u128(3) << (2 * k);
  return from_u128((to_u128(*this) & ~mask) | (u128(value) << (2 * k)));
}

std::string to_string(TagId id) { return id.to_decimal(); }

std::vector<TagId> parse_id_list(std::string_view text, std::size_t max_ids) {
  std::vector<TagId> ids;
  auto too_many = [&] {
    throw std::invalid_argument("the id list '" + std::string(text) + "' holds more than " + std::to_string(max_ids) +
                                " ids");
  };
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    // "1, 2" and "3 - 5" as the family lists allow them.
    const std::string_view item = trim(text.substr(start, comma - start));
    if (item.empty())
      throw std::invalid_argument("the id list '" + std::string(text) +
                                  "' has an empty item: give ids such as 0-11,40");
    const std::size_t dash = item.find('-');
    if (dash == 0)
      throw std::invalid_argument("id '" + std::string(item) +
                                  "' is negative: ids start at 0 (a range is FIRST-LAST, " + "such as 0-11)");
    if (dash == std::string_view::npos) {
      ids.push_back(TagId::parse(item));
    } else {
      const std::string_view first = trim(item.substr(0, dash)), last = trim(item.substr(dash + 1));
      if (last.empty())
        throw std::invalid_argument("id range '" + std::string(item) + "' has no last id: a range is FIRST-LAST, " +
                                    "such as 0-11");
      const TagId lo = TagId::parse(first), hi = TagId::parse(last);
      if (!lo.fits_u64() || !hi.fits_u64() || hi < lo)
        throw std::invalid_argument("id range '" + std::string(item) + "' must run upwards, below 2^64");
      if (hi.low() - lo.low() >= max_ids) too_many();
      // Counted, not compared: a range ending at 2^64 - 1 must not wrap round to 0.
      for (std::uint64_t k = 0; k <= hi.low() - lo.low(); ++k) ids.emplace_back(lo.low() + k);
    }
    if (ids.size() > max_ids) too_many();
    start = comma + 1;
  }
  return ids;
}

}  // namespace lftag
