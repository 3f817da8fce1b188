// Small helpers for the human reports (Markdown) the rcal commands write.
#pragma once

#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

namespace rcal::tool {

constexpr double kMm = 1e3;                        // m → mm, for reports only
constexpr double kDeg = 180.0 / std::numbers::pi;  // rad → deg, for reports only

/// Figures kept in mm for the reports, back in metres for the JSON files (SI in files).
inline std::vector<double> MetresFromMm(const std::vector<double>& v_mm) {
  std::vector<double> v_m;
  v_m.reserve(v_mm.size());
  for (double x : v_mm) v_m.push_back(x / kMm);
  return v_m;
}

inline std::string Fmt(double v, int digits = 3) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

/// A Markdown table.
inline std::string MdTable(const std::vector<std::string>& header,
                           const std::vector<std::vector<std::string>>& rows) {
  std::string s = "|";
  for (const auto& h : header) s += " " + h + " |";
  s += "\n|";
  for (size_t i = 0; i < header.size(); ++i) s += " --- |";
  s += "\n";
  for (const auto& r : rows) {
    s += "|";
    for (const auto& c : r) s += " " + c + " |";
    s += "\n";
  }
  return s;
}

}  // namespace rcal::tool
