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

void Health::Stale(const std::string& reason) {
  Rejected(reason);
  ++stale_;
}

void Health::Duplicate(const std::string& reason) {
  Rejected(reason);
  ++duplicates_;
}

void Health::OutOfHorizon(const std::string& reason) {
  Rejected(reason);
  ++out_of_horizon_;
}

void Health::Resync(const std::string& reason) {
  ++resyncs_;
  last_error_ = reason;
}

void Health::FilterReset(const std::string& reason) {
  ++filter_resets_;
  last_error_ = reason;
}

estimation::TimeVerdict Health::Gate(estimation::TimeGate& gate, int64_t utime,
                                     const std::string& field) {
  using V = estimation::TimeVerdict;
  gate.SetCeiling(estimation::HostCeilingUs());
  const int64_t gaps_before = gate.counters().gap_samples;
  const V v = gate.Offer(utime);
  gaps_ += gate.counters().gap_samples - gaps_before;
  switch (v) {
    case V::kAccepted:
      break;
    case V::kResynchronised:
      Resync(field + ": time base re-synchronised at " + std::to_string(utime));
      break;
    case V::kDuplicate:
      Duplicate(gate.Reason(v, utime, field));
      break;
    case V::kOutOfOrder:
      ++out_of_order_;
      Rejected(gate.Reason(v, utime, field));
      break;
    case V::kBeyondHorizon:
      OutOfHorizon(gate.Reason(v, utime, field));
      break;
  }
  return v;
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
  if (!Tick(utime)) return false;
  return Publish(utime, transport, channel);
}

bool Health::Final(Transport& transport, const std::string& channel) {
  return Publish(latest_, transport, channel);
}

bool Health::Publish(int64_t utime, Transport& transport, const std::string& channel) {
  // Read when a beat goes out (a system call), not per message.
  dropped_ = transport.Dropped();
  ++published_;  // the beat itself counts
  return transport.Publish(channel, Message(utime));
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
  m.duplicates = duplicates_;
  m.out_of_horizon = out_of_horizon_;
  m.out_of_order = out_of_order_;
  m.gaps = gaps_;
  m.resyncs = resyncs_;
  m.filter_resets = filter_resets_;
  m.stale = stale_;
  m.dropped = dropped_;
  m.activity = activity_;
  return m;
}

}  // namespace rcal::transport
