// `rcal experiment paper --sensors`: the report of the sensor-level experiment (issue 4) on the
// simulated cell of libs/cell (rcal/cell/sim_cell.hpp), with peg-in-hole and the robustness sweep.
#pragma once

#include <string>

#include "rcal/cell/sim_cell.hpp"

namespace rcal::tool::exp {

using cell::Cell;
using cell::MakeCell;
using cell::MakeEkf;
using cell::OnlineResult;
using cell::RunOnline;
using cell::RunSettings;
using cell::SetupGuess;
using cell::SimulateWindows;
using cell::Windows;

struct ReportOptions {
  std::string robot = "config/robots/grb3016.yaml";
  std::string out = "out/experiment_sensors";
  std::string json_path;
  unsigned seed = 1;
  int num_cal = 50, num_test = 50;
  bool sweep = true;
  bool peg = true;
};
/// `rcal experiment paper --sensors`: everything, into out/report.md, PNGs and results.json.
int RunSensorsExperiment(const ReportOptions& o);

}  // namespace rcal::tool::exp
