// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the id parser (TagId::parse, `lftag render --id`) and the id-list
// parser (parse_id_list, `lftag generate --id` and lftagtestsrc's `ids`, which allows 64).
// A parsed id must print back to itself, in decimal and in hexadecimal, and a list must
// hold no more ids than allowed.
#include <cstdint>
#include <stdexcept>
#include <string_view>

#include "check.hpp"
#include "lftag/family.hpp"
#include "lftag/tag_id.hpp"

using lftag::fuzz::check;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const lftag::TagId id = lftag::TagId::parse(text);
    check(lftag::TagId::parse(id.to_decimal()) == id, "decimal round trip");
    check(lftag::TagId::parse(id.to_hex()) == id, "hexadecimal round trip");
    for (const lftag::Family& f : lftag::Family::all())
      if (f.contains(id)) f.centers(id);
  } catch (const std::invalid_argument&) {
  }
  for (std::size_t max_ids : {std::size_t(64), std::size_t(100000)}) {
    try {
      const std::vector<lftag::TagId> ids = lftag::parse_id_list(text, max_ids);
      check(!ids.empty() && ids.size() <= max_ids, "an id list longer than allowed, or empty");
    } catch (const std::invalid_argument&) {
    }
  }
  return 0;
}
