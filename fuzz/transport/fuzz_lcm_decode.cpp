// Every rcal LCM message type: the first byte picks the type (mod 16, the order of DecodeAs), the
// rest is the encoded message, bounds-checked, decoded and adapted as the processes do.
#include <cstddef>
#include <cstdint>

#include "lcm_messages.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  rcal::fuzz::DecodeAs(data[0], data + 1, size - 1);
  return 0;
}
