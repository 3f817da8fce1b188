#include "rcal/kinematics/model.hpp"

#include "rcal/geometry/so3.hpp"

#include <stdexcept>

namespace rcal::kinematics {
namespace {

using Kind = ElementaryTransform::Kind;

double Value(const ElementaryTransform& et, const Eigen::VectorXd& q, const Eigen::VectorXd& x) {
  double v = et.nominal;
  if (et.param >= 0) v += x(et.param);
  if (et.joint >= 0) v += q(et.joint);
  return v;
}

Eigen::Matrix3d Rotation(const ElementaryTransform& et, double v) {
  return Eigen::AngleAxisd(v, et.axis).toRotationMatrix();
}

Eigen::Matrix3d RotationProduct(const std::vector<ElementaryTransform>& ets,
                                const Eigen::VectorXd& q, const Eigen::VectorXd& x) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  for (const auto& et : ets) R = R * Rotation(et, Value(et, q, x));
  return R;
}

void CheckSizes(const KinematicModel& m, const Eigen::VectorXd& q, const Eigen::VectorXd& x) {
  if (q.size() != m.num_joints())
    throw std::invalid_argument("q has " + std::to_string(q.size()) + " joints, model '" +
                                m.name() + "' has " + std::to_string(m.num_joints()));
  if (x.size() != m.num_params())
    throw std::invalid_argument("x has " + std::to_string(x.size()) + " parameters, model '" +
                                m.name() + "' has " + std::to_string(m.num_params()));
}

}  // namespace

Eigen::Isometry3d EtTransform(const ElementaryTransform& et, double value) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (et.kind == Kind::kRotation) {
    T.linear() = Rotation(et, value);
  } else {
    T.translation() = value * et.axis;
  }
  return T;
}

const std::vector<ElementaryTransform>& KinematicModel::ets(Segment s) const {
  switch (s) {
    case Segment::kEarth:
      return earth_;
    case Segment::kImu:
      return imu_;
    case Segment::kChain:
      break;
  }
  return chain_;
}

int KinematicModel::FindParameter(const std::string& name) const {
  for (int i = 0; i < num_params(); ++i)
    if (params_[i].name == name) return i;
  return -1;
}

int KinematicModel::MarkerSlot(int id) const {
  for (size_t k = 0; k < markers_.size(); ++k)
    if (markers_[k].id == id) return static_cast<int>(k);
  return -1;
}

const KinematicModel& KinematicModel::ForMarker(int slot) const {
  if (slot == view_slot_) return *this;
  if (view_slot_ != 0 || slot < 1 || slot >= static_cast<int>(markers_.size()) || !marker_views_)
    throw std::out_of_range(
        "marker slot " + std::to_string(slot) + " not in model '" + name_ + "' (" +
        std::to_string(markers_.size()) + " marker(s)" +
        (view_slot_ != 0 ? ", a view of slot " + std::to_string(view_slot_) : std::string()) + ")");
  return (*marker_views_)[slot - 1];
}

bool KinematicModel::WithinLimits(const Eigen::VectorXd& q) const {
  if (q.size() != num_joints()) return false;
  for (int j = 0; j < num_joints(); ++j)
    if (!(q(j) >= joints_[j].lower && q(j) <= joints_[j].upper)) return false;
  return true;
}

Eigen::Isometry3d KinematicModel::ToolFrame(const Eigen::VectorXd& q,
                                            const Eigen::VectorXd& x) const {
  CheckSizes(*this, q, x);
  Eigen::Isometry3d T_WT = Eigen::Isometry3d::Identity();
  for (const auto& et : chain_) T_WT = T_WT * EtTransform(et, Value(et, q, x));
  return T_WT;
}

Eigen::Matrix3d KinematicModel::EarthFromWorld(const Eigen::VectorXd& x) const {
  if (x.size() != num_params())
    throw std::invalid_argument("x has " + std::to_string(x.size()) + " parameters, model '" +
                                name() + "' has " + std::to_string(num_params()));
  // The earth ETs depend on no joint (ModelBuilder::EarthFrame), so q is not read.
  return RotationProduct(earth_, Eigen::VectorXd(), x);
}

