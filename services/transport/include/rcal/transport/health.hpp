// The HEALTH heartbeat every process publishes: counts of messages received, rejected (with the
// last reason) and published; of the rejected, the duplicates, the out-of-horizon, out-of-order
// and stale ones; the messages missing (gaps), the time bases re-synchronised, the filter resets
// and the messages the transport lost below the process (dropped) (lcmtypes/health.lcm). Time comes
// from the messages' utime (sensor time), never from the wall clock, so a replay at any speed
// publishes the same heartbeats.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "rcal/estimation/time_gate.hpp"
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
  /// A message was refused as older than the state in use (counted in rejected and stale).
  void Stale(const std::string& reason);
  /// A message was refused as an exact duplicate (counted in rejected and duplicates).
  void Duplicate(const std::string& reason);
  /// A message was refused for a time beyond the horizon (rejected and out_of_horizon).
  void OutOfHorizon(const std::string& reason);
  /// A source's time base (or sequence) was re-synchronised; `reason` says which.
  void Resync(const std::string& reason);
  /// `n` messages never arrived (a gap in a sequence number or in a source's sample times).
  void Gap(int64_t n) { gaps_ += n; }
  /// The transport's count of messages lost below the process (Transport::Dropped); Tick with a
  /// transport takes it from there.
  void SetDropped(int64_t total) { dropped_ = total; }
  /// A filter's state went non-finite and it was reset; `reason` says which and when.
  void FilterReset(const std::string& reason);
  /// What the process is doing, in its own terms (health_t.activity; e.g. ekf_identifier's
  /// tracking status).
  void Activity(std::string activity) { activity_ = std::move(activity); }
  const std::string& activity() const { return activity_; }

  /// Offers the message's `utime` [µs] to the source's time gate and counts the outcome: a
  /// refused one in rejected (and duplicates / out_of_horizon / out_of_order) with the gate's
  /// reason naming `field`, new gaps of the source in gaps, a re-synchronisation in resyncs.
  /// Returns the verdict (estimation::Usable tells whether to use the message). Moves the gate's
  /// ceiling to estimation::HostCeilingUs() first.
  estimation::TimeVerdict Gate(estimation::TimeGate& gate, int64_t utime, const std::string& field);

  /// Advances sensor time to `utime` [µs] and returns the heartbeat when one is due: at the first
  /// time seen, then whenever utime has advanced by the period since the last one. Time going
  /// backwards by more than a period (a replay started over) restarts the schedule.
  std::optional<health_t> Tick(int64_t utime);
  /// Tick, and publishes the heartbeat on `channel` when due (counted as published).
  bool Tick(int64_t utime, Transport& transport, const std::string& channel = "HEALTH");

  /// Publishes the heartbeat now, whatever the schedule, at the latest sensor time seen: the
  /// final counts of a process that stops cleanly, so every loss up to its end is on record.
  bool Final(Transport& transport, const std::string& channel = "HEALTH");

  /// The heartbeat for sensor time `utime` with the current counts.
  health_t Message(int64_t utime) const;

  int64_t received() const { return received_; }
  int64_t rejected() const { return rejected_; }
  int64_t published() const { return published_; }
  int64_t duplicates() const { return duplicates_; }
  int64_t out_of_horizon() const { return out_of_horizon_; }
  int64_t out_of_order() const { return out_of_order_; }
  int64_t gaps() const { return gaps_; }
  int64_t resyncs() const { return resyncs_; }
  int64_t filter_resets() const { return filter_resets_; }
  int64_t stale() const { return stale_; }
  int64_t dropped() const { return dropped_; }
  const std::string& last_error() const { return last_error_; }

 private:
  // Publishes the heartbeat for `utime` with the transport's drop count (counted as published).
  bool Publish(int64_t utime, Transport& transport, const std::string& channel);
  std::string process_;
  int64_t period_us_;
  std::optional<int64_t> last_beat_;  // utime of the last heartbeat
  int64_t latest_ = 0;                // latest utime seen
  int64_t received_ = 0, rejected_ = 0, published_ = 0;
  int64_t duplicates_ = 0, out_of_horizon_ = 0, out_of_order_ = 0, gaps_ = 0, resyncs_ = 0,
          filter_resets_ = 0, stale_ = 0, dropped_ = 0;
  std::string last_error_;
  std::string activity_;
};

}  // namespace rcal::transport
