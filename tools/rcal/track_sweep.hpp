// The seeded tracking experiment of `rcal track --sweep` (issue 15's figures): on each arm, full
// poses and positions only, an identifier converged on 300 poses sees one of its joints read
// 1 mrad off (an encoder swap) or one link length grow by 0.5 mm, and 30 more poses; another run
// sees an unchanged arm for many poses. Measured: the detection delay, whether the right joint or
// link was named, the held-out error 30 poses after the step against the one before it, false
// alarms, and the steady-state error against the filter as it was before change detection and
// the window (window_poses 0, detect_changes off). And, per seed, what the best possible test
// could do on the same poses (OraclePower): the bound the detected fraction is judged against.
#pragma once

#include <string>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::tool {

struct TrackSweepArm {
  std::string name;
  kinematics::KinematicModel model;  ///< with its set-up frames (and the IMU frame for full poses)
  bool full_pose = true;
};

struct TrackSweepSettings {
  int seeds = 20;
  /// The first seed: seeds first_seed … first_seed + seeds − 1 are run (the README's table is
  /// 0 … 19; others give figures on runs nothing was chosen on). Below 1000.
  int first_seed = 0;
  int converge_poses = 300;
  int after_poses = 30;
  int quiet_poses = 10000;  ///< poses of the unchanged arm per seed (false alarms)
  int steady_poses = 1000;  ///< poses at which the steady-state error is compared
  double joint_step_rad = 1e-3;
  double length_step_m = 5e-4;
  /// The oracle's false-alarm probability per test: the largest per-pose rate under which 0 false
  /// alarms in the 10 000 poses × 20 seeds has a chance of at least 95 %
  /// (−ln 0.95 / 200 000).
  double oracle_false_alarm = 2.56e-7;
  int oracle_poses = 5;             ///< the issue's detection delay [poses]
  identification::EkfSettings ekf;  ///< the identifier under test
};

struct TrackSweepResult {
  std::string arm;
  bool full_pose = true;
  std::string kind;  ///< "joint offset" or "link length"
  int seeds = 0;
  int detected = 0;         ///< steps detected within after_poses
  std::vector<int> delays;  ///< poses from the step to its detection (1: the first)
  int named_right = 0;      ///< detected and the right joint / length named (after the second look)
  int named_right_at_detection = 0;  ///< the same as named by the detection
  /// Of named_right: named first a joint indistinguishable from the stepped one
  /// (IndistinguishableJoints), not the stepped one itself.
  int named_indistinguishable = 0;
  /// Detections that named alternatives (DetectedChange::probability), and of those, the ones
  /// whose alternatives held the right joint / length.
  int alternatives_at_detection = 0, right_among_alternatives = 0;
  std::vector<double> recovery;  ///< error 30 poses after / error before the step
  std::vector<double> error_before_m, error_after_m;
  int false_alarms = 0;              ///< unchanged-arm runs: changes raised
  long quiet_poses = 0;              ///< unchanged-arm poses run
  std::vector<double> steady_ratio;  ///< steady-state error, this filter / the former filter
  /// Per seed: the joint or parameter stepped, and the delay (−1: not detected within 30).
  std::vector<std::string> stepped;
  std::vector<int> seed_delay;
  /// Per seed: what the first change detected named after the second look at it, and at its
  /// detection (identification::ChangeNames, joined by ","; empty: not detected).
  std::vector<std::string> named, named_at_detection;
  /// Per seed: the probability that the best possible test detects the step within
  /// oracle_poses (and within after_poses) poses: OraclePower of the step's own signature, see
  /// StepNoncentrality. No detector at that false-alarm rate does better in expectation, so the
  /// mean over seeds bounds the detected fraction.
  std::vector<double> oracle_power, oracle_power_after;
  int detected_within_oracle_poses = 0;  ///< steps detected within oracle_poses
};

/// The probability that a test of a known step direction and onset, at false-alarm probability
/// `false_alarm`, claims the step: its statistic is χ²(1) with noncentrality λ =
/// Σ_k |R_k^{-1/2} d_k|², and P(χ²₁(λ) > c) = Φ(√λ − √c) + Φ(−√λ − √c), c the χ²(1) quantile.
/// That test (it knows when and which way the arm changed, and ignores what the filter does not
/// know) is the most powerful at its false-alarm rate (Neyman–Pearson), so no detector beats it.
double OraclePower(double noncentrality, double false_alarm);

/// The step's signature in one measurement, whitened by the measurement noise: |d/σ|² where d is
/// what the measured pose at `q` moves by between the arm before (q_before joints, x_before
/// parameters) and after the change (position [m], and the rotation [rad] when the noise has
/// orientation).
double StepNoncentrality(const kinematics::KinematicModel& model, const Eigen::VectorXd& q_before,
                         const Eigen::VectorXd& x_before, const Eigen::VectorXd& q_after,
                         const Eigen::VectorXd& x_after, double position_sigma,
                         double orientation_sigma, bool orientation);

/// Per joint, the joints whose offset step moves the measured tool exactly as its own does (with
/// either sign), at every configuration, at the nominal geometry: itself, and any joint sharing
/// its axis (coaxial revolute joints, e.g. consecutive ones with a = 0 and α = 0 between them;
/// the base set keeps one offset for them). No data can tell a step of one from a step of the
/// other, so naming either names the change; the sweep counts it right (and says how often in
/// TrackSweepResult::named_indistinguishable). The truth's errors of a millimetre separate such
/// axes by micrometres per mrad of step, far below what the poses resolve. Compared at 20
/// seeded configurations, positions and (full_pose) orientations, to 1e-12 m and rad.
std::vector<std::vector<int>> IndistinguishableJoints(const kinematics::KinematicModel& model,
                                                      bool full_pose);

/// Runs the experiment on one arm: one result per step kind (joint offset, link length); the
/// false alarms and steady state are in the joint-offset result. Seeded: seed s of arm a is the
/// same run every time.
std::vector<TrackSweepResult> RunTrackSweep(const TrackSweepArm& arm, const TrackSweepSettings& s);

/// The median (numeric/median.hpp): the mean of the two middle values for an even count.
using numeric::Median;

}  // namespace rcal::tool
