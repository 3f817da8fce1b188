// Batch Levenberg–Marquardt fit of an extended model (kinematics/joint_effects.hpp): the
// geometric errors of the identified parameters and every effect parameter together, the
// reference the online extended EKF (ekf_identifier.hpp) is compared with.
//
//   minimise  Σᵢ |Lᵢ⁻¹ rᵢ(x, e)|²,   rᵢ = zᵢ − h(qᵢ, cᵢ; x, e)   (extended_measurement.hpp)
//
// Lᵢ the Cholesky factor of pose i's covariance Rᵢ (whitening). Each iteration solves the
// column-scaled damped normal equations (AₛᵀAₛ + λI)·δₛ = Aₛᵀb, A = [L⁻¹H] stacked, b = [L⁻¹r]
// stacked, Aₛ = A·D, D = diag(1/|A_c|), δ = D·δₛ; a step is accepted when the cost does not rise
// (λ ÷ 10), else λ × 10; it stops when the cost falls by less than 1e-12 relative, after 30
// iterations, or when λ > 1e6.
// Covariance of [x_identified; e]: (AᵀA)⁺ at the optimum, times the a-posteriori variance factor
// s² = cost / (rows − parameters) when estimate_noise (the covariances are then only relative
// weights), else as given.
//
// Geometry steps (optional): the arm's geometry changed at known poses (a change the online
// identifier detected and released): pose i is measured with xᵢ = x + Σ_{steps s, first_s ≤ i}
// D_s a_s, D_s the step's directions in the full parameter vector, a_s its amplitudes, fitted
// with the rest (state [x_identified; e; a₁; a₂; …]). x is the geometry of the first pose.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"

namespace rcal::identification {

/// A change of the arm's geometry from one pose on (an encoder swapped and re-mastered, a
/// collision): the poses from `first_pose` on are measured with x + directions·a, a the step's
/// amplitudes (one per column, fitted), the earlier ones with x.
struct GeometryStep {
  int first_pose = 0;          ///< index into the measurements
  Eigen::MatrixXd directions;  ///< full-length parameter change per unit amplitude [m | rad per
                               ///< unit], one column per direction
};

/// The geometry pose `pose` is measured with: x + Σ directions·amplitudes over the steps whose
/// first_pose ≤ pose (file comment). `amplitudes` one per step.
Eigen::VectorXd GeometryAt(const Eigen::VectorXd& x, const std::vector<GeometryStep>& steps,
                           const std::vector<Eigen::VectorXd>& amplitudes, int pose);

struct ExtendedFit {
  Eigen::VectorXd x;            ///< geometric errors [m | rad], full length
  Eigen::VectorXd e;            ///< effect parameters [SI]
  Eigen::VectorXd sigma_e;      ///< 1σ of e (scaled by the a-posteriori variance factor when
                                ///< estimate_noise)
  double position_sigma_m = 0;  ///< position noise re-estimated from the residuals [m]
  /// Per geometry step: its amplitudes (one per direction) and their 1σ (as sigma_e).
  std::vector<Eigen::VectorXd> step_amplitudes, step_sigma;
};

/// Fits the geometric errors `identified` (indices into model.base().parameters(); the others
/// keep their values in x0) and every effect parameter, from (x0, e0). One context per
/// measurement; `steps` (file comment) with first_pose in 1 … ms.size() − 1, amplitudes from 0.
/// Throws std::invalid_argument naming the argument on inconsistent sizes.
ExtendedFit FitExtended(const kinematics::ExtendedModel& model, const std::vector<int>& identified,
                        const std::vector<kinematics::PoseMeasurement>& ms,
                        const std::vector<kinematics::EffectContext>& contexts,
                        const Eigen::VectorXd& x0, const Eigen::VectorXd& e0,
                        bool estimate_noise = true, const std::vector<GeometryStep>& steps = {});

}  // namespace rcal::identification
