#include "rcal/kinematics/compiled_chain.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace rcal::kinematics {
namespace {

using Kind = ElementaryTransform::Kind;

/// sin and cos of x [rad]. Cody–Waite reduction by π/2 (three-part constant, exact products for
/// |x| < 1e5) and Cephes' minimax polynomials on [−π/4, π/4]; max error 1 ulp against libm over
/// the joint range. Beyond 1e5, or for NaN/inf, it defers to std::sin/std::cos.
inline void SinCos(double x, double& s, double& c) {
  if (!(std::abs(x) < 1e5)) {
    s = std::sin(x);
    c = std::cos(x);
    return;
  }
  constexpr double kTwoOverPi = 0.63661977236758134308;
  constexpr double kRoundToInt = 6755399441055744.0;       // 1.5 · 2⁵², rounds to nearest in FP
  constexpr double kPio2_1 = 1.57079632673412561417e+00;   // first 33 bits of π/2
  constexpr double kPio2_2 = 6.07710050630396597660e-11;   // next 33 bits
  constexpr double kPio2_2t = 2.02226624879595063154e-21;  // π/2 − kPio2_1 − kPio2_2
  const double k = (x * kTwoOverPi + kRoundToInt) - kRoundToInt;
  const double r = ((x - k * kPio2_1) - k * kPio2_2) - k * kPio2_2t;
  const double z = r * r;
  const double ps = ((((1.58962301576546568060e-10 * z - 2.50507477628578072866e-8) * z +
                       2.75573136213857245213e-6) *
                          z -
                      1.98412698295895385996e-4) *
                         z +
                     8.33333333332211858878e-3) *
                        z -
                    1.66666666666666307295e-1;
  const double pc = ((((-1.13585365213876817300e-11 * z + 2.08757008419747316778e-9) * z -
                       2.75573141792967388112e-7) *
                          z +
                      2.48015872888517045348e-5) *
                         z -
                     1.38888888888730564116e-3) *
                        z +
                    4.16666666666665929218e-2;
  const double sr = r + r * z * ps;
  const double cr = 1.0 - 0.5 * z + z * z * pc;
  switch (static_cast<long>(k) & 3) {
    case 0:
      s = sr;
      c = cr;
      break;
    case 1:
      s = cr;
      c = -sr;
      break;
    case 2:
      s = -sr;
      c = -cr;
      break;
    default:
      s = -cr;
      c = sr;
      break;
  }
}

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

/// 0/1/2 when v is ±x/±y/±z (sign returned), 3 otherwise.
int CoordinateAxis(const Eigen::Vector3d& v, double& sign) {
  sign = 1.0;
  for (int k = 0; k < 3; ++k) {
    for (double sg : {1.0, -1.0}) {
      if (v == sg * Eigen::Vector3d::Unit(k)) {
        sign = sg;
        return k;
      }
    }
  }
  return 3;
}

}  // namespace

void CompiledChain::CloseSegment(std::vector<Op>& ops, size_t begin) {
  int rotations = 0;
  for (size_t i = begin; i < ops.size(); ++i) {
    Op& op = ops[i];
    if (op.kind == Op::Kind::kTranslate) continue;
    ++rotations;
    if (op.kind != Op::Kind::kRotate) {
      op.s = std::sin(op.angle);
      op.c = std::cos(op.angle);
    }
  }
  if (rotations <= 2) return;
  // Cheaper as one rotation and one translation: F = Trans(p) · Rot(M).
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (size_t i = begin; i < ops.size(); ++i) {
    const Op& op = ops[i];
    switch (op.kind) {
      case Op::Kind::kTranslate:
        p += M * op.t;
        break;
      case Op::Kind::kRotate:
        M = M * op.M;
        break;
      default:
        M = M * Eigen::AngleAxisd(op.angle, Eigen::Vector3d::Unit(static_cast<int>(op.kind) - 1))
                    .toRotationMatrix();
        break;
    }
  }
  ops.resize(begin);
  if (!p.isZero(0.0)) {
    Op op;
    op.kind = Op::Kind::kTranslate;
    op.t = p;
    ops.push_back(op);
  }
  if (M != Eigen::Matrix3d::Identity()) {
    Op op;
    op.kind = Op::Kind::kRotate;
    op.M = M;
    ops.push_back(op);
  }
}

