#include "rcal/ik/levenberg_marquardt_ik.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "rcal/geometry/so3.hpp"

namespace rcal::ik {
namespace {

std::string Format(const char* fmt, double a, double b) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), fmt, a, b);
  return buf;
}

}  // namespace

const char* ToString(IkStatus status) {
  switch (status) {
    case IkStatus::kConverged:
      return "converged";
    case IkStatus::kMaxIterations:
      return "max iterations";
    case IkStatus::kStalled:
      return "stalled";
    case IkStatus::kInvalidInput:
      break;
  }
  return "invalid input";
}

LevenbergMarquardtIk::LevenbergMarquardtIk(const kinematics::KinematicModel& model,
                                           const Eigen::VectorXd& x, IkSettings settings)
    : model_(model), chain_(model, x), settings_(settings) {
  const int n = model.num_joints();
  lower_.resize(n);
  upper_.resize(n);
  for (int j = 0; j < n; ++j) {
    lower_(j) = model.joints()[j].lower;
    upper_(j) = model.joints()[j].upper;
  }
  J_.resize(6, n);
  G_.resize(6, n);
  H_.resize(n, n);
  g_.resize(n);
  dq_.resize(n);
  q_.resize(n);
  q_trial_.resize(n);
  Hd_.resize(n, n);
  rhs_.resize(n);
  at_limit_.resize(n);
  llt_ = Eigen::LLT<Eigen::MatrixXd>(n);
}

void LevenbergMarquardtIk::SetParameters(const Eigen::VectorXd& x) {
  chain_ = kinematics::CompiledChain(model_, x);
}

IkResult LevenbergMarquardtIk::Solve(const Eigen::Isometry3d& T_WT_target,
                                     const Eigen::VectorXd& q_seed) {
  return Run(T_WT_target, false, q_seed);
}

IkResult LevenbergMarquardtIk::SolvePosition(const Eigen::Vector3d& p_WT_W,
                                             const Eigen::VectorXd& q_seed) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = p_WT_W;
  return Run(T, true, q_seed);
}

void LevenbergMarquardtIk::Evaluate(const Eigen::VectorXd& q, Eigen::Isometry3d& T_WT,
                                    kinematics::CompiledChain::Jacobian* J) const {
  if (J)
    chain_.JointJacobian(q, *J, &T_WT);
  else
    T_WT = chain_.ToolFrame(q);
}

void LevenbergMarquardtIk::Project(Eigen::VectorXd& q) const {
  if (settings_.respect_joint_limits) q = q.cwiseMax(lower_).cwiseMin(upper_);
}

double LevenbergMarquardtIk::Residual(const Eigen::Isometry3d& T_WT_target,
                                      const Eigen::Isometry3d& T_WT, bool position_only,
                                      Eigen::Matrix<double, 6, 1>& r, double& position_error,
                                      double& orientation_error, Eigen::Vector3d& e_R) const {
  r.head<3>() = T_WT_target.translation() - T_WT.translation();
  position_error = r.head<3>().norm();
  if (position_only) {
    orientation_error = 0.0;
    e_R.setZero();
    r.tail<3>().setZero();
    return 0.5 * r.head<3>().squaredNorm();
  }
  e_R = geometry::Log(T_WT_target.linear() * T_WT.linear().transpose());
  orientation_error = e_R.norm();
  r.tail<3>() = settings_.orientation_weight * e_R;
  return 0.5 * r.squaredNorm();
}

