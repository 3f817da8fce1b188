// What the filter processes (orientation_kf, position_kf) take from a cell file's IMU: its earth
// frame and gravity (unless given on the command line) and its full-scale ranges (what the
// process refuses beyond). Header-only: its users link rcal_io and rcal_transport already.
#pragma once

#include <CLI/CLI.hpp>
#include <stdexcept>
#include <string>

#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/transport/filter_nodes.hpp"

namespace rcal::services {

/// Applies `cell`'s IMU to a filter process's settings: `earth` (and its name for the log) and
/// `gravity` unless the command line gave --earth / --gravity, and the ranges. Throws
/// std::runtime_error naming the key when the cell has no IMU.
inline void ApplyCellImu(const io::CellSpec& cell, const CLI::App& app, const std::string& process,
                         estimation::EarthFrame* earth, std::string* earth_name, double* gravity,
                         transport::SensorRanges* ranges) {
  if (!cell.imu)
    throw std::runtime_error(cell.source + ": sensors.imu: absent, the cell has no IMU for " +
                             process);
  if (app.count("--earth") == 0) {
    *earth = cell.imu->earth;
    *earth_name = cell.imu->earth == estimation::EarthFrame::kEnu ? "enu" : "ned";
  }
  if (app.count("--gravity") == 0) *gravity = cell.imu->gravity;
  ranges->gyro = cell.imu->gyro_range;
  ranges->accel = cell.imu->accel_range;
  ranges->mag = cell.imu->mag_range;
}

}  // namespace rcal::services