Eigen::Matrix3d KinematicModel::WorldFromEarthCovariance(const Eigen::VectorXd& x,
                                                         const Eigen::VectorXd& sigma) const {
  if (sigma.size() != num_params())
    throw std::invalid_argument("sigma has " + std::to_string(sigma.size()) +
                                " parameters, model '" + name() + "' has " +
                                std::to_string(num_params()));
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  if (!has_earth()) return C;
  const Eigen::Matrix3d R_WE = EarthFromWorld(x).transpose();
  const double h = 1e-6;
  Eigen::VectorXd xp = x, xm = x;
  for (int i = 0; i < num_params(); ++i) {
    if (!(sigma(i) > 0.0)) continue;
    xp(i) = x(i) + h;
    xm(i) = x(i) - h;
    const Eigen::Vector3d J = (geometry::Log(EarthFromWorld(xp).transpose() * R_WE.transpose()) -
                               geometry::Log(EarthFromWorld(xm).transpose() * R_WE.transpose())) /
                              (2.0 * h);
    C += sigma(i) * sigma(i) * J * J.transpose();
    xp(i) = xm(i) = x(i);
  }
  return C;
}

ToolPose KinematicModel::Forward(const Eigen::VectorXd& q, const Eigen::VectorXd& x) const {
  const Eigen::Isometry3d T_WT = ToolFrame(q, x);
  return {T_WT.translation(),
          RotationProduct(earth_, q, x) * T_WT.linear() * RotationProduct(imu_, q, x)};
}

void KinematicModel::IdentificationJacobian(const Eigen::VectorXd& q, const Eigen::VectorXd& x,
                                            Eigen::Ref<Eigen::MatrixXd> J, ToolPose* pose) const {
  CheckSizes(*this, q, x);
  if (J.rows() != 6 || J.cols() != num_params())
    throw std::invalid_argument("identification Jacobian must be 6 x " +
                                std::to_string(num_params()));
  J.setZero();
  // Earth segment: a rotation about u after R_before moves the orientation by R_before·u.
  Eigen::Matrix3d R_EW = Eigen::Matrix3d::Identity();
  for (const auto& et : earth_) {
    if (et.param >= 0) J.block<3, 1>(3, et.param) += R_EW * et.axis;
    R_EW = R_EW * Rotation(et, Value(et, q, x));
  }
  // Chain: the frame in front of each ET, then the columns once the end point is known.
  thread_local std::vector<Eigen::Isometry3d> frames;
  frames.resize(chain_.size());
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (size_t k = 0; k < chain_.size(); ++k) {
    frames[k] = T;
    T = T * EtTransform(chain_[k], Value(chain_[k], q, x));
  }
  const Eigen::Vector3d p_WM_W = T.translation();
  for (size_t k = 0; k < chain_.size(); ++k) {
    const auto& et = chain_[k];
    if (et.param < 0) continue;
    const Eigen::Vector3d u_W = frames[k].linear() * et.axis;
    if (et.kind == Kind::kRotation) {
      J.block<3, 1>(0, et.param) += u_W.cross(p_WM_W - frames[k].translation());
      J.block<3, 1>(3, et.param) += R_EW * u_W;
    } else {
      J.block<3, 1>(0, et.param) += u_W;
    }
  }
  // IMU segment: rotations after the whole chain.
  Eigen::Matrix3d R = R_EW * T.linear();
  for (const auto& et : imu_) {
    if (et.param >= 0) J.block<3, 1>(3, et.param) += R * et.axis;
    R = R * Rotation(et, Value(et, q, x));
  }
  if (pose != nullptr) *pose = {p_WM_W, R};
}

Eigen::MatrixXd KinematicModel::JointJacobian(const Eigen::VectorXd& q,
                                              const Eigen::VectorXd& x) const {
  CheckSizes(*this, q, x);
  thread_local std::vector<Eigen::Isometry3d> frames;
  frames.resize(chain_.size());
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (size_t k = 0; k < chain_.size(); ++k) {
    frames[k] = T;
    T = T * EtTransform(chain_[k], Value(chain_[k], q, x));
  }
  Eigen::MatrixXd Jq = Eigen::MatrixXd::Zero(6, num_joints());
  for (size_t k = 0; k < chain_.size(); ++k) {
    const auto& et = chain_[k];
    if (et.joint < 0) continue;
    const Eigen::Vector3d u_W = frames[k].linear() * et.axis;
    if (et.kind == Kind::kRotation) {
      Jq.block<3, 1>(0, et.joint) += u_W.cross(T.translation() - frames[k].translation());
      Jq.block<3, 1>(3, et.joint) += u_W;
    } else {
      Jq.block<3, 1>(0, et.joint) += u_W;
    }
  }
  return Jq;
}

// ---------------------------------------------------------------------------------------------

ModelBuilder::ModelBuilder(std::string name) {
  model_.name_ = std::move(name);
}

