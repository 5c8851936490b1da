// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the family parsers (Family::parse, `--family`; Family::parse_list,
// `lftag detect --family` and lftagdetect's `families`). A parsed family prints back to
// itself (blanks around it dropped, X read as x) and a list holds each family once.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>

#include "check.hpp"
#include "lftag/family.hpp"

using lftag::fuzz::check;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    // The name is the text without surrounding blanks, with 'X' read as 'x'.
    const lftag::Family f = lftag::Family::parse(text);
    std::string_view core = text;
    while (!core.empty() && (core.front() == ' ' || core.front() == '\t')) core.remove_prefix(1);
    while (!core.empty() && (core.back() == ' ' || core.back() == '\t')) core.remove_suffix(1);
    std::string spelled(core);
    std::replace(spelled.begin(), spelled.end(), 'X', 'x');
    check(f.name() == spelled && lftag::Family::parse(f.name()) == f, "family round trip");
  } catch (const std::invalid_argument&) {
  }
  try {
    std::vector<lftag::Family> list = lftag::Family::parse_list(text);
    check(!list.empty() && list.size() <= lftag::Family::all().size(), "family list size");
    std::sort(list.begin(), list.end());
    check(std::adjacent_find(list.begin(), list.end()) == list.end(), "a family twice in a list");
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
