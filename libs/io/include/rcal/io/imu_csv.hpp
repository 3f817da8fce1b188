// IMU streams as CSV, the BROAD layout (../shared/data/broad/README.md), read by `rcal fuse` and
// `rcal analyze STREAM.csv`:
//   t_s                 time [s], finite, strictly increasing                       required
//   gyr_x, gyr_y, gyr_z angular rate [rad/s], IMU frame, |each| ≤ gyro range        required
//   acc_x, acc_y, acc_z specific force [m/s²], IMU frame, |each| ≤ accel range      required
//   mag_x, mag_y, mag_z magnetic field [µT], IMU frame, |each| ≤ magnetometer range required
//   q_w, q_x, q_y, q_z  truth orientation IMU → earth; all four NaN where occluded  optional
//   pos_x, pos_y, pos_z truth position [m]; NaN where occluded                      optional
//   movement            1 in a motion phase, 0 at rest                              optional
// A value beyond a sensor's range is no measurement that sensor can make (a corrupted cell, a
// wrong unit): the file is refused naming the column and the row, as for NaN where no gap is
// allowed. Gaps the format allows (NaN truth) are counted, not refused.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

namespace rcal::io {

/// Sensor ranges: a sample beyond them is refused. Defaults are above every BROAD trial (largest:
/// gyro 25 rad/s on trial 07, accelerometer 144 m/s² on trial 24's taps, field 57 µT on 33) and at
/// or above the full scale of common MEMS IMUs (±2000 °/s = 35 rad/s, ±16 g = 157 m/s²,
/// magnetometers to ±4900 µT).
struct ImuCsvSettings {
  double gyro_range_rad_s = 35.0;      ///< largest |gyr_*| [rad/s]
  double accel_range_m_s2 = 160.0;     ///< largest |acc_*| [m/s²]
  double mag_range_uT = 5000.0;        ///< largest |mag_*| [µT]
  double position_range_m = 1e6;       ///< largest |pos_*| [m]
  double quaternion_tolerance = 1e-3;  ///< largest | |q| − 1 | of a truth quaternion
  /// Refuse a stream whose units are not rcal's, naming the likely one: the median |acc| outside
  /// g/3 … 3g (in g? milli-g?), the median |mag| outside a factor of 3 of Earth's 22 … 67 µT
  /// (tesla? gauss? milligauss? nanotesla?; all zero is a stream without magnetometer, let
  /// through), the magnetic field turning in the IMU frame at π/180 of the rate the gyro reads
  /// (°/s?). A range refusal names the likely unit too.
  bool check_units = true;
};

/// One IMU stream, a sample per row.
struct ImuCsv {
  std::vector<double> t;                 // [s]
  std::vector<Eigen::Vector3d> gyro;     // [rad/s]
  std::vector<Eigen::Vector3d> accel;    // [m/s²]
  std::vector<Eigen::Vector3d> mag_uT;   // [µT]
  bool has_truth = false;                // q_w..q_z present
  std::vector<Eigen::Vector4d> q_truth;  // normalised [w,x,y,z]; all NaN where occluded
  bool has_position = false;             // pos_x..pos_z present
  std::vector<Eigen::Vector3d> p_truth;  // [m]; all NaN where any axis is NaN
  bool has_movement = false;             // movement present
  std::vector<int> movement;             // 0 or 1
  long truth_missing = 0;                // rows whose truth quaternion is NaN
  long position_missing = 0;             // rows whose truth position is NaN
};

/// Parses BROAD-layout CSV text. `source` names it in errors. Throws std::runtime_error
/// "SOURCE: row N column 'gyr_x' is 1e300: beyond the gyro range ±35 rad/s
/// (ImuCsvSettings::gyro_range_rad_s)" (row 1 = the first data row), and for a missing column,
/// non-finite values where no gap is allowed, time not increasing, a partial or non-unit truth
/// quaternion, a movement other than 0 or 1, or no rows.
ImuCsv ParseImuCsv(const std::string& text, const std::string& source,
                   const ImuCsvSettings& settings = {});
/// Reads a file: ParseImuCsv of its text.
ImuCsv LoadImuCsv(const std::filesystem::path& path, const ImuCsvSettings& settings = {});

/// The stream's sampling rate [Hz]: 1 / the median step between rows (a gap, where the IMU fell
/// silent, does not slow it as it would the mean). NaN with fewer than two rows.
double SampleRate(const ImuCsv& stream);

}  // namespace rcal::io
