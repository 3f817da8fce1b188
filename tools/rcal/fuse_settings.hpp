// The one set of filter settings `rcal fuse` and `rcal fuse-loo` use for every BROAD trial
// (IMU → ENU, magnetic north on +y), with the --set NAME=VALUE overrides both take.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/io/imu_csv.hpp"

namespace rcal::tool {

struct FuseSettings {
  estimation::OrientationKfSettings orientation;
  estimation::PositionKfSettings position;
  io::ImuCsvSettings imu;            ///< sensor ranges the trial is checked against
  estimation::AidedInsSettings ins;  ///< the tracker-aided INS (aided_ins.hpp)
  /// The INS's heading: 0 the magnetometer field the orientation KF accepted, levelled with the
  /// INS's tilt; 1 the orientation KF's heading.
  int ins_heading_from_kf = 0;
};

/// The BROAD settings with `overrides` applied: each NAME=VALUE, NAME as in the JSON settings
/// with or without its unit (tilt_sigma or tilt_sigma_rad), VALUE one finite number in SI
/// units. Throws std::runtime_error naming the setting for an unknown name or a bad value.
/// pos_noise_m [m]: the simulated position sensor's noise, the position KF's σ.
FuseSettings BroadSettingsWith(const std::vector<std::string>& overrides,
                               double pos_noise_m = 1e-3);

/// The longest IMU step the orientation KF and the INS integrate, for a stream sampled at
/// rate_hz [Hz] (io::SampleRate): three of its periods where that is longer than their max_step
/// (estimation::MaxStepForRate), so that a slow IMU is not taken for a silent one and restarted
/// at every sample. A rate that is not finite and positive leaves the settings.
void SetMaxStepForRate(FuseSettings& s, double rate_hz);

/// Every overridable filter setting, key name_unit → value (SI).
nlohmann::json SettingsJson(const FuseSettings& s);
/// The sensor ranges, key name_unit → value (the magnetometer's in µT, the file's unit).
nlohmann::json ImuRangesJson(const FuseSettings& s);

}  // namespace rcal::tool
