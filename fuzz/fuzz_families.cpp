// SPDX-License-Identifier: LGPL-2.1-or-later
// libFuzzer target: the family parsers (Family::parse, `--family`; Family::parse_list,
// `lftag detect --family` and lftagdetect's `families`). A parsed family prints back to
// itself and a list holds each family once.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string_view>

#include "lftag/family.hpp"

namespace {

void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "%s\n", what);
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const lftag::Family f = lftag::Family::parse(text);
    check(f.name() == text && lftag::Family::parse(f.name()) == f, "family round trip");
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
