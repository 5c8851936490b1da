// SPDX-License-Identifier: LGPL-2.1-or-later
// The fuzz targets' property check: a broken property is a crash libFuzzer keeps.
#pragma once

#include <cstdio>
#include <cstdlib>

namespace lftag::fuzz {

inline void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "%s\n", what);
    std::abort();
  }
}

}  // namespace lftag::fuzz
