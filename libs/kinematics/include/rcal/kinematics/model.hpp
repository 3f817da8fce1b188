// Kinematic model of a serial arm and its measurement set-up, as a sequence of elementary
// transforms (ETs), each a translation along or a rotation about a unit axis of the frame reached
// so far. Every parameterisation rcal supports is a way of laying out ETs:
//
//   standard D–H link i    Rz(θᵢ + qᵢ) · Tz(dᵢ) · Tx(aᵢ) · Rx(αᵢ)
//   Hayati link i          Rz(θᵢ + qᵢ) · Tx(aᵢ) · Rx(αᵢ) · Ry(βᵢ)        (axis i ∥ axis i+1)
//   modified D–H link i    Rx(αᵢ₋₁) · Tx(aᵢ₋₁) · Rz(θᵢ + qᵢ) · Tz(dᵢ)
//   modified D–H, Hayati   Rx(αᵢ₋₁) · Tx(aᵢ₋₁) · Ry(βᵢ) · Rz(θᵢ + qᵢ)    (axis i ∥ axis i−1)
//   URDF-style joint i     T(xyz, rpy) · Tx Ty Tz Rz Ry Rx (6 errors) · R_axis(qᵢ)
//
// Each ET's value is  nominal + x[param] + q[joint]  (an absent index contributes nothing), so the
// parameter vector x holds the *errors* from the drawing (the paper's Δv, Eq. 2).
//
// The set-up the model describes (ARCHITECTURE.md, "Frames"):
//
//   p_WM_W = T_WB · T_BF(q) · p_FM              position of the marker, world (position sensor)
//   R_EI   = R_EW · R_WB · R_BF(q) · R_FI        orientation of the IMU, earth frame
//
// In ET terms the model has three segments:
//   earth  (rotations only, orientation output only): R_EW
//   chain  base ETs (T_WB), links (T_BF), tool/marker ETs; position output = end of chain
//   imu    (rotations only, orientation output only): R_FI
//
// Several markers (several points measured on the tool, e.g. laser-tracker reflectors): each
// marker id has its own flange → marker offset p_FM (parameters marker_x/y/z for id 0,
// marker<id>_x/y/z for id ≥ 1). The chain ends with the three translation ETs of the first
// marker (slot 0); ForMarker(slot) is the same model with those ETs reading marker `slot`'s
// parameters, so every function of a model (Forward, the Jacobians, ExtendedModel, IK) serves
// any marker through its view. All views share one parameter vector x.
// The paper's set-up is the special case of an empty earth and imu segment, a D–H tool link, and
// measurements of the tool frame in the base frame.
//
// Identification Jacobian convention: rows 0–2 are ∂p_WM_W/∂x [m per unit of x]; rows 3–5 are
// ∂δθ_E/∂x [rad per unit], δθ_E the left rotation error in the earth frame,
// R_EI(x + dx) = Exp(δθ_E) · R_EI(x). Units of x: m for translations, rad for rotations.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <string>
#include <vector>

namespace rcal::kinematics {

enum class JointType { kRevolute, kPrismatic };

/// One elementary transform: a translation along, or rotation about, `axis` of the current frame.
struct ElementaryTransform {
  enum class Kind { kTranslation, kRotation };
  Kind kind = Kind::kRotation;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< unit vector, current frame
  double nominal = 0.0;                             ///< [m] or [rad]: the drawing value
  int param = -1;  ///< index of this ET's error in x, or −1 when the ET is not identified
  int joint = -1;  ///< index of the joint variable added to the value, or −1
};

/// Where an ET acts (see the file comment).
enum class Segment { kEarth, kChain, kImu };

/// A model parameter: the error of one ET from its nominal value.
struct Parameter {
  std::string name;       ///< e.g. "a2", "alpha2", "d3", "theta1", "beta2", "base_x", "tool_d"
  bool is_angle = false;  ///< true: [rad]; false: [m]
  double nominal = 0.0;   ///< the nominal value of the ET it belongs to [m] or [rad]
  std::string group;      ///< "base", "link 3", "tool", "marker", "imu", "earth", joint name
};

/// Whether a parameter group is a set-up frame of the cell (world ← base, flange → marker,
/// flange → IMU, earth ← world) rather than the arm's own geometry.
inline bool IsSetupGroup(const std::string& group) {
  return group == "base" || group == "marker" || group == "imu" || group == "earth";
}

struct Joint {
  std::string name;
  JointType type = JointType::kRevolute;
  double lower = -3.14159265358979;  ///< [rad] or [m]
  double upper = 3.14159265358979;   ///< [rad] or [m]
};

/// One measured point on the tool: its offset p_FM from the flange (the chain's last frame before
/// the marker), three translations along the flange axes.
struct Marker {
  int id = 0;                            ///< the dataset's `marker` id
  std::array<int, 3> param{-1, -1, -1};  ///< index of p_FM's x, y, z error in x; −1: fixed
  Eigen::Vector3d nominal = Eigen::Vector3d::Zero();  ///< nominal p_FM [m], flange frame
};

/// What the sensors see at one pose.
struct ToolPose {
  Eigen::Vector3d p_WM_W;  ///< marker (position sensor target) in the world frame [m]
  Eigen::Matrix3d R_EI;    ///< IMU orientation, imu → earth
};

/// The geometric model of an arm and its measurement set-up. Immutable once built; every query
/// takes the joint vector q [rad | m] and the parameter-error vector x [rad | m].
class KinematicModel {
 public:
  KinematicModel() = default;

