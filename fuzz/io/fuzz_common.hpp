// Shared by the io fuzz targets: the input as text, and the one outcome a parser may have for bad
// input besides success, std::runtime_error (any other exception, a crash, a leak or a sanitizer
// report is a finding).
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace rcal::fuzz {

inline std::string Text(const std::uint8_t* data, std::size_t size) {
  return size == 0 ? std::string() : std::string(reinterpret_cast<const char*>(data), size);
}

template <typename F>
void Refusing(F&& f) {
  try {
    f();
  } catch (const std::runtime_error&) {
    // Bad input refused with a message: the expected outcome.
  }
}

}  // namespace rcal::fuzz