int ModelBuilder::AddParam(const std::string& name, bool is_angle, double nominal,
                           const std::string& group) {
  if (model_.FindParameter(name) >= 0)
    throw std::invalid_argument("parameter '" + name + "' defined twice in model '" + model_.name_ +
                                "'");
  model_.params_.push_back({name, is_angle, nominal, group});
  return model_.num_params() - 1;
}

void ModelBuilder::Push(Segment s, Kind kind, const Eigen::Vector3d& axis, double nominal,
                        int param, int joint) {
  if (s == Segment::kChain && model_.marker_et_ >= 0)
    throw std::logic_error("model '" + model_.name_ +
                           "': a chain transform after the marker offset");
  ElementaryTransform et;
  et.kind = kind;
  et.axis = axis.normalized();
  et.nominal = nominal;
  et.param = param;
  et.joint = joint;
  switch (s) {
    case Segment::kEarth:
      model_.earth_.push_back(et);
      break;
    case Segment::kChain:
      model_.chain_.push_back(et);
      break;
    case Segment::kImu:
      model_.imu_.push_back(et);
      break;
  }
}

void ModelBuilder::PushRpy(Segment s, const Eigen::Vector3d& rpy, const std::string& prefix,
                           const std::string& group, bool identify) {
  // R = Rz(yaw) · Ry(pitch) · Rx(roll): the ETs in that order.
  const Eigen::Vector3d axes[3] = {Eigen::Vector3d::UnitZ(), Eigen::Vector3d::UnitY(),
                                   Eigen::Vector3d::UnitX()};
  const double values[3] = {rpy(2), rpy(1), rpy(0)};
  const char* names[3] = {"rz", "ry", "rx"};
  for (int i = 0; i < 3; ++i) {
    const int p = identify ? AddParam(prefix + names[i], true, values[i], group) : -1;
    Push(s, Kind::kRotation, axes[i], values[i], p);
  }
}

ModelBuilder& ModelBuilder::BaseFrame(const Eigen::Vector3d& p_WB_W, const Eigen::Vector3d& rpy_WB,
                                      bool identify) {
  if (!model_.chain_.empty())
    throw std::logic_error("BaseFrame must be the first transform of the chain");
  const char* names[3] = {"base_x", "base_y", "base_z"};
  for (int i = 0; i < 3; ++i) {
    const int p = identify ? AddParam(names[i], false, p_WB_W(i), "base") : -1;
    Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::Unit(i), p_WB_W(i), p);
  }
  PushRpy(Segment::kChain, rpy_WB, "base_", "base", identify);
  return *this;
}

ModelBuilder& ModelBuilder::DhLink(double a, double alpha, double d, double theta,
                                   const Joint& joint, bool hayati, double beta) {
  const int i = ++link_;
  const std::string n = std::to_string(i), group = "link " + n;
  model_.joints_.push_back(joint);
  const int j = model_.num_joints() - 1;
  const bool revolute = joint.type == JointType::kRevolute;
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitZ(), theta,
       AddParam("theta" + n, true, theta, group), revolute ? j : -1);
  if (hayati && revolute) {
    Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitZ(), d, -1);
  } else {
    Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitZ(), d,
         AddParam("d" + n, false, d, group), revolute ? -1 : j);
  }
  Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitX(), a,
       AddParam("a" + n, false, a, group));
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitX(), alpha,
       AddParam("alpha" + n, true, alpha, group));
  if (hayati && revolute)
    Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitY(), beta,
         AddParam("beta" + n, true, beta, group));
  return *this;
}

ModelBuilder& ModelBuilder::ModifiedDhLink(double a_prev, double alpha_prev, double d, double theta,
                                           const Joint& joint, bool hayati, double beta) {
  const int i = ++link_;
  const std::string n = std::to_string(i), group = "link " + n;
  model_.joints_.push_back(joint);
  const int j = model_.num_joints() - 1;
  const bool revolute = joint.type == JointType::kRevolute;
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitX(), alpha_prev,
       AddParam("alpha" + n, true, alpha_prev, group));
  Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitX(), a_prev,
       AddParam("a" + n, false, a_prev, group));
  if (hayati && revolute)
    Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitY(), beta,
         AddParam("beta" + n, true, beta, group));
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitZ(), theta,
       AddParam("theta" + n, true, theta, group), revolute ? j : -1);
  if (hayati && revolute) {
    Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitZ(), d, -1);
  } else {
    Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitZ(), d,
         AddParam("d" + n, false, d, group), revolute ? -1 : j);
  }
  return *this;
}