  const std::string& name() const { return name_; }
  int num_joints() const { return static_cast<int>(joints_.size()); }
  int num_params() const { return static_cast<int>(params_.size()); }
  const std::vector<Joint>& joints() const { return joints_; }
  const std::vector<Parameter>& parameters() const { return params_; }
  const std::vector<ElementaryTransform>& ets(Segment s) const;
  /// Index of the parameter called `name`, or −1.
  int FindParameter(const std::string& name) const;
  /// A zero parameter-error vector (the nominal model).
  Eigen::VectorXd Nominal() const { return Eigen::VectorXd::Zero(num_params()); }
  /// Joints inside their limits?
  bool WithinLimits(const Eigen::VectorXd& q) const;

  /// The markers on the tool, in slot order (slot 0 is the one the chain ends with); empty when
  /// the model has no marker offset (the position output is then the end of the tool).
  const std::vector<Marker>& markers() const { return markers_; }
  /// Slot of the marker with dataset id `id`, or −1.
  int MarkerSlot(int id) const;
  /// The model measuring marker `slot` (markers()[slot]): the same parameters and joints, the
  /// chain ending at that marker. Slot 0 (or a model without markers) is the model itself.
  /// Throws std::out_of_range for a slot the model does not have.
  const KinematicModel& ForMarker(int slot) const;
  /// The marker slot this model measures: 0, or the slot of a ForMarker view.
  int marker_slot() const { return view_slot_; }

  /// Marker position and IMU orientation at joints q with parameter errors x.
  ToolPose Forward(const Eigen::VectorXd& q, const Eigen::VectorXd& x) const;

  /// Whether the model has an earth ← world rotation (ModelBuilder::EarthFrame).
  bool has_earth() const { return !earth_.empty(); }
  /// The earth ← world rotation R_EW at parameter errors x (identity without an earth frame):
  /// the frame Forward's R_EI is in, against the position sensor's world frame.
  Eigen::Matrix3d EarthFromWorld(const Eigen::VectorXd& x) const;
  /// Covariance [rad²] of R_WE = EarthFromWorld(x)ᵀ when the parameters err independently by
  /// sigma [m | rad] (one per parameter, ≥ 0), as a rotation vector δφ_W on the left
  /// (R_WE,true = Exp(δφ_W) R_WE): Σ σ_i² J_i J_iᵀ with J_i = ∂δφ_W/∂x_i by central
  /// differences (step 1e-6). Zero without an earth frame.
  Eigen::Matrix3d WorldFromEarthCovariance(const Eigen::VectorXd& x,
                                           const Eigen::VectorXd& sigma) const;

  /// Pose of the end of the chain (the tool/marker frame) in the world frame, T_WT. This is the
  /// frame the IK corrector places.
  Eigen::Isometry3d ToolFrame(const Eigen::VectorXd& q, const Eigen::VectorXd& x) const;

  /// Identification Jacobian, 6 × num_params (convention in the file comment). `pose`, when not
  /// null, receives the forward pose at the same point (computed on the way).
  void IdentificationJacobian(const Eigen::VectorXd& q, const Eigen::VectorXd& x,
                              Eigen::Ref<Eigen::MatrixXd> J, ToolPose* pose = nullptr) const;