CompiledChain::CompiledChain(const KinematicModel& model, const Eigen::VectorXd& x) {
  static_assert(static_cast<int>(Op::Kind::kRotX) == 1 && static_cast<int>(Op::Kind::kRotZ) == 3);
  if (x.size() != model.num_params())
    throw std::invalid_argument("CompiledChain: x has " + std::to_string(x.size()) +
                                " parameters, model '" + model.name() + "' has " +
                                std::to_string(model.num_params()));
  std::vector<int> seen(model.num_joints(), 0);
  size_t segment_begin = 0;
  joints_.reserve(model.num_joints());
  for (const ElementaryTransform& et : model.ets(Segment::kChain)) {
    const double value = et.nominal + (et.param >= 0 ? x(et.param) : 0.0);
    if (et.joint >= 0) {
      if (++seen[et.joint] > 1)
        throw std::invalid_argument("CompiledChain: joint '" + model.joints()[et.joint].name +
                                    "' of model '" + model.name() + "' drives more than one ET");
      CloseSegment(ops_, segment_begin);
      if (joints_.empty()) {
        base_ops_end_ = static_cast<int>(ops_.size());
      } else {
        joints_.back().ops_end = static_cast<int>(ops_.size());
      }
      segment_begin = ops_.size();
      JointStep step;
      step.index = et.joint;
      step.revolute = et.kind == Kind::kRotation;
      step.u = et.axis;
      step.offset = value;
      step.axis = CoordinateAxis(et.axis, step.sign);
      joints_.push_back(step);
      continue;
    }
    if (value == 0.0) continue;  // identity
    const bool same_segment = ops_.size() > segment_begin;
    if (et.kind == Kind::kTranslation) {
      // Consecutive translations act in the same frame: merge them.
      if (same_segment && ops_.back().kind == Op::Kind::kTranslate) {
        ops_.back().t += value * et.axis;
      } else {
        Op op;
        op.kind = Op::Kind::kTranslate;
        op.t = value * et.axis;
        ops_.push_back(op);
      }
      continue;
    }
    double sign = 1.0;
    const int axis = CoordinateAxis(et.axis, sign);
    if (axis == 3) {
      Op op;
      op.kind = Op::Kind::kRotate;
      op.M = Eigen::AngleAxisd(value, et.axis).toRotationMatrix();
      ops_.push_back(op);
      continue;
    }
    const auto kind = static_cast<Op::Kind>(axis + 1);
    if (same_segment && ops_.back().kind == kind) {
      ops_.back().angle += sign * value;  // rotations about one axis add up
    } else {
      Op op;
      op.kind = kind;
      op.angle = sign * value;
      ops_.push_back(op);
    }
  }
  CloseSegment(ops_, segment_begin);
  if (joints_.empty()) {
    base_ops_end_ = static_cast<int>(ops_.size());
  } else {
    joints_.back().ops_end = static_cast<int>(ops_.size());
  }
  if (num_joints() != model.num_joints())
    throw std::invalid_argument("CompiledChain: model '" + model.name() + "' has " +
                                std::to_string(model.num_joints()) + " joints but " +
                                std::to_string(num_joints()) + " joint ETs in its chain");
}

namespace {

template <typename Op>
inline void ApplyOps(const Op* op, const Op* end, Eigen::Matrix3d& R, Eigen::Vector3d& p) {
  for (; op != end; ++op) {
    switch (op->kind) {
      case Op::Kind::kTranslate:
        p.noalias() += R * op->t;
        break;
      case Op::Kind::kRotX:
        RotateX(R, op->s, op->c);
        break;
      case Op::Kind::kRotY:
        RotateY(R, op->s, op->c);
        break;
      case Op::Kind::kRotZ:
        RotateZ(R, op->s, op->c);
        break;
      case Op::Kind::kRotate:
        R = R * op->M;
        break;
    }
  }
}

// R ← R · R_u(v): axis 0/1/2 = ±x/±y/±z (sign), 3 = the general unit axis u (Rodrigues).
inline void RotateJoint(Eigen::Matrix3d& R, int axis, double sign, const Eigen::Vector3d& u,
                        double v) {
  double s, c;
  SinCos(v, s, c);
  if (axis == 3) {
    Eigen::Matrix3d K;
    K << 0.0, -u.z(), u.y(), u.z(), 0.0, -u.x(), -u.y(), u.x(), 0.0;
    const Eigen::Matrix3d R_u = Eigen::Matrix3d::Identity() + s * K + (1.0 - c) * (K * K);
    R = R * R_u;
    return;
  }
  s *= sign;
  if (axis == 0) {
    RotateX(R, s, c);
  } else if (axis == 1) {
    RotateY(R, s, c);
  } else {
    RotateZ(R, s, c);
  }
}

}  // namespace

Eigen::Isometry3d CompiledChain::ToolFrame(const Eigen::Ref<const Eigen::VectorXd>& q) const {
  eigen_assert(q.size() == num_joints());
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  const Op* ops = ops_.data();
  ApplyOps(ops, ops + base_ops_end_, R, p);
  const Op* next = ops + base_ops_end_;
  for (const JointStep& j : joints_) {
    const double v = q(j.index) + j.offset;
    if (j.revolute) {
      RotateJoint(R, j.axis, j.sign, j.u, v);
    } else {
      p.noalias() += R * (v * j.u);
    }
    ApplyOps(next, ops + j.ops_end, R, p);
    next = ops + j.ops_end;
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
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  const Op* ops = ops_.data();
  ApplyOps(ops, ops + base_ops_end_, R, p);
  const Op* next = ops + base_ops_end_;
  // First pass: each column holds [o_k; u_k] (joint origin and world axis); the linear part is
  // finished once the tool origin is known.
  for (const JointStep& j : joints_) {
    const double v = q(j.index) + j.offset;
    auto col = J.col(j.index);
    const Eigen::Vector3d u_W =
        j.axis == 3 ? Eigen::Vector3d(R * j.u) : Eigen::Vector3d(j.sign * R.col(j.axis));
    if (j.revolute) {
      col.head<3>() = p;
      col.tail<3>() = u_W;
      RotateJoint(R, j.axis, j.sign, j.u, v);
    } else {
      col.head<3>() = u_W;
      col.tail<3>().setZero();
      p.noalias() += v * u_W;
    }
    ApplyOps(next, ops + j.ops_end, R, p);
    next = ops + j.ops_end;
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
