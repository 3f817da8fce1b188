// z and p in the JSON rcal analyze writes, by the rule of discrepancy/significance.hpp: numbers
// stay finite and valid JSON; what a double cannot hold is written as a bound beside the number.
//   "<key>": z, plus "<key>_bound": ">" | "<" when z is infinite (the number is then the bound).
//   "<prefix>p_value": p (0 after underflow), "<prefix>log10_p_value": exact when p > 0, plus
//   "<prefix>p_value_bound": "< 1e-300" when p < 1e-300.
#pragma once

#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "rcal/discrepancy/significance.hpp"

namespace rcal::tool {

inline void PutZ(nlohmann::json& j, const std::string& key, double z) {
  const discrepancy::WrittenZ w = discrepancy::WriteZ(z);
  j[key] = w.value;
  if (!w.bound.empty()) j[key + "_bound"] = w.bound;
}

inline void PutP(nlohmann::json& j, const std::string& prefix, double log_p) {
  j[prefix + "p_value"] = std::exp(log_p);
  if (std::isfinite(log_p)) j[prefix + "log10_p_value"] = log_p / std::numbers::ln10;
  if (!(std::exp(log_p) >= discrepancy::kPBound)) j[prefix + "p_value_bound"] = "< 1e-300";
}

}  // namespace rcal::tool
