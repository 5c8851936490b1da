// SPDX-License-Identifier: LGPL-2.1-or-later
#include "systems.hpp"

#include <algorithm>
#include <functional>
#include <stdexcept>
#include <utility>

#include "apriltag_system.hpp"
#include "aruco_system.hpp"
#include "lftag_system.hpp"

namespace bench {
namespace {

using Factory = std::function<std::unique_ptr<FiducialSystem>()>;

// Name -> factory. A new system (such as the LFTag detector's adapter) is one entry here.
const std::vector<std::pair<std::string, Factory>>& registry() {
  static const std::vector<std::pair<std::string, Factory>> all = [] {
    std::vector<std::pair<std::string, Factory>> r;
    for (int n = lftag::Family::kMinN; n <= lftag::Family::kMaxN; ++n) {
      r.emplace_back("lftag-" + lftag::Family(n).name(), [=] { return std::make_unique<LftagSystem>(n); });
    }
    for (const std::string family : {"16h5", "25h9", "36h11", "41h12"})
      for (int decimate : {1, 2})
        r.emplace_back("apriltag-" + family + "-d" + std::to_string(decimate),
                       [=] { return std::make_unique<AprilTagSystem>(family, decimate); });
    r.emplace_back("aruco-36h11", [] { return std::make_unique<ArucoSystem>(); });
    return r;
  }();
  return all;
}

}  // namespace

std::vector<std::string> system_names() {
  std::vector<std::string> names;
  for (const auto& entry : registry()) names.push_back(entry.first);
  return names;
}

std::vector<std::string> select_systems(const std::string& filter) {
  std::vector<std::string> tokens;
  for (std::size_t start = 0; start <= filter.size();) {
    const std::size_t end = std::min(filter.find(',', start), filter.size());
    if (end > start) tokens.push_back(filter.substr(start, end - start));
    start = end + 1;
  }
  std::vector<bool> chosen(registry().size(), tokens.empty());
  for (const std::string& token : tokens) {
    bool any = false;
    for (std::size_t i = 0; i < registry().size(); ++i)
      if (registry()[i].first.rfind(token, 0) == 0) chosen[i] = true, any = true;
    if (!any) {
      std::string known;
      for (const std::string& n : system_names()) known += " " + n;
      throw std::invalid_argument("no system matches '" + token + "'; known:" + known);
    }
  }
  std::vector<std::string> names;
  for (std::size_t i = 0; i < registry().size(); ++i)
    if (chosen[i]) names.push_back(registry()[i].first);
  return names;
}

std::unique_ptr<FiducialSystem> make_system(const std::string& name) {
  for (const auto& [n, factory] : registry()) {
    if (n != name) continue;
    std::unique_ptr<FiducialSystem> system = factory();
    if (system->name() != name) throw std::logic_error("system " + system->name() + " registered as " + name);
    return system;
  }
  throw std::invalid_argument("unknown system " + name);
}

}  // namespace bench
