// Position sensor model (camera / laser tracker on the marker), sampled from truth positions.
//   p_M = R_MW p_W + t_MW + n,  n white with σ per axis [m]  (frame M: the sensor's own frame)
// Every effect switchable: rate decimation, noise, latency (the sample of time t becomes
// available at t + latency), random dropouts (probability per sample). Seeded with an explicit
// std::mt19937_64 seed.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <random>

namespace rcal::sim {

struct PositionSample {
  double t = 0.0;            ///< time the position refers to [s]
  double t_available = 0.0;  ///< time the sample reaches the user: t + latency [s]
  Eigen::Vector3d p_M = Eigen::Vector3d::Zero();  ///< measured position in M [m]
};

struct PositionSensorSettings {
  double rate_hz = 20.0;  ///< output rate [Hz]; the truth must be sampled at least as fast
  bool noise = true;
  double sigma = 1e-3;  ///< white noise per axis [m]
  bool latency_enabled = false;
  double latency = 0.02;  ///< [s]
  bool dropouts = false;
  double dropout_probability = 0.05;  ///< [-] per sample
  /// Sensor frame pose: p_M = R_MW p_W + t_MW (identity by default).
  Eigen::Matrix3d R_MW = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_MW = Eigen::Vector3d::Zero();  ///< [m]
};

class PositionSensorModel {
 public:
  PositionSensorModel(const PositionSensorSettings& settings, std::uint64_t seed);
  void Reset(std::uint64_t seed);
  /// Offers the truth position p_W [m] at t [s] (increasing). Returns a sample when the sensor
  /// fires at this time (every 1/rate_hz s) and the sample is not dropped.
  std::optional<PositionSample> Sample(double t, const Eigen::Vector3d& p_W);
  std::int64_t dropped() const { return dropped_; }

 private:
  PositionSensorSettings settings_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
  double next_t_ = 0.0;
  bool started_ = false;
  std::int64_t dropped_ = 0;
};

}  // namespace rcal::sim
