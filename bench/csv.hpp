// SPDX-License-Identifier: LGPL-2.1-or-later
// Results as CSV files: one header line, then one line per row. Numbers that are not
// finite (a quantity that was never reached) are written as empty fields.
#pragma once

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace bench {

class Csv {
 public:
  // Creates (truncates) `path`; throws std::runtime_error when it cannot.
  Csv(const std::filesystem::path& path, const std::vector<std::string>& header);

  template <class... T>
  void row(const T&... values) {
    write({field(values)...});
  }

 private:
  static std::string field(const std::string& s);
  static std::string field(const char* s) { return field(std::string(s)); }
  static std::string field(double v);
  static std::string field(int v) { return std::to_string(v); }
  static std::string field(long v) { return std::to_string(v); }
  static std::string field(long long v) { return std::to_string(v); }
  static std::string field(unsigned long v) { return std::to_string(v); }
  void write(const std::vector<std::string>& fields);

  std::filesystem::path path_;
  std::ofstream out_;
  std::size_t columns_;
};

}  // namespace bench
