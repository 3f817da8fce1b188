// `rcal experiment paper --sensors --sweep-seeds N`: the robustness sweep of the sensor-level
// experiment ("what sensor a user needs") over N seeds per configuration, as statistics (median,
// 10th–90th percentile) of the test position error against the truth, with the Cramér–Rao
// prediction of each run alongside.
//
// Every run is independent and reproducible alone: configuration number k (fixed per
// configuration, baseline 0) and seed index i give the run seed 10000·k + i, which seeds both the
// cell (MakeCell) and the streams (RunSettings::seed). The baseline's run i is therefore exactly
// `rcal experiment paper --sensors --seed i`; no run depends on which other runs the sweep makes.
#pragma once

#include <string>
#include <vector>

#include "rcal/cell/sim_cell.hpp"

namespace rcal::tool::exp {

/// One row of the table: a change from the baseline programme.
struct SweepConfig {
  std::string id;      ///< command-line name, e.g. "noise-2", "poses-10"
  int number = 0;      ///< fixed; the run seed is 10000·number + seed index
  std::string factor;  ///< table text, e.g. "sensor noise"
  std::string value;   ///< table text, e.g. "×2"
  cell::RunSettings settings;
};

/// The configurations of the README table (baseline first), for a baseline programme of
/// `num_cal` + `num_test` stops.
std::vector<SweepConfig> SensorSweepConfigs(int num_cal = 50, int num_test = 50);

/// The seed of run `seed_index` (≥ 1, < 10000) of configuration number `config_number`.
unsigned SweepRunSeed(int config_number, unsigned seed_index);

struct SeedSweepOptions {
  std::string robot = "config/robots/grb3016.yaml";
  std::string out = "out/experiment_sensors_sweep";
  std::string json_path;
  int seeds = 20;           ///< seed indices first_seed … first_seed + seeds − 1
  unsigned first_seed = 1;  ///< first seed index
  int num_cal = 50, num_test = 50;
  std::vector<std::string> configs;  ///< ids to run; empty: all
  int jobs = 2;                      ///< worker threads (the result does not depend on it)
};

/// Runs the sweep; writes report.md, sweep_seeds.png and results.json into `out` and prints the
/// table. Returns 0; a run with too few windows to calibrate is counted as failed, not an error.
int RunSensorsSeedSweep(const SeedSweepOptions& o);

}  // namespace rcal::tool::exp
