// The conditions an arm works under (temperature, payload), as its controller reports them over
// time, and what a still window takes of them as its pose's context (issue 15, item 4: the
// extended model online needs each pose's temperature and payload; a real cell's controller
// reports them on their own stream, ARM_CONDITIONS, not inside the sensor samples).
//
// ArmConditionsHistory keeps the recent reports in sensor time and answers, for a time t, the
// newest report at or before t, when it is at most `max_age` old: sample and hold, as the
// controller's report stands until the next one. A still window [t_begin, t_end] takes the report
// standing at its middle (ForWindow): a window's end is detected up to about a second into the
// next move (the arm starts slowly, under the still threshold), so the report at the end may
// already describe the next stop (a pick reported as the arm leaves), and a slowly changing
// temperature is best represented at the middle of the samples averaged. A window within which
// the reported payload changed (a grasp made at the stop, or reported as the arm left it) was
// measured under two loads: ForWindow names the change and the caller refuses the window. The
// reports of a window may reach the caller after the samples that end it (another process, another
// transport, a loaded CPU): a caller decides a window once ReportedPast its end (no report still
// to come can fall inside it), or once it has waited long enough. Reports must arrive in
// non-decreasing time (the caller's time gate refuses the others); the history is
// bounded (`capacity`), the oldest dropped first, so a flood of reports cannot grow it.
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

  /// What a still window over [t_begin, t_end] [s] takes of the reports (file comment).
  struct Window {
    /// The report standing at the window's middle, (t_begin + t_end) / 2 (At); nullopt: none.
    std::optional<ArmConditionsReport> standing;
    /// The first report within (t_begin, t_end] whose payload differs by more than the tolerance
    /// from the payload reported before it (the one standing at t_begin, or the window's earlier
    /// report); nullopt: the payload did not change. A payload not known (NaN) is no change.
    std::optional<ArmConditionsReport> payload_change;
    double payload_before_kg = std::numeric_limits<double>::quiet_NaN();  ///< before the change
  };
  /// A payload change below this [kg] is taken as the same payload (a controller re-estimating
  /// its payload reports small changes; 10 g is far below what bends an arm measurably).
  static constexpr double kPayloadTolerance = 0.01;
  Window ForWindow(double t_begin, double t_end,
                   double payload_tolerance_kg = kPayloadTolerance) const;

  /// Whether a report after sensor time t [s] has come: reports come in time order, so no report
  /// still to come can stand at or before t, and a window ending at t may be decided.
  bool ReportedPast(double t) const { return !reports_.empty() && reports_.back().t > t; }

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
