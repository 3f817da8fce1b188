// Calibration from a measured pose set, as a robotics engineer runs it on real data:
//
// 1. start the set-up frames from the data: world ← base from a rigid alignment (Kabsch) of the
//    nominal flange positions to the measured ones; flange → IMU (or marker) rotation from the
//    chordal mean of the orientation residuals;
// 2. "nominal" model = the drawing kinematics with only the set-up frames fitted (base, marker,
//    imu, earth): the fair before-calibration figure, since no one uses a robot without knowing
//    where its base is;
// 3. calibrated model = the identifiable (base) parameter set at the data's own poses, fitted by
//    batch LM (or the EKF);
// 4. measurement noise, when not known, from the residuals (variance components: position and
//    orientation σ scaled until each block's χ² matches its share of the degrees of freedom);
// 5. judged on data it did not fit: the `set` split, or k-fold cross-validation.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

/// (R, t) minimising Σ |R·a_i + t − b_i|² (Kabsch with the reflection guard). At least 3
/// non-collinear points; throws std::invalid_argument otherwise.
Eigen::Isometry3d FitRigidTransform(const std::vector<Eigen::Vector3d>& a,
                                    const std::vector<Eigen::Vector3d>& b);

/// Parameters of the set-up frames: groups base, marker, imu, earth.
std::vector<int> SetupParameters(const kinematics::KinematicModel& model);

/// Starting errors with the set-up frames guessed from the data (GuessSetup, setup_guess.hpp):
/// world ← base and the marker offsets by registering the drawing's marker points to the
/// measured ones; earth ← world and flange → IMU rotations by a hand–eye solve of the
/// orientations (R_meas = Y·A·X), or the IMU rotation alone by a chordal mean when there is no
/// earth frame; a bad pose left out. Frames the model lacks, or too few poses (3 positions, 3
/// orientations for the earth frame), leave those parameters at 0.
Eigen::VectorXd InitialSetupGuess(const kinematics::KinematicModel& model,
                                  const std::vector<kinematics::PoseMeasurement>& ms);

/// The columns among `candidates` that the poses can identify together (pivoted QR of the
/// column-scaled stacked Jacobian at x), ascending.
std::vector<int> IdentifiableSubset(const kinematics::KinematicModel& model,
                                    const std::vector<kinematics::PoseMeasurement>& ms,
                                    const Eigen::VectorXd& x, const std::vector<int>& candidates);

/// A base (identifiable) parameter set chosen in an order of preference: a parameter joins when
/// it raises the rank of the column-scaled stacked Jacobian at x over the joints qs (pivoted QR,
/// threshold 1e-9), tried in the order set-up frames (groups base, earth, imu, marker), then the
/// arm's parameters in model order, the D–H tool (group tool) last. So link and tool errors that
/// a rotated IMU or a shifted marker explain are reported as part of those frames, as a user who
/// mounted them expects. Ascending.
std::vector<int> PreferredBaseSet(const kinematics::KinematicModel& model,
                                  const std::vector<Eigen::VectorXd>& qs, const Eigen::VectorXd& x,
                                  kinematics::MeasurementKind kind);

struct CalibrationSettings {
  enum class Method { kLm, kEkf };
  Method method = Method::kLm;
  bool estimate_noise = true;  ///< rescale position/orientation σ from the residuals
  int noise_iterations = 4;
  int folds = 5;  ///< k-fold when there is no cal/test split; ≥ number of poses: leave-one-out
  unsigned seed = 1;  ///< fold assignment
};

struct CalibrationFit {
  std::vector<int> setup;                      ///< identified set-up parameters (the nominal fit)
  std::vector<int> identified;                 ///< identified parameters of the calibrated fit
  Eigen::VectorXd x_nominal;                   ///< set-up frames only [m | rad]
  Eigen::VectorXd x;                           ///< calibrated [m | rad]
  Eigen::VectorXd sigma;                       ///< 1σ of x (0 where not identified)
  double position_sigma_m = 0;                 ///< noise used (estimated when settings say so)
  double orientation_sigma_rad = 0;            ///< 0 when positions only
  PoseErrorStats nominal_fit, calibrated_fit;  ///< on the poses fitted
  double cost = 0;
  int iterations = 0;
};

/// Fits the nominal (set-up only) and the calibrated model to `ms`. The covariances in `ms` are
/// the starting noise; with estimate_noise they are rescaled.
CalibrationFit Calibrate(const kinematics::KinematicModel& model,
                         std::vector<kinematics::PoseMeasurement> ms,
                         const CalibrationSettings& settings = {});