ModelBuilder& ModelBuilder::FixedTransform(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy) {
  for (int i = 0; i < 3; ++i)
    if (xyz(i) != 0.0)
      Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::Unit(i), xyz(i), -1);
  const int order[3] = {2, 1, 0};  // Rz(yaw) Ry(pitch) Rx(roll)
  for (int k : order)
    if (rpy(k) != 0.0) Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::Unit(k), rpy(k), -1);
  return *this;
}

ModelBuilder& ModelBuilder::UrdfJoint(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy,
                                      const Eigen::Vector3d& axis, const Joint& joint,
                                      bool identify) {
  ++link_;
  FixedTransform(xyz, rpy);
  model_.joints_.push_back(joint);
  const int j = model_.num_joints() - 1;
  const std::string& n = joint.name;
  if (identify) {
    const char* t[3] = {"_dx", "_dy", "_dz"};
    for (int i = 0; i < 3; ++i)
      Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::Unit(i), 0.0,
           AddParam(n + t[i], false, 0.0, n));
    const char* r[3] = {"_drz", "_dry", "_drx"};
    const int axes[3] = {2, 1, 0};
    for (int i = 0; i < 3; ++i)
      Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::Unit(axes[i]), 0.0,
           AddParam(n + r[i], true, 0.0, n));
  }
  Push(Segment::kChain, joint.type == JointType::kRevolute ? Kind::kRotation : Kind::kTranslation,
       axis, 0.0, -1, j);
  return *this;
}

ModelBuilder& ModelBuilder::ToolDh(double a, double alpha, double d, double theta, bool identify) {
  auto p = [&](const char* name, bool angle, double v) {
    return identify ? AddParam(name, angle, v, "tool") : -1;
  };
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitZ(), theta,
       p("tool_theta", true, theta));
  Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitZ(), d, p("tool_d", false, d));
  Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::UnitX(), a, p("tool_a", false, a));
  Push(Segment::kChain, Kind::kRotation, Eigen::Vector3d::UnitX(), alpha,
       p("tool_alpha", true, alpha));
  return *this;
}

ModelBuilder& ModelBuilder::MarkerOffset(const Eigen::Vector3d& p_FM, bool identify, int id) {
  if (model_.MarkerSlot(id) >= 0)
    throw std::invalid_argument("model '" + model_.name_ + "': marker id " + std::to_string(id) +
                                " given twice");
  if (id < 0)
    throw std::invalid_argument("model '" + model_.name_ + "': marker id " + std::to_string(id) +
                                " is negative");
  const std::string prefix = id == 0 ? "marker_" : "marker" + std::to_string(id) + "_";
  const char* axes[3] = {"x", "y", "z"};
  Marker m;
  m.id = id;
  m.nominal = p_FM;
  for (int i = 0; i < 3; ++i)
    m.param[i] = identify ? AddParam(prefix + axes[i], false, p_FM(i), "marker") : -1;
  if (model_.markers_.empty()) {
    const int first = static_cast<int>(model_.chain_.size());
    for (int i = 0; i < 3; ++i)
      Push(Segment::kChain, Kind::kTranslation, Eigen::Vector3d::Unit(i), p_FM(i), m.param[i]);
    model_.marker_et_ = first;
  }
  model_.markers_.push_back(m);
  return *this;
}

KinematicModel ModelBuilder::Build() const {
  KinematicModel model = model_;
  if (model.markers_.size() < 2) return model;
  // A view per further marker: the chain's marker ETs read that marker's parameters and nominal.
  auto views = std::make_shared<std::vector<KinematicModel>>();
  for (size_t k = 1; k < model.markers_.size(); ++k) {
    KinematicModel v = model_;
    v.view_slot_ = static_cast<int>(k);
    for (int i = 0; i < 3; ++i) {
      ElementaryTransform& et = v.chain_[v.marker_et_ + i];
      et.param = v.markers_[k].param[i];
      et.nominal = v.markers_[k].nominal(i);
    }
    views->push_back(std::move(v));
  }
  model.marker_views_ = std::move(views);
  return model;
}

ModelBuilder& ModelBuilder::ImuMounting(const Eigen::Vector3d& rpy_FI, bool identify) {
  PushRpy(Segment::kImu, rpy_FI, "imu_", "imu", identify);
  return *this;
}

ModelBuilder& ModelBuilder::EarthFrame(const Eigen::Vector3d& rpy_EW, bool identify) {
  PushRpy(Segment::kEarth, rpy_EW, "earth_", "earth", identify);
  return *this;
}

}  // namespace rcal::kinematics
