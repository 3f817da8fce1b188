#include "rcal/estimation/time_gate.hpp"

#include <chrono>
#include <cmath>

namespace rcal::estimation {
namespace {

// b − a for b > a, exact as unsigned (the true difference is below 2^64), saturated to int64.
int64_t Step(int64_t a, int64_t b) {
  const uint64_t d = static_cast<uint64_t>(b) - static_cast<uint64_t>(a);
  return d > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())
             ? std::numeric_limits<int64_t>::max()
             : static_cast<int64_t>(d);
}

}  // namespace

TimeGate::TimeGate(const TimeGateSettings& settings) : settings_(settings) {
  if (settings_.resync_samples < 1) settings_.resync_samples = 1;
  if (settings_.horizon_us < 1) settings_.horizon_us = 1;
}

void TimeGate::Restore(int64_t last_utime) {
  Reset();
  last_ = last_utime;
}

void TimeGate::Reset() {
  last_.reset();
  run_ = 0;
  run_last_ = 0;
  period_ = 0;
}

void TimeGate::Accept(int64_t utime) {
  if (last_) {
    const int64_t step = Step(*last_, utime);  // utime > *last_ here
    if (step > 0 && (period_ == 0 || step < period_)) period_ = step;
    if (period_ > 0 && settings_.gap_factor > 1.0 &&
        static_cast<double>(step) > settings_.gap_factor * static_cast<double>(period_))
      counters_.gap_samples += std::llround(static_cast<double>(step) / period_) - 1;
  }
  last_ = utime;
  run_ = 0;
  ++counters_.accepted;
}

TimeVerdict TimeGate::Refuse(TimeVerdict v, int64_t utime) {
  if (v == TimeVerdict::kDuplicate) {
    ++counters_.duplicates;
    return v;  // a resend is no evidence of a new time base
  }
  // The run of refused samples: consistent when each is after the previous, within the horizon,
  // and under the ceiling (a time beyond it never becomes a time base).
  const bool late = v == TimeVerdict::kOutOfOrder && last_ &&
                    Step(utime, *last_) < settings_.resync_min_jump_back_us;
  if (late) {
    run_ = 0;  // late data interrupts a run of evidence for a new time base
  } else if (utime <= settings_.ceiling_us) {
    const bool consistent =
        run_ > 0 && utime > run_last_ && Step(run_last_, utime) <= settings_.horizon_us;
    run_ = consistent ? run_ + 1 : 1;
    run_last_ = utime;
    if (run_ >= settings_.resync_samples) {
      // A new time base: the period and the gap count start over (the jump is not a gap).
      last_ = utime;
      period_ = 0;
      run_ = 0;
      ++counters_.accepted;
      ++counters_.resyncs;
      return TimeVerdict::kResynchronised;
    }
  }
  if (v == TimeVerdict::kOutOfOrder)
    ++counters_.out_of_order;
  else
    ++counters_.beyond_horizon;
  return v;
}

TimeVerdict TimeGate::Offer(int64_t utime) {
  if (utime > settings_.ceiling_us) return Refuse(TimeVerdict::kBeyondHorizon, utime);
  if (!last_) {
    Accept(utime);
    return TimeVerdict::kAccepted;
  }
  if (utime == *last_) return Refuse(TimeVerdict::kDuplicate, utime);
  if (utime < *last_) return Refuse(TimeVerdict::kOutOfOrder, utime);
  if (Step(*last_, utime) <= settings_.horizon_us) {
    Accept(utime);
    return TimeVerdict::kAccepted;
  }
  return Refuse(TimeVerdict::kBeyondHorizon, utime);
}

std::string TimeGate::Reason(TimeVerdict v, int64_t utime, const std::string& field) const {
  const std::string u = std::to_string(utime);
  const std::string l = last_ ? std::to_string(*last_) : std::string("none");
  switch (v) {
    case TimeVerdict::kDuplicate:
      return field + ": " + u + " duplicates the last sample";
    case TimeVerdict::kOutOfOrder:
      return field + ": " + u + " is not after the last sample (" + l + ")";
    case TimeVerdict::kBeyondHorizon:
      if (utime > settings_.ceiling_us)
        return field + ": " + u + " is beyond the time ceiling (" +
               std::to_string(settings_.ceiling_us) + ")";
      return field + ": " + u + " is more than " + std::to_string(settings_.horizon_us) +
             " us past the last sample (" + l + ")";
    default:
      return "";
  }
}

int64_t HostCeilingUs(double ahead_s) {
  const auto now = std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch())
                       .count();
  return static_cast<int64_t>(now) + static_cast<int64_t>(ahead_s * 1e6);
}

}  // namespace rcal::estimation
