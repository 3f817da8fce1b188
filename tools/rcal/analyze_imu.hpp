// The IMU-stream branch of `rcal analyze` (discrepancy/imu_analysis.hpp) and the BROAD-layout CSV
// reader and writer it uses; `rcal simulate-imu` writes a simulated stream (sim/imu_stream.hpp).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "rcal/discrepancy/imu_analysis.hpp"
#include "rcal/sim/imu_stream.hpp"

namespace rcal::tool {

/// True when the CSV's header (after '#' comments) has a gyr_x column: the BROAD layout.
bool IsImuStreamCsv(const std::string& path);

/// Reads a BROAD-layout CSV. Required: t_s, gyr_*, acc_*, mag_*; optional: q_w..q_z, movement.
/// Throws std::runtime_error naming the file, the column and the row for bad input.
discrepancy::ImuStreamData LoadImuStreamCsv(const std::string& path);

/// The IMU channel of an LCM log of the pipeline.
struct ImuLog {
  discrepancy::ImuStreamData data;  ///< no truth; movement from the joints when they were logged
  int joint_readings = 0;           ///< joint-rate readings behind `movement` (0: none, detected)
};

/// The IMU channel of an LCM log of the pipeline (imu_sample_t, field in T → µT): samples that
/// fail to decode, are not finite, lack the magnetometer, or are not after the previous one are
/// skipped and counted (a warning names the first reason). No truth orientation. When the log
/// has `joints_channel` (joint_state_t), each sample's movement flag is the arm's state from its
/// joints, as the pose pipeline's StillDetector judges it (joint rate below its threshold: still);
/// otherwise no movement flag (rests are detected from the IMU). The log's read summary is
/// printed (CheckLogGaps): when frames were broken or events did not decode, throws unless
/// `allow_gaps`. Throws std::runtime_error when the log cannot be read or has no samples.
ImuLog LoadImuStreamLog(const std::string& path, const std::string& channel,
                        bool allow_gaps = false, const std::string& joints_channel = "JOINTS");

/// Writes the stream in the BROAD layout (atomically).
void WriteImuStreamCsv(const std::filesystem::path& path,
                       const std::vector<sim::ImuStreamSample>& stream);

struct AnalyzeImuOptions {
  std::string data;
  std::string out = "out/analyze";
  std::string json_path;
  double alpha = 0.01;
  std::string channel = "IMU";  ///< for an LCM log: the imu_sample_t channel
  /// For an LCM log: the joint_state_t channel the rests come from ("" or absent: detected).
  std::string joints_channel = "JOINTS";
  bool allow_gaps = false;  ///< for an LCM log: go on when it lost data (CheckLogGaps)
};

/// `rcal analyze` on an IMU stream: DIR/report.md with plots and DIR/analysis.json.
int RunAnalyzeImu(const AnalyzeImuOptions& options);

}  // namespace rcal::tool
