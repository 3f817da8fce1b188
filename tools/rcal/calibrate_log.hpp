// `rcal calibrate-log LOG` and its alias `rcal calibrate --log LOG`: one code path
// (cmd_calibrate_log.cpp).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

namespace rcal::tool {

struct CalibrateLogOptions {
  std::string log;
  std::string robot = "config/robots/grb3016.yaml";
  std::string channel;  ///< empty: POSE_MEASUREMENT (transport::channels::kPoseMeasurement)
  unsigned ident_seed = 1;
  bool position_only = false;
  unsigned cell_seed = 0;  ///< > 0: the simulated cell (ekf_identifier --cell-seed)
  int guess_poses = 6;     ///< with a cell: poses held back for the set-up guess
  std::string json_path;
  bool allow_gaps = false;  ///< go on when the log lost data (CheckLogGaps); else exit non-zero
};

/// The options calibrate-log has besides LOG, --robot and --json (which `calibrate` shares):
/// --channel, --ident-seed, --position-only, --cell-seed, --guess-poses, --allow-gaps. `suffix` is
/// appended to each description.
void AddCalibrateLogOptions(CLI::App& sub, CalibrateLogOptions& o, const std::string& suffix);

/// Runs the identification over the log; returns the exit code. Throws std::runtime_error
/// naming the file when the log cannot be read.
int RunCalibrateLog(const CalibrateLogOptions& o);

}  // namespace rcal::tool
