/// Taps and knocks on the tool, as its IMU's accelerometer feels them: shocks of tens of m/s²
/// that last a few milliseconds or ring for tens, while the tool itself hardly moves (BROAD's
/// tapping trials: 30–70 m/s² for about 80 ms). A disturbance for the position KF's tests and
/// sweeps (estimation::PositionKf's accelerometer gate and rollback are for it); seeded.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <random>

namespace rcal::sim {

struct ImuTapsSettings {
  double mean_gap = 2.0;        ///< mean time between tap starts [s] (exponential gaps)
  double first_after = 1.0;     ///< no tap before this time [s] (plus the first gap)
  double min_amplitude = 30.0;  ///< [m/s²]
  double max_amplitude = 70.0;  ///< [m/s²] (uniform between the two)
  /// Probability that a tap rings (else it is one sample: a knock shorter than the sample period).
  double ringing_probability = 0.5;
  double ringing_duration = 0.08;  ///< how long a ringing tap lasts [s]
  /// Decay time constant of a ringing tap's magnitude, A e^{−age/τ} [s].
  double ringing_decay = 0.04;
};

/// The taps' specific force, sample by sample. Each tap starts at the first sample at or after its
/// time, with an amplitude A drawn uniformly. A one-sample tap adds A along a random direction to
/// that sample alone. A ringing tap adds A e^{−age/τ} along a new random direction to every sample
/// within ringing_duration of its start: the 100 Hz samples of a ringing at hundreds of Hz alias
/// to random signs and directions. A tap still ringing when the next one starts is cut short.
class ImuTaps {
 public:
  explicit ImuTaps(std::uint64_t seed, const ImuTapsSettings& settings = {});
  /// The tap's specific force [m/s²] (sensor frame) to add to the accelerometer sample at t [s].
  /// Call once per sample, t not decreasing.
  Eigen::Vector3d At(double t);
  /// Taps started so far, and how many of them ring.
  int taps() const { return taps_; }
  int ringing() const { return ringing_count_; }

 private:
  double Gap();
  ImuTapsSettings settings_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  double next_ = 0.0;
  double start_ = 0.0;
  double amplitude_ = 0.0;
  bool started_ = false, ringing_ = false, first_ = false;
  int taps_ = 0, ringing_count_ = 0;
};

}  // namespace rcal::sim
