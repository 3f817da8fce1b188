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

/// Writes the stream in the BROAD layout (atomically).
void WriteImuStreamCsv(const std::filesystem::path& path,
                       const std::vector<sim::ImuStreamSample>& stream);

struct AnalyzeImuOptions {
  std::string data;
  std::string out = "out/analyze";
  std::string json_path;
  double alpha = 0.01;
};

/// `rcal analyze` on an IMU stream: DIR/report.md with plots and DIR/analysis.json.
int RunAnalyzeImu(const AnalyzeImuOptions& options);

}  // namespace rcal::tool
