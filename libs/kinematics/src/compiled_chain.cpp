#include "rcal/kinematics/compiled_chain.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace rcal::kinematics {
namespace {

using Kind = ElementaryTransform::Kind;

// R ← R · R_axis(angle) for the coordinate axes: only two columns change.
inline void RotateX(Eigen::Matrix3d& R, double s, double c) {
  const Eigen::Vector3d c1 = R.col(1), c2 = R.col(2);
  R.col(1) = c * c1 + s * c2;
  R.col(2) = c * c2 - s * c1;
}
inline void RotateY(Eigen::Matrix3d& R, double s, double c) {
  const Eigen::Vector3d c0 = R.col(0), c2 = R.col(2);
  R.col(0) = c * c0 - s * c2;
  R.col(2) = s * c0 + c * c2;
}
inline void RotateZ(Eigen::Matrix3d& R, double s, double c) {
  const Eigen::Vector3d c0 = R.col(0), c1 = R.col(1);
  R.col(0) = c * c0 + s * c1;
  R.col(1) = c * c1 - s * c0;
}

// R ← R · R_u(v): axis 0/1/2 = ±x/±y/±z (sign), 3 = the general unit axis u (Rodrigues).
inline void Rotate(Eigen::Matrix3d& R, int axis, double sign, const Eigen::Vector3d& u, double v) {
  if (axis == 3) {
    const double s = std::sin(v), c = std::cos(v);
    Eigen::Matrix3d K;
    K << 0.0, -u.z(), u.y(), u.z(), 0.0, -u.x(), -u.y(), u.x(), 0.0;
    const Eigen::Matrix3d R_u = Eigen::Matrix3d::Identity() + s * K + (1.0 - c) * (K * K);
    R = R * R_u;
    return;
  }
  const double s = sign * std::sin(v), c = std::cos(v);
  if (axis == 0) {
    RotateX(R, s, c);
  } else if (axis == 1) {
    RotateY(R, s, c);
  } else {
    RotateZ(R, s, c);
  }
}

}  // namespace

CompiledChain::CompiledChain(const KinematicModel& model, const Eigen::VectorXd& x) {
  if (x.size() != model.num_params())
    throw std::invalid_argument("CompiledChain: x has " + std::to_string(x.size()) +
                                " parameters, model '" + model.name() + "' has " +
                                std::to_string(model.num_params()));
  std::vector<int> seen(model.num_joints(), 0);
  Eigen::Isometry3d F = Eigen::Isometry3d::Identity();  // fixed part being accumulated
  auto close = [&F](Fixed& out) {
    out.R = F.linear();
    out.p = F.translation();
    out.identity = out.R == Eigen::Matrix3d::Identity() && out.p.isZero(0.0);
    F.setIdentity();
  };
  Fixed* pending = &base_;
  joints_.reserve(model.num_joints());
  for (const ElementaryTransform& et : model.ets(Segment::kChain)) {
    const double constant = et.nominal + (et.param >= 0 ? x(et.param) : 0.0);
    // The constant part of a joint ET shares the joint axis, so it goes into the fixed part.
    if (constant != 0.0) F = F * EtTransform(et, constant);
    if (et.joint < 0) continue;
    if (++seen[et.joint] > 1)
      throw std::invalid_argument("CompiledChain: joint '" + model.joints()[et.joint].name +
                                  "' of model '" + model.name() + "' drives more than one ET");
    close(*pending);
    JointStep step;
    step.index = et.joint;
    step.revolute = et.kind == Kind::kRotation;
    step.u = et.axis;
    step.axis = Axis::kGeneral;
    for (int k = 0; k < 3; ++k) {
      for (double sign : {1.0, -1.0}) {
        if (et.axis == sign * Eigen::Vector3d::Unit(k)) {
          step.axis = static_cast<Axis>(k);
          step.sign = sign;
        }
      }
    }
    joints_.push_back(step);
    pending = &joints_.back().after;
  }
  close(*pending);
  if (num_joints() != model.num_joints())
    throw std::invalid_argument("CompiledChain: model '" + model.name() + "' has " +
                                std::to_string(model.num_joints()) + " joints but " +
                                std::to_string(num_joints()) + " joint ETs in its chain");
}

Eigen::Isometry3d CompiledChain::ToolFrame(const Eigen::Ref<const Eigen::VectorXd>& q) const {
  eigen_assert(q.size() == num_joints());
  Eigen::Matrix3d R = base_.R;
  Eigen::Vector3d p = base_.p;
  for (const JointStep& j : joints_) {
    const double v = q(j.index);
    if (j.revolute) {
      Rotate(R, static_cast<int>(j.axis), j.sign, j.u, v);
    } else {
      p.noalias() += R * (v * j.u);
    }
    if (!j.after.identity) {
      p.noalias() += R * j.after.p;
      R = R * j.after.R;
    }
  }
  Eigen::Isometry3d T_WT;
  T_WT.linear() = R;
  T_WT.translation() = p;
  T_WT.makeAffine();
  return T_WT;
}

void CompiledChain::JointJacobian(const Eigen::Ref<const Eigen::VectorXd>& q,
                                  Eigen::Ref<Jacobian> J, Eigen::Isometry3d* T_WT) const {
  eigen_assert(q.size() == num_joints() && J.cols() == num_joints());
  Eigen::Matrix3d R = base_.R;
  Eigen::Vector3d p = base_.p;
  // First pass: each column holds [o_k; u_k] (joint origin and world axis); the linear part is
  // finished once the tool origin is known.
  for (const JointStep& j : joints_) {
    const double v = q(j.index);
    auto col = J.col(j.index);
    const Eigen::Vector3d u_W = j.axis == Axis::kGeneral
                                    ? Eigen::Vector3d(R * j.u)
                                    : Eigen::Vector3d(j.sign * R.col(static_cast<int>(j.axis)));
    if (j.revolute) {
      col.head<3>() = p;
      col.tail<3>() = u_W;
      Rotate(R, static_cast<int>(j.axis), j.sign, j.u, v);
    } else {
      col.head<3>() = u_W;
      col.tail<3>().setZero();
      p.noalias() += v * u_W;
    }
    if (!j.after.identity) {
      p.noalias() += R * j.after.p;
      R = R * j.after.R;
    }
  }
  for (const JointStep& j : joints_) {
    if (!j.revolute) continue;
    auto col = J.col(j.index);
    const Eigen::Vector3d r = p - col.head<3>();
    col.head<3>() = col.tail<3>().cross(r);
  }
  if (T_WT != nullptr) {
    T_WT->linear() = R;
    T_WT->translation() = p;
    T_WT->makeAffine();
  }
}

CompiledChain::Jacobian CompiledChain::JointJacobian(
    const Eigen::Ref<const Eigen::VectorXd>& q) const {
  Jacobian J(6, num_joints());
  JointJacobian(q, J);
  return J;
}

}  // namespace rcal::kinematics
