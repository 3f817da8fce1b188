// The time gate of one sample source (one channel of one sensor): decides, from its utime alone,
// whether a sample may reach a filter, so that one sample with a wrong time cannot poison the
// stream for ever (issue 11, item 3).
//
// Rules, for a sample at utime u of a source whose last accepted sample was at L:
//   u == L                      duplicate: refused, counted (an exact resend of the same sample);
//   u <  L                      out of order: refused, counted;
//   u >  L + horizon_us         beyond the horizon: refused, counted, never becomes L (a sample
//                               10 s ahead of a 100 Hz stream is a corrupt time, not a sample);
//   u >  ceiling_us             beyond the ceiling: refused whatever L is (also the first sample,
//                               which has no L yet: the nodes set the ceiling from the host clock,
//                               a day ahead of it, so 2^62 µs can never become the time base);
//   else                        accepted, L = u.
// Re-synchronisation: a source whose time really jumped (a restarted driver starting over, a
// pause longer than the horizon) sends samples that are all refused as out of order or beyond
// the horizon. When `resync_samples` such refused samples in a row are consistent with each other
// (each after the previous one, by at most horizon_us, and under the ceiling), the last of them
// is accepted as the new time base (verdict kResynchronised: the caller resets what depends on
// time order, e.g. its filter). A single corrupt sample is never consistent with the stream that
// follows it, so it never re-synchronises the source.
// Gaps: the source's period is taken as the smallest step between accepted samples; a step larger
// than gap_factor periods counts round(step / period) − 1 samples missing (lost on the wire, in
// LCM's receive queue, or never sent).
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace rcal::estimation {

struct TimeGateSettings {
  /// A sample more than this past the last accepted sample of its source is refused [µs].
  int64_t horizon_us = 10'000'000;
  /// Consecutive, mutually consistent refused samples that re-synchronise the source [-] (≥ 1).
  int resync_samples = 5;
  /// A time going back by less than this is late data, never a new time base [µs]: a burst of
  /// delayed resends (a sender descheduled under load) is a consistent, increasing run of
  /// out-of-order samples just below the last one, and must not pull the stream back. A restarted
  /// driver that goes back by less is accepted again once it passes the last time.
  int64_t resync_min_jump_back_us = 1'000'000;
  /// No sample later than this is accepted [µs] (INT64_MAX: no ceiling). See SetCeiling.
  int64_t ceiling_us = std::numeric_limits<int64_t>::max();
  /// A step above gap_factor × the period counts the missing samples [-]; ≤ 1: no gap count.
  double gap_factor = 1.5;
};

enum class TimeVerdict {
  kAccepted,        ///< use the sample
  kResynchronised,  ///< use the sample, the source's time base moved: reset what depends on it
  kDuplicate,       ///< refused: same utime as the last accepted sample
  kOutOfOrder,      ///< refused: before the last accepted sample
  kBeyondHorizon,   ///< refused: beyond the horizon or the ceiling
};

/// True for kAccepted and kResynchronised.
inline bool Usable(TimeVerdict v) {
  return v == TimeVerdict::kAccepted || v == TimeVerdict::kResynchronised;
}

class TimeGate {
 public:
  struct Counters {
    int64_t accepted = 0;        ///< samples accepted (including re-synchronisations)
    int64_t duplicates = 0;      ///< refused as exact duplicates
    int64_t out_of_order = 0;    ///< refused as before the last accepted sample
    int64_t beyond_horizon = 0;  ///< refused beyond the horizon or the ceiling
    int64_t resyncs = 0;         ///< re-synchronisations
    int64_t gap_samples = 0;     ///< samples missing between accepted ones (see the header)
  };

  explicit TimeGate(const TimeGateSettings& settings = {});

  /// Judges one sample at `utime` [µs] and updates the state (see the header).
  TimeVerdict Offer(int64_t utime);
  /// A reason naming `field` for a refused verdict of the sample at `utime` ("" when usable).
  /// Call right after Offer (it quotes the last accepted time).
  std::string Reason(TimeVerdict v, int64_t utime, const std::string& field) const;

  /// Moves the ceiling [µs] (the nodes follow the host clock with it).
  void SetCeiling(int64_t ceiling_us) { settings_.ceiling_us = ceiling_us; }
  /// Sets the last accepted time [µs] (a trusted checkpoint's time) without counting a sample.
  void Restore(int64_t last_utime);
  /// Forgets the time base, the run and the period (counters are kept).
  void Reset();

  /// utime of the last accepted sample [µs], none before the first.
  std::optional<int64_t> last() const { return last_; }
  /// The period estimate [µs] (0 before two samples were accepted).
  int64_t period_us() const { return period_; }
  const Counters& counters() const { return counters_; }
  const TimeGateSettings& settings() const { return settings_; }

 private:
  TimeVerdict Refuse(TimeVerdict v, int64_t utime);
  void Accept(int64_t utime);

  TimeGateSettings settings_;
  Counters counters_;
  std::optional<int64_t> last_;
  int run_ = 0;           // consistent refused samples in a row
  int64_t run_last_ = 0;  // utime of the last of them
  int64_t period_ = 0;
};

/// The host clock as a ceiling [µs since the Unix epoch]: now + `ahead_s`. Sensor time is either
/// epoch time (never ahead of the host by a day) or time since a start (far behind it), so a
/// sample past this is a corrupt time. The only wall-clock read of the filter path, and only as
/// a bound: filters still run on sensor time.
int64_t HostCeilingUs(double ahead_s = 86'400.0);

}  // namespace rcal::estimation
