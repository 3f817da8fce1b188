#include "rcal/sim/position_sensor_model.hpp"

#include "rcal/sim/draw.hpp"

namespace rcal::sim {

PositionSensorModel::PositionSensorModel(const PositionSensorSettings& settings, std::uint64_t seed)
    : settings_(settings) {
  Reset(seed);
}

void PositionSensorModel::Reset(std::uint64_t seed) {
  rng_.seed(seed);
  normal_.reset();
  uniform_.reset();
  started_ = false;
  next_t_ = 0.0;
  dropped_ = 0;
}

std::optional<PositionSample> PositionSensorModel::Sample(double t, const Eigen::Vector3d& p_W) {
  const double period = 1.0 / settings_.rate_hz;
  if (!started_) {
    started_ = true;
    next_t_ = t;
  }
  if (t < next_t_ - 1e-9 * period) return std::nullopt;
  next_t_ += period;
  if (t >= next_t_) next_t_ = t + period;  // the truth skipped a period: restart the clock
  // Draw both random numbers every firing so that switching effects keeps the others' noise.
  const Eigen::Vector3d n = Draw3(normal_, rng_);
  const double u = uniform_(rng_);
  if (settings_.dropouts && u < settings_.dropout_probability) {
    ++dropped_;
    return std::nullopt;
  }
  PositionSample s;
  s.t = t;
  s.t_available = t + (settings_.latency_enabled ? settings_.latency : 0.0);
  s.p_M = settings_.R_MW * p_W + settings_.t_MW;
  if (settings_.noise) s.p_M += settings_.sigma * n;
  return s;
}

}  // namespace rcal::sim
