// The conditions an arm works under (temperature, payload), as its controller reports them over
// time, and what a still window takes of them as its pose's context (issue 15, item 4: the
// extended model online needs each pose's temperature and payload; a real cell's controller
// reports them on their own stream, ARM_CONDITIONS, not inside the sensor samples).
//
// ArmConditionsHistory keeps the recent reports in sensor time and answers, for a window that
// ended at t, the newest report at or before t, when it is at most `max_age` old: sample and hold,
// as the controller's report stands until the next one. A report after t is not used for t (it
// may describe a payload picked up after the stop). Reports must arrive in non-decreasing time
// (the caller's time gate refuses the others); the history is bounded (`capacity`), the oldest
// dropped first, so a flood of reports cannot grow it.
#pragma once

#include <cstddef>
#include <deque>
#include <limits>
#include <optional>

#include "rcal/estimation/time_gate.hpp"

namespace rcal::estimation {

/// One report of the arm's conditions.
struct ArmConditionsReport {
  double t = 0.0;                                                   ///< sensor time [s]
  double temperature_c = std::numeric_limits<double>::quiet_NaN();  ///< [°C]; NaN: not measured
  double payload_kg = std::numeric_limits<double>::quiet_NaN();     ///< [kg]; NaN: not known
};

/// The time gate of a conditions stream: `sensor`'s settings with the horizon widened to at
/// least `max_age` [s]. A controller may report slowly (a temperature every 30 s); a report as far
/// after the last as a report may stand for a window is not "beyond the horizon" (with the
/// sensors' 10 s horizon such a stream would be refused report after report).
TimeGateSettings ArmConditionsGateSettings(TimeGateSettings sensor, double max_age);

class ArmConditionsHistory {
 public:
  /// `max_age` [s]: how old the newest report before a window's end may be and still stand for
  /// it; `capacity`: reports kept (≥ 1).
  explicit ArmConditionsHistory(double max_age = 10.0, std::size_t capacity = 4096);

  /// A report, in non-decreasing t (an older one throws std::invalid_argument: the caller gates
  /// time). A report at the same t as the newest replaces it.
  void Add(const ArmConditionsReport& r);

  /// The report that stands at sensor time t [s]: the newest with report.t ≤ t and
  /// t − report.t ≤ max_age; nullopt when there is none (never reported, all after t, or the
  /// newest before t is too old).
  std::optional<ArmConditionsReport> At(double t) const;

  /// Drops everything (the time base changed: a stream re-synchronised).
  void Clear() { reports_.clear(); }
  std::size_t size() const { return reports_.size(); }
  double max_age() const { return max_age_; }

 private:
  double max_age_;
  std::size_t capacity_;
  std::deque<ArmConditionsReport> reports_;
};

}  // namespace rcal::estimation
