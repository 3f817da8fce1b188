// The HEALTH heartbeat every process publishes: counts of messages received, rejected (with the
// last reason) and published. Time comes from the messages' utime (sensor time), never from the
// wall clock, so a replay at any speed publishes the same heartbeats.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "rcal/health_t.hpp"

namespace rcal::transport {

class Transport;

class Health {
 public:
  /// `process`: the name in the heartbeat; `period_us`: sensor time between heartbeats [µs].
  explicit Health(std::string process, int64_t period_us = 1'000'000);

  /// A message arrived (decoded or not).
  void Received() { ++received_; }
  /// A message was rejected; `reason` names the field or the channel.
  void Rejected(const std::string& reason);
  /// An error that is not a rejected message (e.g. a checkpoint that could not be written).
  void Error(const std::string& reason) { last_error_ = reason; }
  /// A message was published.
  void Published() { ++published_; }

  /// Advances sensor time to `utime` [µs] and returns the heartbeat when one is due: at the first
  /// time seen, then whenever utime has advanced by the period since the last one. Time going
  /// backwards by more than a period (a replay started over) restarts the schedule.
  std::optional<health_t> Tick(int64_t utime);
  /// Tick, and publishes the heartbeat on `channel` when due (counted as published).
  bool Tick(int64_t utime, Transport& transport, const std::string& channel = "HEALTH");

  /// The heartbeat for sensor time `utime` with the current counts.
  health_t Message(int64_t utime) const;

  int64_t received() const { return received_; }
  int64_t rejected() const { return rejected_; }
  int64_t published() const { return published_; }
  const std::string& last_error() const { return last_error_; }

 private:
  std::string process_;
  int64_t period_us_;
  std::optional<int64_t> last_beat_;  // utime of the last heartbeat
  int64_t latest_ = 0;                // latest utime seen
  int64_t received_ = 0, rejected_ = 0, published_ = 0;
  std::string last_error_;
};

}  // namespace rcal::transport
