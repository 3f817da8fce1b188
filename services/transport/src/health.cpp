#include "rcal/transport/health.hpp"

#include <unistd.h>

#include "rcal/transport/transport.hpp"

namespace rcal::transport {

Health::Health(std::string process, int64_t period_us)
    : process_(std::move(process)), period_us_(period_us > 0 ? period_us : 1) {}

void Health::Rejected(const std::string& reason) {
  ++rejected_;
  last_error_ = reason;
}

std::optional<health_t> Health::Tick(int64_t utime) {
  latest_ = utime;
  if (last_beat_ && utime < *last_beat_ - period_us_) last_beat_.reset();  // replay restarted
  if (last_beat_ && utime < *last_beat_ + period_us_) return std::nullopt;
  // Keep the schedule on multiples of the period after the first beat, so a gap in the data
  // gives one heartbeat, not a burst.
  if (!last_beat_)
    last_beat_ = utime;
  else
    last_beat_ = *last_beat_ + ((utime - *last_beat_) / period_us_) * period_us_;
  return Message(utime);
}

bool Health::Tick(int64_t utime, Transport& transport, const std::string& channel) {
  auto beat = Tick(utime);
  if (!beat) return false;
  ++published_;
  beat->published = published_;
  return transport.Publish(channel, *beat);
}

health_t Health::Message(int64_t utime) const {
  health_t m;
  m.utime = utime;
  m.process = process_;
  m.pid = static_cast<int32_t>(::getpid());
  m.received = received_;
  m.rejected = rejected_;
  m.published = published_;
  m.last_error = last_error_;
  return m;
}

}  // namespace rcal::transport
