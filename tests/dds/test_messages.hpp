// Deterministic LCM messages shared by the DDS tests and their publisher process: the truth the
// DDS side is compared with. Values are chosen to catch any lossy step: thirds, -0.0, the
// smallest subnormal, huge and tiny magnitudes, a utime that is not whole seconds.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include "rcal/calibration_status_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"

namespace rcal::dds::testing {

/// Sensor time of version `version` [µs]: 10 s apart, with a sub-second part.
inline int64_t TestUtime(int version) {
  return int64_t{version} * 10'000'000 + 123'457;
}

/// KINEMATIC_PARAMS, version `version` (≥ 1), 28 parameters of a 6R arm + 4-parameter tool.
inline kinematic_params_t TestParams(int version, const std::string& robot_id = "robot_a") {
  kinematic_params_t m;
  m.utime = TestUtime(version);
  m.robot_id = robot_id;
  m.model_id = "grb3016:00c0ffee12345678";
  const char* kinds[] = {"a", "alpha", "d", "theta"};
  for (int j = 1; j <= 7; ++j)
    for (const char* k : kinds)
      m.names.push_back(std::string(k) + (j == 7 ? "_tool" : std::to_string(j)));
  m.num_params = static_cast<int32_t>(m.names.size());
  for (int i = 0; i < m.num_params; ++i) {
    double v = (i + 1) / 3.0 * 1e-3 * version;
    if (i % 7 == 3) v = -v;
    m.values.push_back(v);
    m.sigmas.push_back(std::ldexp(1.0 + i / 7.0, -20 - i) / version);
    m.identified.push_back(i % 5 != 4);
  }
  m.values[5] = -0.0;
  m.values[6] = std::numeric_limits<double>::denorm_min();
  m.values[7] = 1e300 * version;
  m.sigmas[4] = 0.0;  // not identified
  m.poses_used = 10 * version;
  // Two effect parameters (an extended identifier's), values and σ exact in binary.
  m.num_effect_params = 2;
  m.effect_names = {"joint_compliance.j2.c", "thermal.k"};
  m.effect_units = {"rad/(N*m)", "1/K"};
  m.effect_values = {std::ldexp(3.0, -20) * version, -std::ldexp(5.0, -18)};
  m.effect_sigmas = {std::ldexp(1.0, -23), std::ldexp(1.0, -21) / version};
  return m;
}

inline calibration_status_t TestStatus(int version) {
  calibration_status_t m{};  // value-initialised: every field set, also those added later
  m.utime = TestUtime(version);
  m.poses_accepted = 10 * version;
  m.poses_rejected = version;
  m.last_rejection = "pose " + std::to_string(version) + ": NIS 31.7 above the gate";
  m.condition_number = 123.456 * version;
  m.rms_position_residual = 3.5e-5 / version;
  m.rms_orientation_residual = 1.0 / 3.0 * 1e-3;
  m.last_nis = 5.25 + version;
  m.relinearizations = version;
  m.converged = version % 2;
  return m;
}

/// ORIENTATION number k of version `version`.
inline orientation_estimate_t TestOrientation(int version, int k) {
  orientation_estimate_t m;
  m.utime = TestUtime(version) + int64_t{k} * 10'000;
  const double a = 0.1 * k + version;
  m.q_EI[0] = std::cos(a / 2);
  m.q_EI[1] = std::sin(a / 2) / std::sqrt(3.0);
  m.q_EI[2] = -std::sin(a / 2) / std::sqrt(3.0);
  m.q_EI[3] = std::sin(a / 2) / std::sqrt(3.0);
  for (int i = 0; i < 9; ++i) m.covariance[i] = (i % 4 == 0) ? 1e-6 * (1 + i) : 1e-9 / (1 + i);
  for (int i = 0; i < 3; ++i) m.gyro_bias[i] = 0;
  return m;
}

/// TOOL_POSITION number k of version `version` (same utime as TestOrientation(version, k)).
inline tool_position_estimate_t TestToolPosition(int version, int k) {
  tool_position_estimate_t m;
  m.utime = TestUtime(version) + int64_t{k} * 10'000;
  for (int i = 0; i < 3; ++i) {
    m.p[i] = 0.5 + i / 3.0 + 1e-3 * k + version;
    m.v[i] = -0.01 * (i + 1) * k;
  }
  for (int i = 0; i < 36; ++i) m.covariance[i] = (i % 7 == 0) ? 1e-8 * (1 + i) : 1e-12 * i;
  return m;
}

}  // namespace rcal::dds::testing
