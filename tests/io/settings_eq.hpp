// Field-by-field equality of the settings structs a cell file sets (estimation::
// PosePipelineSettings with its nested filter settings, identification::EkfSettings), so that a
// field added to or changed in one of them shows up as a named failure. Shared by the io and
// cell tests.
#pragma once

#include <gtest/gtest.h>

#include "rcal/estimation/pose_pipeline.hpp"
#include "rcal/identification/ekf_identifier.hpp"

namespace rcal::testing {

#define RCAL_EXPECT_FIELD(a, b, f) EXPECT_EQ((a).f, (b).f) << #f

inline void ExpectSameSettings(const estimation::OrientationKfSettings& a,
                               const estimation::OrientationKfSettings& b) {
  RCAL_EXPECT_FIELD(a, b, gravity);
  RCAL_EXPECT_FIELD(a, b, angular_accel_noise);
  RCAL_EXPECT_FIELD(a, b, gyro_bias_random_walk);
  RCAL_EXPECT_FIELD(a, b, attitude_process_noise);
  RCAL_EXPECT_FIELD(a, b, rate_proportional_noise);
  RCAL_EXPECT_FIELD(a, b, gyro_noise_density);
  RCAL_EXPECT_FIELD(a, b, tilt_sigma);
  RCAL_EXPECT_FIELD(a, b, heading_sigma);
  RCAL_EXPECT_FIELD(a, b, accel_lowpass_tau);
  RCAL_EXPECT_FIELD(a, b, mag_lowpass_tau);
  RCAL_EXPECT_FIELD(a, b, accel_norm_tolerance);
  RCAL_EXPECT_FIELD(a, b, tilt_gate_chi2);
  RCAL_EXPECT_FIELD(a, b, mag_norm_tolerance);
  RCAL_EXPECT_FIELD(a, b, mag_dip_tolerance);
  RCAL_EXPECT_FIELD(a, b, heading_gate_chi2);
  RCAL_EXPECT_FIELD(a, b, mag_ref_norm);
  RCAL_EXPECT_FIELD(a, b, mag_ref_dip);
  RCAL_EXPECT_FIELD(a, b, mag_reference_tau);
  RCAL_EXPECT_FIELD(a, b, mag_new_reference_time);
  RCAL_EXPECT_FIELD(a, b, still_gyro);
  RCAL_EXPECT_FIELD(a, b, still_accel);
  RCAL_EXPECT_FIELD(a, b, zero_rate_sigma);
  RCAL_EXPECT_FIELD(a, b, initial_attitude_sigma);
  RCAL_EXPECT_FIELD(a, b, initial_rate_sigma);
  RCAL_EXPECT_FIELD(a, b, initial_bias_sigma);
  RCAL_EXPECT_FIELD(a, b, gyro_range);
  RCAL_EXPECT_FIELD(a, b, accel_range);
  RCAL_EXPECT_FIELD(a, b, earth);
  RCAL_EXPECT_FIELD(a, b, estimate_gyro_bias);
  RCAL_EXPECT_FIELD(a, b, learn_in_motion);
  RCAL_EXPECT_FIELD(a, b, decoupled_fqa);
  RCAL_EXPECT_FIELD(a, b, reject_accel);
  RCAL_EXPECT_FIELD(a, b, reject_mag);
  RCAL_EXPECT_FIELD(a, b, mag_reference_samples);
  RCAL_EXPECT_FIELD(a, b, zero_rate_update);
  RCAL_EXPECT_FIELD(a, b, still_samples);
}

inline void ExpectSameSettings(const estimation::PositionKfSettings& a,
                               const estimation::PositionKfSettings& b) {
  RCAL_EXPECT_FIELD(a, b, earth);
  RCAL_EXPECT_FIELD(a, b, gravity);
  RCAL_EXPECT_FIELD(a, b, jerk_noise);
  RCAL_EXPECT_FIELD(a, b, accel_sigma);
  RCAL_EXPECT_FIELD(a, b, position_sigma);
  RCAL_EXPECT_FIELD(a, b, position_gate_chi2);
  RCAL_EXPECT_FIELD(a, b, max_consecutive_rejections);
  RCAL_EXPECT_FIELD(a, b, initial_velocity_sigma);
  RCAL_EXPECT_FIELD(a, b, initial_accel_sigma);
  RCAL_EXPECT_FIELD(a, b, accel_bias_walk);
  RCAL_EXPECT_FIELD(a, b, accel_relative_sigma);
  RCAL_EXPECT_FIELD(a, b, accel_noise_adaptation_tau);
  RCAL_EXPECT_FIELD(a, b, accel_noise_max_scale);
}

inline void ExpectSameSettings(const estimation::StillDetectorSettings& a,
                               const estimation::StillDetectorSettings& b) {
  RCAL_EXPECT_FIELD(a, b, joint_rate_threshold);
  RCAL_EXPECT_FIELD(a, b, gyro_threshold);
  RCAL_EXPECT_FIELD(a, b, accel_threshold);
  RCAL_EXPECT_FIELD(a, b, gravity);
  RCAL_EXPECT_FIELD(a, b, min_duration);
}

inline void ExpectSameSettings(const estimation::PosePipelineSettings& a,
                               const estimation::PosePipelineSettings& b) {
  ExpectSameSettings(a.orientation, b.orientation);
  ExpectSameSettings(a.position, b.position);
  ExpectSameSettings(a.still, b.still);
  RCAL_EXPECT_FIELD(a, b, settle_time);
  RCAL_EXPECT_FIELD(a, b, min_window_samples);
  RCAL_EXPECT_FIELD(a, b, min_raw_samples);
  RCAL_EXPECT_FIELD(a, b, max_gap);
  RCAL_EXPECT_FIELD(a, b, use_orientation);
  RCAL_EXPECT_FIELD(a, b, covariance_scale);
  RCAL_EXPECT_FIELD(a, b, position_floor_sigma);
  RCAL_EXPECT_FIELD(a, b, orientation_floor_sigma);
  RCAL_EXPECT_FIELD(a, b, rest_from_joints);
  RCAL_EXPECT_FIELD(a, b, accel_bias_sigma);
  RCAL_EXPECT_FIELD(a, b, accel_bias_random_walk);
}

inline void ExpectSameSettings(const identification::EkfSettings& a,
                               const identification::EkfSettings& b) {
  RCAL_EXPECT_FIELD(a, b, prior_sigma_length);
  RCAL_EXPECT_FIELD(a, b, prior_sigma_angle);
  RCAL_EXPECT_FIELD(a, b, drift_sigma_length);
  RCAL_EXPECT_FIELD(a, b, drift_sigma_angle);
  RCAL_EXPECT_FIELD(a, b, gate_probability);
  RCAL_EXPECT_FIELD(a, b, gate_after);
  RCAL_EXPECT_FIELD(a, b, max_iterations);
  RCAL_EXPECT_FIELD(a, b, iteration_tolerance);
  RCAL_EXPECT_FIELD(a, b, relinearize_threshold);
  RCAL_EXPECT_FIELD(a, b, max_relinearize_passes);
  EXPECT_EQ(a.prior_sigma_effects.size(), b.prior_sigma_effects.size());
  EXPECT_EQ(a.drift_sigma_effects.size(), b.drift_sigma_effects.size());
}

#undef RCAL_EXPECT_FIELD

}  // namespace rcal::testing