  /// Geometric Jacobian of the tool frame w.r.t. the joints, 6 × num_joints, in the world frame:
  /// rows 0–2 the velocity of the tool-frame origin [m/s per joint unit/s], rows 3–5 the angular
  /// velocity [rad/s per joint unit/s].
  Eigen::MatrixXd JointJacobian(const Eigen::VectorXd& q, const Eigen::VectorXd& x) const;

 private:
  friend class ModelBuilder;
  std::string name_;
  std::vector<Joint> joints_;
  std::vector<Parameter> params_;
  std::vector<ElementaryTransform> earth_, chain_, imu_;
  std::vector<Marker> markers_;
  int marker_et_ = -1;  ///< index in chain_ of the first of the three marker ETs
  int view_slot_ = 0;   ///< which marker this model measures (views: ≥ 1)
  /// Views for slots 1 … markers_.size() − 1 (set by ModelBuilder::Build; null in views).
  std::shared_ptr<const std::vector<KinematicModel>> marker_views_;
};

/// Builds a KinematicModel ET by ET. Links are numbered from 1 in parameter names, as the paper.
/// Every `identify` flag decides whether that ET's error becomes a parameter.
class ModelBuilder {
 public:
  explicit ModelBuilder(std::string name);

  /// World ← base, 6 DoF: Tx Ty Tz Rz Ry Rx (parameters base_x … base_rx) with the nominal
  /// translation [m] and roll-pitch-yaw [rad] of T_WB.
  ModelBuilder& BaseFrame(const Eigen::Vector3d& p_WB_W, const Eigen::Vector3d& rpy_WB,
                          bool identify = true);
  /// Standard D–H link; `hayati` replaces d by β (for a link whose next axis is parallel):
  /// d stays at its nominal value and is not a parameter; `beta` is β's nominal value (a
  /// calibrated robot carries its identified β there). Lengths [m], angles [rad].
  ModelBuilder& DhLink(double a, double alpha, double d, double theta, const Joint& joint,
                       bool hayati = false, double beta = 0.0);
  /// Modified (Craig) D–H link; `hayati` replaces dᵢ by βᵢ (axis i parallel to axis i−1), with
  /// nominal value `beta` [rad].
  ModelBuilder& ModifiedDhLink(double a_prev, double alpha_prev, double d, double theta,
                               const Joint& joint, bool hayati = false, double beta = 0.0);
  /// URDF-style joint: fixed origin (xyz [m], rpy [rad]) then a 6-parameter placement error
  /// (name_dx … name_drx) then the motion about/along the unit `axis`.
  ModelBuilder& UrdfJoint(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy,
                          const Eigen::Vector3d& axis, const Joint& joint, bool identify = true);
  /// A fixed URDF origin with no joint and no parameters (fixed joints, links between).
  ModelBuilder& FixedTransform(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy);
  /// The paper's 4-parameter D–H tool transform after the last joint (tool_a … tool_theta).
  ModelBuilder& ToolDh(double a, double alpha, double d, double theta, bool identify = true);
  /// Flange → marker translation p_FM [m] of marker `id` (parameters marker_x, marker_y,
  /// marker_z for id 0; marker<id>_x … for id ≥ 1). The first call ends the chain with the
  /// marker's three translation ETs; later calls add further markers (other ids) measured from
  /// the same flange. No chain ET may follow. Throws std::invalid_argument for an id given twice.
  ModelBuilder& MarkerOffset(const Eigen::Vector3d& p_FM, bool identify = true, int id = 0);
  /// Flange → IMU rotation as roll-pitch-yaw [rad] (imu_rz, imu_ry, imu_rx): orientation only.
  ModelBuilder& ImuMounting(const Eigen::Vector3d& rpy_FI, bool identify = true);
  /// Earth ← world rotation as roll-pitch-yaw [rad] (earth_rz, earth_ry, earth_rx).
  ModelBuilder& EarthFrame(const Eigen::Vector3d& rpy_EW, bool identify = true);

  /// The model, with a view per additional marker (KinematicModel::ForMarker).
  KinematicModel Build() const;

 private:
  int AddParam(const std::string& name, bool is_angle, double nominal, const std::string& group);
  void Push(Segment s, ElementaryTransform::Kind kind, const Eigen::Vector3d& axis, double nominal,
            int param, int joint = -1);
  void PushRpy(Segment s, const Eigen::Vector3d& rpy, const std::string& prefix,
               const std::string& group, bool identify);
  KinematicModel model_;
  int link_ = 0;
};

/// The transform of one ET at value v.
Eigen::Isometry3d EtTransform(const ElementaryTransform& et, double value);

}  // namespace rcal::kinematics
