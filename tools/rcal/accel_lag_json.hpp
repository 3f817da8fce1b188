// The accelerometer lag's figures as JSON, one shape for `rcal fuse` (its accel_lag) and
// `rcal accel-lag --json`: SI units in the keys.
#pragma once

#include <nlohmann/json.hpp>

#include "rcal/estimation/accel_lag.hpp"

namespace rcal::tool {

inline nlohmann::json AccelLagJson(const estimation::AccelLagEstimate& lag) {
  return {{"delay_s", lag.delay},
          {"delay_sigma_s", lag.delay_sigma},
          {"lever_arm_B_m", {lag.lever_arm_B.x(), lag.lever_arm_B.y(), lag.lever_arm_B.z()}},
          {"bias_W_m_s2", {lag.bias_W.x(), lag.bias_W.y(), lag.bias_W.z()}},
          {"triplets", lag.triplets},
          {"residual_rms_m_s2", lag.residual_rms},
          {"jerk_rms_m_s3", lag.jerk_rms}};
}

}  // namespace rcal::tool
