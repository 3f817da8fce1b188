// `rcal calibrate-log LOG` and its alias `rcal calibrate --log LOG`: one code path
// (cmd_calibrate_log.cpp).
#pragma once

#include <string>
#include "cli.hpp"

namespace rcal::tool {

struct CalibrateLogOptions {
  std::string log;
  std::string cell = "config/cells/grb3016.yaml";  ///< the cell file (ekf_identifier --cell)
  std::string channel;                             ///< empty: the cell's channels.pose_measurement
  std::string json_path;
  bool allow_gaps = false;  ///< go on when the log lost data (CheckLogGaps); else exit non-zero
  /// analysis.json: the effects identified with the geometry, as ekf_identifier --effects
  /// (empty: none).
  std::string effects_path;
};

/// The options calibrate-log has besides LOG, --cell and --json (which `calibrate` shares):
/// --channel, --allow-gaps. `suffix` is appended to each description.
void AddCalibrateLogOptions(Args& sub, CalibrateLogOptions& o, const std::string& suffix);

/// Runs the identification over the log; returns the exit code. Throws std::runtime_error
/// naming the file when the log cannot be read.
int RunCalibrateLog(const CalibrateLogOptions& o);

}  // namespace rcal::tool
