#include "rcal/sim/imu_taps.hpp"

#include <cmath>

#include "rcal/sim/draw.hpp"

namespace rcal::sim {

ImuTaps::ImuTaps(std::uint64_t seed, const ImuTapsSettings& settings)
    : settings_(settings), rng_(seed) {
  next_ = settings_.first_after + Gap();
}

double ImuTaps::Gap() {
  return std::exponential_distribution<double>(1.0 / settings_.mean_gap)(rng_);
}

Eigen::Vector3d ImuTaps::At(double t) {
  if (t >= next_) {
    started_ = first_ = true;
    start_ = t;
    amplitude_ = std::uniform_real_distribution<double>(settings_.min_amplitude,
                                                        settings_.max_amplitude)(rng_);
    ringing_ = std::bernoulli_distribution(settings_.ringing_probability)(rng_);
    ++taps_;
    ringing_count_ += ringing_;
    // The next start from this one (not from `next_`): a gap never lands two taps on one sample.
    next_ = t + Gap();
  }
  const double age = t - start_;
  const bool on = started_ && (first_ || (ringing_ && age < settings_.ringing_duration));
  first_ = false;
  if (!on) return Eigen::Vector3d::Zero();
  const double magnitude =
      ringing_ ? amplitude_ * std::exp(-age / settings_.ringing_decay) : amplitude_;
  return magnitude * Draw3(normal_, rng_).normalized();
}

}  // namespace rcal::sim
