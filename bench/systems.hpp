// SPDX-License-Identifier: LGPL-2.1-or-later
// The systems the benchmarks compare, by name.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "system.hpp"

namespace bench {

// Every known system name, in report order.
std::vector<std::string> system_names();
// The names selected by a comma-separated list of names or name prefixes ("aruco",
// "apriltag-36h11"); an empty list selects all. Throws std::invalid_argument on a
// token that selects nothing.
std::vector<std::string> select_systems(const std::string& filter);
// A fresh instance: systems keep per-frame state, so every thread makes its own.
std::unique_ptr<FiducialSystem> make_system(const std::string& name);

}  // namespace bench