struct HeldOutErrors {
  std::string scheme;                  ///< "cal/test split", "5-fold", "leave-one-out"
  PoseErrorStats nominal, calibrated;  ///< on poses not fitted
};

/// Which poses each held-out round judges: fold[i] = the round that holds pose i out (−1: always
/// fitted). The `set` split when `is_test` marks some poses (one round: the test poses), else
/// k-fold over configurations, k = min(settings.folds, configurations), configurations shuffled
/// with settings.seed; all poses of one configuration (`configuration[i]`, ids 0 … m − 1; empty:
/// each pose its own) are held out together. Scheme "5-fold", "leave-one-out", with
/// " (by configuration)" when configurations hold several poses.
struct HeldOutFolds {
  std::vector<int> fold;
  int folds = 0;
  std::string scheme;  ///< "cal/test split", "5-fold", "leave-one-out"
};
HeldOutFolds MakeHeldOutFolds(int num_poses, const std::vector<bool>& is_test,
                              const CalibrationSettings& settings,
                              const std::vector<int>& configuration = {});

/// Configuration id per measurement (0, 1, … in order of first appearance): measurements at the
/// same joints (within 1e-9 rad | m) share one, e.g. several markers measured at one stop.
std::vector<int> ConfigurationGroups(const std::vector<kinematics::PoseMeasurement>& ms);

/// The offset p_FM [m, flange frame] of marker `slot` that puts it at the measured p_WM_W [m,
/// world] when the arm stands at q, with the model at errors x: p_FM = T_WF(q, x)⁻¹ · p_WM_W.
/// For a point whose offset is not fitted but measured once at a stated configuration.
Eigen::Vector3d MarkerOffsetFromPoint(const kinematics::KinematicModel& model, int slot,
                                      const Eigen::VectorXd& x, const Eigen::VectorXd& q,
                                      const Eigen::Vector3d& p_WM_W);

/// A marker whose offset is measured, not fitted: measurement `measurement` (an index into the
/// poses given to HeldOut) measures marker `slot` at a stated configuration. Each round solves
/// the marker's offset from it with that round's fit (MarkerOffsetFromPoint); that measurement is
/// neither fitted nor judged.
struct MarkerReference {
  int slot = 0;
  int measurement = 0;
};

/// Errors on poses not fitted (MakeHeldOutFolds, configurations from ConfigurationGroups): a split
/// when `is_test` marks some poses (fit on the others), else k-fold. Noise levels from `fit` are
/// used as weights. `references`: markers whose offsets are measured (MarkerReference).
HeldOutErrors HeldOut(const kinematics::KinematicModel& model,
                      const std::vector<kinematics::PoseMeasurement>& ms,
                      const std::vector<bool>& is_test, const CalibrationFit& fit,
                      const CalibrationSettings& settings = {},
                      const std::vector<MarkerReference>& references = {});

/// Held-out errors of an extended model (geometry + effects) next to the geometric calibration,
/// on the same folds as HeldOut (MakeHeldOutFolds). Each round calibrates the training poses as
/// HeldOut does (weights from `fit`), then fits the extended model (FitExtended, extended_lm.hpp)
/// over that round's identified parameters from its geometric fit and the effects from e0.
/// One context per measurement.
struct ExtendedHeldOutErrors {
  std::string scheme;
  PoseErrorStats nominal, geometric, extended;  ///< on poses not fitted
};
ExtendedHeldOutErrors HeldOutExtended(const kinematics::ExtendedModel& model,
                                      const std::vector<kinematics::PoseMeasurement>& ms,
                                      const std::vector<kinematics::EffectContext>& contexts,
                                      const std::vector<bool>& is_test, const CalibrationFit& fit,
                                      const Eigen::VectorXd& e0,
                                      const CalibrationSettings& settings = {});

/// The residuals of poses as variance components: the sums of squared position and orientation
/// residuals [m², rad²] and how many values each holds.
struct ResidualSums {
  double position_m2 = 0, orientation_rad2 = 0;
  int position_values = 0, orientation_values = 0;
};
/// ResidualSums of `ms` against the model at the geometry x_at(k) of each pose k [m | rad].
ResidualSums SumResiduals(const kinematics::KinematicModel& model,
                          const std::vector<kinematics::PoseMeasurement>& ms,
                          const std::function<Eigen::VectorXd(size_t)>& x_at);

/// Sets every measurement's covariance to diag(σ_p², σ_p², σ_p², σ_o², σ_o², σ_o²).
void SetNoise(std::vector<kinematics::PoseMeasurement>& ms, double position_sigma_m,
              double orientation_sigma_rad);

}  // namespace rcal::identification
