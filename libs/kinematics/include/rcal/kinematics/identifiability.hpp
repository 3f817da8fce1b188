// Which parameter errors a pose set can identify.
//
// The stacked identification Jacobian J (6m × n for m full poses, 3m × n for positions only) is
// column-scaled to unit norm, J_s = J·D, so that lengths [m] and angles [rad] compare. Its
// numerical rank r (singular values above `rank_tolerance`·σ_max) is the number of identifiable
// combinations. The n − r null-space directions are the parameter changes that move no measured
// pose; reduced to row-echelon form they read as sentences ("d2 and d3 enter only as d2 − d3").
// Each null direction is removed by fixing one parameter (its pivot) at nominal; the rest form the
// base (identifiable) parameter set. Pivots are taken among the arm's parameters first, from the
// end of the list (tool and wrist parameters are dropped before shoulder ones), then among the
// set-up frames (IsSetupGroup): where the mounting and the arm explain the same motion, the arm
// keeps its drawing and the set-up frame takes the difference.
#pragma once

#include <Eigen/Core>
#include <random>
#include <string>
#include <vector>

#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::kinematics {

enum class MeasurementKind { kFullPose, kPositionOnly };

struct IdentifiabilitySettings {
  double rank_tolerance = 1e-9;    ///< relative to the largest singular value of J_s
  double coefficient_zero = 1e-6;  ///< null-vector entries below this (relative) are zero
  /// A parameter is dropped for a null direction only when its scaled entry is at least this share
  /// of the largest one left among the parameters not yet passed (keeps the base set well
  /// conditioned, not just of full rank).
  double pivot_share = 0.1;
};

/// One direction of the parameter space that no measurement sees.
struct UnidentifiableCombination {
  int dropped = -1;               ///< parameter fixed at nominal to remove this direction
  std::vector<int> params;        ///< parameters involved (dropped first)
  std::vector<double> direction;  ///< Δx along `params` [m | rad], dropped entry = 1
  std::string explanation;        ///< in words
};

struct IdentifiabilityReport {
  int num_params = 0;
  int num_equations = 0;
  int rank = 0;
  Eigen::VectorXd singular_values;  ///< of the column-scaled Jacobian, descending
  std::vector<int> identifiable;    ///< base parameter indices, ascending
  std::vector<UnidentifiableCombination> unidentifiable;
  double condition_number = 0;  ///< of the column-scaled Jacobian restricted to `identifiable`
};

/// `count` joint vectors uniform inside the limits shrunk by `margin` (a fraction of each range
/// kept free at both ends), drawn from `rng`: the generic poses an identifiability question is
/// asked at (sim::SampleJoints is this).
std::vector<Eigen::VectorXd> SampleJointsInLimits(const KinematicModel& model, int count,
                                                  std::mt19937_64& rng, double margin = 0.05);

/// Stacks the identification Jacobians at joint vectors `qs` around parameter errors `x`.
Eigen::MatrixXd StackedJacobian(const KinematicModel& model, const std::vector<Eigen::VectorXd>& qs,
                                const Eigen::VectorXd& x, MeasurementKind kind);

/// Stacks the identification Jacobians of measurements at their own joints and markers (3 rows
/// per position-only measurement, 6 per full pose) around parameter errors `x`.
Eigen::MatrixXd StackedJacobian(const KinematicModel& model, const std::vector<PoseMeasurement>& ms,
                                const Eigen::VectorXd& x);

/// Rank, null-space combinations in words and a base parameter set.
IdentifiabilityReport AnalyzeIdentifiability(const KinematicModel& model,
                                             const std::vector<Eigen::VectorXd>& qs,
                                             const Eigen::VectorXd& x, MeasurementKind kind,
                                             const IdentifiabilitySettings& settings = {});
/// The same at measurements' own joints, markers and dimensions.
IdentifiabilityReport AnalyzeIdentifiability(const KinematicModel& model,
                                             const std::vector<PoseMeasurement>& ms,
                                             const Eigen::VectorXd& x,
                                             const IdentifiabilitySettings& settings = {});
/// The same of a stacked identification Jacobian J (rows: measured quantities, columns: the
/// model's parameters).
IdentifiabilityReport AnalyzeJacobian(const KinematicModel& model, const Eigen::MatrixXd& J,
                                      const IdentifiabilitySettings& settings = {});

}  // namespace rcal::kinematics
