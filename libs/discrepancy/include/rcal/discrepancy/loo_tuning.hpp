// Leave-one-trial-out selection of one set of settings among candidates, so that the figure
// reported for a trial comes from settings chosen without that trial (issue 17: tune by
// cross-validation across what you have, never per case).
//   cost(c, t) ≥ 0: the cost of candidate c on trial t (lower is better; NaN = the candidate
//   failed on that trial, so it is never chosen on a fold containing the trial).
//   In-sample: the candidate with the lowest mean cost over all trials.
//   Fold t (held out): the candidate with the lowest mean cost over the other trials; trial t is
//   then scored with it. Ties go to the lower candidate index (deterministic).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace rcal::discrepancy {

struct LeaveOneOutChoice {
  int in_sample = -1;         ///< candidate chosen on all trials
  std::vector<int> held_out;  ///< per trial t: candidate chosen without trial t
  /// Mean cost over the trials: in-sample with `in_sample`, held-out with each fold's choice.
  double in_sample_mean = 0.0;
  double held_out_mean = 0.0;
};

/// Throws std::invalid_argument when there is no candidate, fewer than two trials, a negative
/// cost, or a fold on which every candidate failed.
LeaveOneOutChoice LeaveOneOutSelect(const Eigen::MatrixXd& cost);

}  // namespace rcal::discrepancy
