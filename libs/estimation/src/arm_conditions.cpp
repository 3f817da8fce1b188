#include "rcal/estimation/arm_conditions.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace rcal::estimation {

TimeGateSettings ArmConditionsGateSettings(TimeGateSettings sensor, double max_age) {
  if (std::isfinite(max_age) && max_age > 0)
    sensor.horizon_us =
        std::max(sensor.horizon_us, static_cast<int64_t>(std::llround(max_age * 1e6)));
  return sensor;
}

ArmConditionsHistory::ArmConditionsHistory(double max_age, std::size_t capacity)
    : max_age_(max_age), capacity_(capacity) {
  if (!(max_age >= 0.0) || std::isinf(max_age))
    throw std::invalid_argument("ArmConditionsHistory: max_age " + std::to_string(max_age) +
                                " s is not a finite figure ≥ 0");
  if (capacity == 0) throw std::invalid_argument("ArmConditionsHistory: capacity 0");
}

void ArmConditionsHistory::Add(const ArmConditionsReport& r) {
  if (!std::isfinite(r.t))
    throw std::invalid_argument("ArmConditionsHistory::Add: time not finite");
  if (!reports_.empty()) {
    if (r.t < reports_.back().t)
      throw std::invalid_argument("ArmConditionsHistory::Add: t " + std::to_string(r.t) +
                                  " s before the newest report's " +
                                  std::to_string(reports_.back().t) + " s");
    if (r.t == reports_.back().t) {
      reports_.back() = r;
      return;
    }
  }
  reports_.push_back(r);
  while (reports_.size() > capacity_) reports_.pop_front();
}

std::optional<ArmConditionsReport> ArmConditionsHistory::At(double t) const {
  // The first report after t; the one before it stands at t.
  const auto after =
      std::upper_bound(reports_.begin(), reports_.end(), t,
                       [](double time, const ArmConditionsReport& r) { return time < r.t; });
  if (after == reports_.begin()) return std::nullopt;
  const ArmConditionsReport& r = *std::prev(after);
  if (t - r.t > max_age_) return std::nullopt;
  return r;
}

ArmConditionsHistory::Window ArmConditionsHistory::ForWindow(double t_begin, double t_end,
                                                             double payload_tolerance_kg) const {
  Window w;
  w.standing = At(0.5 * (t_begin + t_end));
  // The payload as reported at the window's start, then each report inside it in time order.
  double last = std::numeric_limits<double>::quiet_NaN();
  if (const auto start = At(t_begin)) last = start->payload_kg;
  const auto inside =
      std::upper_bound(reports_.begin(), reports_.end(), t_begin,
                       [](double time, const ArmConditionsReport& r) { return time < r.t; });
  for (auto it = inside; it != reports_.end() && it->t <= t_end; ++it) {
    if (std::isnan(it->payload_kg)) continue;
    if (!std::isnan(last) && std::abs(it->payload_kg - last) > payload_tolerance_kg) {
      w.payload_change = *it;
      w.payload_before_kg = last;
      break;
    }
    last = it->payload_kg;
  }
  return w;
}

}  // namespace rcal::estimation
