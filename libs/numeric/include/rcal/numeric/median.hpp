// Medians of samples, one definition for every layer (they were copied into five libraries and
// two tools, with different answers for an empty input).
//
// UpperMedian(v): the order statistic of 0-based rank ⌊n/2⌋: the median for odd n, the upper of
// the two middle values for even n. Always one of the samples; O(n) (std::nth_element). The
// robust scales (1.4826 · median |r|, the MAD's σ for Gaussian data) and the estimators' medians
// use it, and their golden figures were made with it.
// Median(v): the median of statistics, the mean of the two middle values for even n; O(n).
// Both take the samples by value (they reorder the copy) and return NaN for an empty input (an
// integer UpperMedian needs a non-empty input). The
// samples must be comparable (no NaN: a NaN breaks the strict weak ordering nth_element needs);
// callers filter them first.
#pragma once

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <limits>
#include <vector>

namespace rcal::numeric {

/// The order statistic of rank ⌊n/2⌋ (0-based); NaN when empty. Units: those of the samples.
inline double UpperMedian(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// UpperMedian of integers (clock stamps, counts) [their unit]; `v` must not be empty.
template <std::integral T>
T UpperMedian(std::vector<T> v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// The median (the mean of the two middle values for even n); NaN when empty.
inline double Median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  if (v.size() % 2 == 1) return *mid;
  // The lower middle value is the largest of the elements before mid (all ≤ *mid).
  return 0.5 * (*std::max_element(v.begin(), mid) + *mid);
}

}  // namespace rcal::numeric
