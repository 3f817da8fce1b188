// The command-line options of a process's estimation::TimeGate, shared by every service that
// gates a sensor or pose stream (CLI11, header-only).
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <sstream>
#include <string>

#include "rcal/estimation/time_gate.hpp"

namespace rcal::services {

/// Adds --horizon [s] and --resync-samples to `app`, writing into `time` (which must outlive the
/// parse); the defaults shown are `time`'s values. `what` names a stream's element in the help
/// ("sample", "pose").
inline void AddTimeGateOptions(CLI::App& app, estimation::TimeGateSettings* time,
                               const std::string& what = "sample") {
  app.add_option_function<double>(
         "--horizon",
         [time](double horizon_s) { time->horizon_us = std::llround(horizon_s * 1e6); },
         "a " + what + " more than this past the last of its stream is refused [s]")
      ->check(CLI::PositiveNumber)
      ->default_str((std::ostringstream() << static_cast<double>(time->horizon_us) * 1e-6).str());
  app.add_option("--resync-samples", time->resync_samples,
                 "consistent refused " + what + "s that re-synchronise a stream whose time jumped")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

}  // namespace rcal::services
