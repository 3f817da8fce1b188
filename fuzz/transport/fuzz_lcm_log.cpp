// The LCM log reader (io/lcm_log.hpp) on arbitrary bytes, each event it returns decoded as its
// channel's type, as `rcal calibrate --log` and `rcal analyze LOG` do. Besides not crashing, the
// reader must account for every byte exactly once: in an intact frame or as unreadable.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "lcm_messages.hpp"
#include "rcal/io/lcm_log.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  rcal::io::LcmLogReader reader(std::vector<std::uint8_t>(data, data + size));
  std::int64_t frame_bytes = 0;
  while (const auto e = reader.Next()) {
    frame_bytes += rcal::io::kLcmLogHeaderBytes + static_cast<std::int64_t>(e->channel.size()) +
                   static_cast<std::int64_t>(e->data.size());
    rcal::fuzz::DecodeChannel(e->channel, e->data.data(), e->data.size());
  }
  const auto& s = reader.stats();
  if (frame_bytes + s.bytes_unreadable != static_cast<std::int64_t>(size) ||
      (s.bytes_unreadable > 0) != (s.broken_frames > 0)) {
    std::fprintf(stderr, "%lld bytes: %lld in frames + %s\n", static_cast<long long>(size),
                 static_cast<long long>(frame_bytes), s.Summary().c_str());
    std::abort();
  }
  return 0;
}
