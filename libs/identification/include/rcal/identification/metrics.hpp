// How good a calibration is: pose errors against measurements or against a known truth, and the
// error the measurement noise alone allows (the Cramér–Rao prediction).
//
// Position error = |p_a − p_b| [m]; orientation error = angle of R_a·R_bᵀ [rad] (the paper's Table
// 2 reports both as mean and max).
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

struct PoseErrorStats {
  std::vector<double> position_m;       ///< per pose [m]
  std::vector<double> orientation_rad;  ///< per pose [rad]; empty when not measured
  double mean_position_m = 0, max_position_m = 0, rms_position_m = 0;
  double mean_orientation_rad = 0, max_orientation_rad = 0, rms_orientation_rad = 0;
};

/// Summary statistics of per-pose errors.
PoseErrorStats Summarize(std::vector<double> position_m, std::vector<double> orientation_rad);

/// The model at errors x against the measured poses.
PoseErrorStats ErrorsAgainstMeasurements(const kinematics::KinematicModel& model,
                                         const Eigen::VectorXd& x,
                                         const std::vector<kinematics::PoseMeasurement>& ms);

/// An extended model at geometric errors x and effects e [SI] against the measured poses, each
/// taken under its context (`contexts` one per measurement, or empty: all default). Throws
/// std::invalid_argument when contexts has another size.
PoseErrorStats ErrorsAgainstMeasurements(const kinematics::ExtendedModel& model,
                                         const Eigen::VectorXd& x, const Eigen::VectorXd& e,
                                         const std::vector<kinematics::PoseMeasurement>& ms,
                                         const std::vector<kinematics::EffectContext>& contexts);

/// The model at errors x against the truth (the same model at x_true) at joints qs.
PoseErrorStats ErrorsAgainstTruth(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                  const Eigen::VectorXd& x_true,
                                  const std::vector<Eigen::VectorXd>& qs);
/// The same where the truth stands elsewhere than the joints read (a joint whose reading stepped,
/// sim::TrueJoints): the model at x at the readings qs[i] against the truth at qs_true[i].
/// Throws std::invalid_argument when the lists differ in size.
PoseErrorStats ErrorsAgainstTruth(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                  const Eigen::VectorXd& x_true,
                                  const std::vector<Eigen::VectorXd>& qs,
                                  const std::vector<Eigen::VectorXd>& qs_true);

/// Expected mean position and orientation error at joints qs of an estimate whose error is
/// N(0, C) on the `identified` parameters around x (C from CramerRaoBound): E|Jₚ δx|, E|J_θ δx|
/// by `samples` seeded draws per pose. Returns {mean position [m], mean orientation [rad]}.
std::pair<double, double> PredictedMeanErrors(const kinematics::KinematicModel& model,
                                              const std::vector<int>& identified,
                                              const Eigen::MatrixXd& C, const Eigen::VectorXd& x,
                                              const std::vector<Eigen::VectorXd>& qs,
                                              unsigned seed = 1, int samples = 200);

/// The spread of one calibration's realized mean position error at joints qs, where
/// PredictedMeanErrors gives its expectation: the estimate's error is ONE draw δx ~ N(0, C) on the
/// `identified` parameters, shared by every pose of qs (as one calibration's error is), and the
/// mean over qs of |Jₚ δx| is taken per draw. Returns its p-quantile [m] (0 < p < 1) over `samples`
/// seeded draws. Use it to judge a realized test error with a known false-alarm rate (1 − p) where
/// a fixed multiple of the expectation would be exceeded at a rate nobody knows. Throws
/// std::invalid_argument for p outside (0, 1), samples < 1 or C not of the identified size.
double MeanPositionErrorQuantile(const kinematics::KinematicModel& model,
                                 const std::vector<int>& identified, const Eigen::MatrixXd& C,
                                 const Eigen::VectorXd& x, const std::vector<Eigen::VectorXd>& qs,
                                 double p, unsigned seed = 1, int samples = 20000);

}  // namespace rcal::identification