IkResult LevenbergMarquardtIk::Run(const Eigen::Isometry3d& T_WT_target, bool position_only,
                                   const Eigen::VectorXd& q_seed) {
  IkResult res;
  const int n = num_joints();
  if (q_seed.size() != n) {
    res.q = Eigen::VectorXd::Zero(n);
    res.reason =
        "seed has " + std::to_string(q_seed.size()) + " joints, the chain has " + std::to_string(n);
    return res;
  }
  res.q = q_seed;
  if (!q_seed.allFinite()) {
    res.reason = "seed contains NaN or inf";
    return res;
  }
  if (!T_WT_target.matrix().allFinite()) {
    res.reason = "target pose contains NaN or inf";
    return res;
  }
  if (!position_only && !(T_WT_target.linear().transpose() * T_WT_target.linear())
                             .isApprox(Eigen::Matrix3d::Identity(), 1e-9)) {
    res.reason = "target rotation is not orthonormal";
    return res;
  }

  const int m = position_only ? 3 : 6;
  const double tol_p = settings_.position_tolerance, tol_R = settings_.orientation_tolerance;
  const double w = settings_.orientation_weight;
  q_ = q_seed;
  Project(q_);
  Eigen::Isometry3d T_WT, T_trial;
  Evaluate(q_, T_WT, &J_);
  Eigen::Matrix<double, 6, 1> r, r_trial;
  Eigen::Vector3d e_R, e_R_trial;
  double pos_err = 0, ori_err = 0, pos_trial = 0, ori_trial = 0;
  double cost = Residual(T_WT_target, T_WT, position_only, r, pos_err, ori_err, e_R);

  double lambda = -1.0, nu = 2.0;
  bool need_normal_equations = true;
  int slow_steps = 0;
  res.status = IkStatus::kMaxIterations;
  int it = 0;
  for (;; ++it) {
    if (pos_err <= tol_p && (position_only || ori_err <= tol_R)) {
      res.status = IkStatus::kConverged;
      break;
    }
    if (it >= settings_.max_iterations) break;
    if (need_normal_equations) {
      G_.topRows<3>() = J_.topRows<3>();
      if (!position_only) {
        // Inverse right Jacobian of the log error; beyond 3 rad it is ill-conditioned (sin → 0)
        // and the plain J_ω is a descent direction good enough to get closer first.
        const Eigen::Matrix3d Jr_inv =
            ori_err < 3.0 ? geometry::RightJacobianInverse(e_R) : Eigen::Matrix3d::Identity();
        G_.bottomRows<3>().noalias() = w * Jr_inv * J_.bottomRows<3>();
      }
      H_.noalias() = G_.topRows(m).transpose() * G_.topRows(m);
      g_.noalias() = G_.topRows(m).transpose() * r.head(m);
      if (lambda < 0)
        lambda = settings_.initial_damping * std::max(H_.diagonal().maxCoeff(), 1e-12);
      need_normal_equations = false;
    }
    // Damped step. A joint resting on a limit that the step would push further out is held
    // there (its row and column leave the system) and the step is solved again for the others,
    // so the free joints do the work instead of a step that the projection would cut short.
    at_limit_.setZero();
    for (int pass = 0; pass <= n; ++pass) {
      Hd_ = H_;
      Hd_.diagonal().array() += lambda;
      rhs_ = g_;
      for (int j = 0; j < n; ++j) {
        if (!at_limit_(j)) continue;
        Hd_.row(j).setZero();
        Hd_.col(j).setZero();
        Hd_(j, j) = 1.0;
        rhs_(j) = 0.0;
      }
      llt_.compute(Hd_);
      dq_.noalias() = llt_.solve(rhs_);
      if (!settings_.respect_joint_limits) break;
      bool changed = false;
      for (int j = 0; j < n; ++j) {
        if (at_limit_(j)) continue;
        if ((q_(j) <= lower_(j) && dq_(j) < 0.0) || (q_(j) >= upper_(j) && dq_(j) > 0.0)) {
          at_limit_(j) = 1;
          changed = true;
        }
      }
      if (!changed) break;
    }
    q_trial_ = q_ + dq_;
    Project(q_trial_);
    Evaluate(q_trial_, T_trial, nullptr);
    const double cost_trial =
        Residual(T_WT_target, T_trial, position_only, r_trial, pos_trial, ori_trial, e_R_trial);
    if (cost_trial < cost) {
      const double predicted = 0.5 * dq_.dot(lambda * dq_ + rhs_);
      const double rho = predicted > 0 ? (cost - cost_trial) / predicted : 0.0;
      slow_steps = (cost - cost_trial) < 1e-12 * cost ? slow_steps + 1 : 0;
      q_ = q_trial_;
      cost = cost_trial;
      r = r_trial;
      e_R = e_R_trial;
      pos_err = pos_trial;
      ori_err = ori_trial;
      Evaluate(q_, T_WT, &J_);
      need_normal_equations = true;
      lambda *= std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      nu = 2.0;
      if (slow_steps >= 3) {
        res.status = IkStatus::kStalled;
        ++it;
        break;
      }
    } else {
      lambda *= nu;
      nu *= 2.0;
      const double step = dq_.lpNorm<Eigen::Infinity>();
      if (lambda > 1e20 || step <= 1e-15 * (1.0 + q_.lpNorm<Eigen::Infinity>())) {
        res.status = IkStatus::kStalled;
        ++it;
        break;
      }
    }
  }

  res.q = q_;
  res.iterations = it;
  res.position_error = pos_err;
  res.orientation_error = ori_err;
  res.converged = res.status == IkStatus::kConverged;
  if (res.converged) return res;

  const std::string errors =
      position_only ? Format("position error %.3g m (tolerance %.1g m)", pos_err, tol_p)
                    : Format("position error %.3g m, orientation error %.3g rad", pos_err, ori_err);
  std::string at_limits;
  if (settings_.respect_joint_limits) {
    for (int j = 0; j < n; ++j)
      if (q_(j) <= lower_(j) || q_(j) >= upper_(j))
        at_limits += (at_limits.empty() ? "" : ", ") + model_.joints()[j].name;
  }
  if (res.status == IkStatus::kStalled) {
    res.reason =
        "stalled in a local minimum after " + std::to_string(it) + " iterations, " + errors +
        ": the target is out of reach" +
        (at_limits.empty() ? std::string()
                           : " or beyond the joint limits (at a limit: " + at_limits + ")");
  } else {
    res.reason = "not converged after " + std::to_string(it) + " iterations, " + errors +
                 (at_limits.empty() ? std::string() : " (at a limit: " + at_limits + ")");
  }
  return res;
}

}  // namespace rcal::ik
