// The aided_ins process's INS settings before its command line: the AidedInsSettings defaults
// with what `rcal fuse-loo --ins` chose on BROAD's sixteen trials (README, "With the tracker").
// One definition, so that the process, the tests that replay it against the library and `rcal
// fuse` (BroadInsSettings, which adds BROAD's frame, tracker σ and accelerometer lag) run the same
// filter. Header-only.
#pragma once

#include "rcal/estimation/aided_ins.hpp"

namespace rcal::services {

inline estimation::AidedInsSettings AidedInsProcessDefaults() {
  estimation::AidedInsSettings s;
  // Chosen by leave-one-trial-out, as 15 of its 16 folds (the fold without trial 27 leaves the
  // adaptation off).
  s.mag_heading_sigma = 0.6;           // [rad]
  s.accel_noise_density = 0.02;        // [m/s²/√Hz]
  s.accel_noise_adaptation_tau = 3.0;  // [s]
  s.accel_change_sigma = 0.1;          // [-]
  s.accel_shock_sigma = 2.0;           // κ [-]: in every candidate, not chosen (cmd_fuse_loo.cpp)
  return s;
}

}  // namespace rcal::services
