// What the LCM <-> DDS conversions (convert.cpp, ros2_convert.cpp) share: failing with a message
// that names the field, checking values, and allocating the C strings and sequences idlc's
// generated code frees (dds_sample_free). Internal to services/dds_bridge.
#pragma once

#include <dds/dds.h>

#include <cmath>
#include <cstring>
#include <string>
#include <type_traits>

#include "ros2_msgs.h"

namespace rcal::dds::detail {

inline constexpr int64_t kMicrosPerSecond = 1'000'000;

/// Sets *error (when given) and returns false.
inline bool Fail(std::string* error, std::string message) {
  if (error) *error = std::move(message);
  return false;
}

/// "field[i]" (appended piecewise: GCC 12's -Wrestrict misfires on "literal" + std::string).
inline std::string Indexed(const char* field, size_t i) {
  std::string s(field);
  s += '[';
  s += std::to_string(i);
  s += ']';
  return s;
}

/// A finite value, or (allow_inf) +inf/-inf; never NaN. `field` is a string or a callable that
/// returns one (built only on failure: the check runs on every value of every message).
template <typename Field>
bool CheckValue(double v, const Field& field, std::string* error, bool allow_inf = false) {
  if (std::isfinite(v) || (allow_inf && std::isinf(v))) return true;
  std::string name;
  if constexpr (std::is_invocable_v<Field>)
    name = field();
  else
    name = field;
  name += std::isnan(v) ? ": NaN" : ": infinite";
  return Fail(error, std::move(name));
}

template <size_t N>
bool CheckArray(const double (&a)[N], const char* field, std::string* error) {
  for (size_t i = 0; i < N; ++i)
    if (!CheckValue(
            a[i], [&] { return Indexed(field, i); }, error))
      return false;
  return true;
}

inline char* Dup(const std::string& s) {
  return dds_string_dup(s.c_str());
}

inline std::string Str(const char* s) {
  return s ? std::string(s) : std::string();
}

/// Allocates n elements of a generated sequence (freed by dds_sample_free).
template <typename Seq, typename Elem>
void AllocSeq(Seq& seq, size_t n) {
  seq._maximum = seq._length = static_cast<uint32_t>(n);
  seq._buffer = n ? static_cast<Elem*>(dds_alloc(n * sizeof(Elem))) : nullptr;
  if (n) std::memset(seq._buffer, 0, n * sizeof(Elem));
  seq._release = true;
}

template <size_t N>
void Copy(double (&to)[N], const double (&from)[N]) {
  std::memcpy(to, from, sizeof to);
}

}  // namespace rcal::dds::detail
