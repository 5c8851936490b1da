// SPDX-License-Identifier: LGPL-2.1-or-later
#include "csv.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace bench {

Csv::Csv(const std::filesystem::path& path, const std::vector<std::string>& header)
    : path_(path), out_(path), columns_(header.size()) {
  if (!out_) throw std::runtime_error("cannot write " + path.string());
  write(header);
}

std::string Csv::field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string quoted = "\"";
  for (char c : s) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

std::string Csv::field(double v) {
  if (!std::isfinite(v)) return "";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

void Csv::write(const std::vector<std::string>& fields) {
  if (fields.size() != columns_) throw std::logic_error(path_.string() + ": a row with the wrong number of fields");
  for (std::size_t i = 0; i < fields.size(); ++i) out_ << (i ? "," : "") << fields[i];
  out_ << '\n';
  out_.flush();
}

}  // namespace bench
