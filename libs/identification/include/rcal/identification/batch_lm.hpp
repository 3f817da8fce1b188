// Batch Levenberg–Marquardt identification: the reference the EKF is judged against.
//
//   minimise  Σₖ rₖ(x)ᵀ Rₖ⁻¹ rₖ(x)   over the identified parameter errors x [m | rad]
//
// with rₖ the pose residuals of measurement.hpp and Rₖ their covariances. Each residual is
// whitened by the Cholesky factor of Rₖ; steps solve (JᵀJ + λ·diag(JᵀJ)) δ = Jᵀr (Marquardt's
// scaling, so lengths and angles need no hand-tuned weights). The covariance of the estimate is
// (JᵀJ)⁻¹ at the solution: the Cramér–Rao bound evaluated there.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

struct LmSettings {
  int max_iterations = 100;
  double initial_lambda = 1e-3;
  double relative_cost_tolerance = 1e-14;  ///< stop when the cost improves by less (relative)
  double step_tolerance = 1e-13;           ///< stop when |δ| [m | rad] falls below
};

struct LmResult {
  Eigen::VectorXd x;           ///< full-length parameter errors [m | rad]
  Eigen::MatrixXd covariance;  ///< of the identified subset, (JᵀR⁻¹J)⁻¹ at the solution
  Eigen::VectorXd sigma;       ///< full-length 1σ; 0 where not identified
  double initial_cost = 0;     ///< Σ rᵀR⁻¹r at the start (dimensionless)
  double cost = 0;             ///< at the solution
  int iterations = 0;
  bool converged = false;
};

class BatchLm {
 public:
  BatchLm(const kinematics::KinematicModel& model, std::vector<int> identified,
          LmSettings settings = {});

  /// Solves from the starting errors `x0` (full length). Measurements must be valid
  /// (kinematics::Validate); throws std::invalid_argument naming the first invalid one.
  /// `progress`, if set, is called after each iteration with (iteration, cost).
  LmResult Solve(const std::vector<kinematics::PoseMeasurement>& measurements,
                 const Eigen::VectorXd& x0,
                 const std::function<void(int, double)>& progress = {}) const;

  /// Σ rᵀR⁻¹r at x (full length).
  double Cost(const std::vector<kinematics::PoseMeasurement>& measurements,
              const Eigen::VectorXd& x) const;

 private:
  kinematics::KinematicModel model_;
  std::vector<int> identified_;
  LmSettings settings_;
};

/// Cramér–Rao bound of the identified subset: (Σ Jₖᵀ Rₖ⁻¹ Jₖ)⁻¹ at the parameters `x` (the truth,
/// when known). Only q, has_orientation and covariance of each measurement are used.
Eigen::MatrixXd CramerRaoBound(const kinematics::KinematicModel& model,
                               const std::vector<int>& identified,
                               const std::vector<kinematics::PoseMeasurement>& measurements,
                               const Eigen::VectorXd& x);

}  // namespace rcal::identification
