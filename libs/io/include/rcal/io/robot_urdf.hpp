// Robots from URDF files (parsed by liburdfdom), and calibrated URDFs written back.
//
// The chain runs from a base link to a tip link. Each revolute, continuous or prismatic joint
// becomes a kinematics::ModelBuilder::UrdfJoint (its origin xyz [m] and rpy [rad] in the parent
// link's frame, its axis, its limits), with a 6-parameter placement error
//   T(xyz, rpy) · T(dx, dy, dz) · Rz(drz) · Ry(dry) · Rx(drx) · motion(q)
// named JOINT_dx … JOINT_drx. Fixed joints become fixed transforms. Continuous joints get limits
// [−π, π]. Floating, planar and mimic joints are not supported (error).
//
// A calibrated URDF is the source URDF with each identified joint's <origin> replaced by the
// origin composed with its error (rcal::io::ComposeUrdfOrigin), so loading it gives, at zero
// errors, the calibrated kinematics. Everything else in the file is kept. The calibrated set-up
// frames are added as fixed joints (and written to the calibrated YAML too):
//   rcal_world  → the URDF's root link   world ← base T_WB (the position sensor's frame; composed
//                                         with the fixed joints from the root to the base link)
//   rcal_earth  → rcal_world             earth ← world R_EW (the IMU's earth frame)
//   tip link    → rcal_marker            flange → marker p_FM of marker id 0 (rcal_marker_<id>)
//   tip link    → rcal_imu               flange → IMU R_FI
// so the chain rcal_world → rcal_marker of the calibrated URDF, loaded with no errors, gives the
// calibrated marker positions in the world frame.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <string>
#include <vector>

#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::io {

struct UrdfOptions {
  std::string base_link;  ///< first link of the chain; empty: the URDF's root link
  /// Last link of the chain. Empty: the child link of the deepest moving joint below base_link
  /// (depth in moving joints; for a UR arm wrist_3_link). Fixed frames after it (flange, tool0,
  /// cameras) stay out: the marker offset and IMU mounting describe what is mounted there. Two
  /// such links (two arms, gripper fingers) are an error asking for tip_link.
  std::string tip_link;
  bool identify_joints = true;  ///< 6-parameter placement error per moving joint

  /// Add a 6-DoF world ← base frame T_WB in front of the chain (ModelBuilder::BaseFrame).
  bool add_base_frame = false;
  Eigen::Vector3d base_xyz = Eigen::Vector3d::Zero();  ///< nominal p_WB_W [m]
  Eigen::Vector3d base_rpy = Eigen::Vector3d::Zero();  ///< nominal roll-pitch-yaw of R_WB [rad]
  bool identify_base = true;

  /// Add a flange(tip link) → marker offset p_FM after the chain (ModelBuilder::MarkerOffset).
  bool add_marker = false;
  Eigen::Vector3d marker_xyz = Eigen::Vector3d::Zero();  ///< nominal p_FM [m], tip-link frame
  bool identify_marker = true;
};

/// The robot description (convention urdf) of the chain in URDF text. `source` names the file in
/// error messages. Throws std::runtime_error naming the file and the link or joint at fault,
/// also for values no arm has, naming the likely unit where it explains them: an origin xyz or a
/// prismatic limit beyond 100 m, or the chain's origins adding up to more (CheckArmSize),
/// "millimetres?"; a chain joint's origin roll, pitch or yaw beyond a turn (2π, as written: the
/// parsed rotation forgets it) or a revolute limit beyond two turns (4π), "degrees?".
RobotSpec ParseUrdfRobotSpec(const std::string& urdf_xml, const std::string& source,
                             const UrdfOptions& options = {});
/// Reads a URDF file: ParseUrdfRobotSpec of its text.
RobotSpec LoadUrdfRobotSpec(const std::filesystem::path& urdf, const UrdfOptions& options = {});
/// Reads a URDF file straight into a model: BuildModel(LoadUrdfRobotSpec(urdf, options)).
kinematics::KinematicModel LoadRobotUrdf(const std::filesystem::path& urdf,
                                         const UrdfOptions& options = {});

/// The source URDF text with each joint of `model` that has identified errors (parameters
/// JOINT_dx … JOINT_drx) given its calibrated origin at parameter errors `x` [m, rad], and the
/// set-up frames as fixed joints (file comment). Throws std::runtime_error when a joint of the
/// model is not in the URDF or x has the wrong size.
/// `spec` is the description `model` was built from (BuildModel(spec), with its base and tip
/// links): the set-up frames it has are written calibrated (file comment).
std::string CalibratedUrdfText(const std::string& urdf_xml, const std::string& source,
                               const RobotSpec& spec, const kinematics::KinematicModel& model,
                               const Eigen::VectorXd& x);
/// Reads `source_urdf`, writes CalibratedUrdfText of it to `out` atomically.
void SaveCalibratedUrdf(const std::filesystem::path& source_urdf, const std::filesystem::path& out,
                        const RobotSpec& spec, const kinematics::KinematicModel& model,
                        const Eigen::VectorXd& x);

/// Link names of the set-up frames in every URDF rcal writes (file comment): "rcal_world",
/// "rcal_earth", "rcal_imu", and "rcal_marker" for marker id 0, "rcal_marker_<id>" for others.
std::string UrdfMarkerLink(int marker_id);

/// A URDF of the model `spec` describes (BuildModel(spec) = `model`) at parameter errors `x`
/// [m, rad], for robots that come from no URDF (rcal.robot/1 YAML, any convention): written from
/// the model's elementary transforms, so it holds for D–H, modified D–H, Hayati and URDF-style
/// links alike. Links: spec.base_link (root of the arm), "link1" … "linkN" after each joint
/// ("rcal_linkI" where the chain's base or tip link has that name), the joints named as the
/// model's, revolute or prismatic with the model's limits; spec.tip_link
/// after the last joint and tool; the set-up frames as fixed joints with the names of the file
/// comment (rcal_world → base_link is T_WB; rcal_earth → rcal_world, or → base_link without a
/// base frame). Loaded with no errors it gives `model` at x (CheckUrdfParity). Throws
/// std::runtime_error when x has the wrong size or a value is not finite.
std::string SpecUrdfText(const RobotSpec& spec, const kinematics::KinematicModel& model,
                         const Eigen::VectorXd& x);

/// The calibrated robot as URDF text, whatever it came from: CalibratedUrdfText of `urdf_xml`
/// when the robot came from a URDF (non-empty text; meshes, other links and fixed frames kept),
/// else SpecUrdfText. `header` lines are added as XML comments after the declaration (the
/// calibration hash, date, data and σ of rcal export). This is the text to publish as a
/// robot_description. Throws std::runtime_error as the two functions do.
std::string RobotDescriptionUrdf(const RobotSpec& spec, const kinematics::KinematicModel& model,
                                 const Eigen::VectorXd& x, const std::string& urdf_xml = {},
                                 const std::string& source = "<robot>",
                                 const std::vector<std::string>& header = {});

/// Forward kinematics straight from a URDF as liburdfdom parses it (its joint origins, axes and
/// types), independent of kinematics::ModelBuilder: the proof that a written URDF means the model
/// it was written from.
class UrdfChain {
 public:
  /// The path of joints from `root_link` down to `tip_link`. Throws std::runtime_error naming the
  /// file and the link or joint when the URDF does not parse, a link is missing, tip_link is not
  /// below root_link, or a joint on the path is floating, planar or mimic.
  UrdfChain(const std::string& urdf_xml, const std::string& source, const std::string& root_link,
            const std::string& tip_link);
  /// The moving joints on the path, root first.
  const std::vector<std::string>& joint_names() const { return joint_names_; }
  /// Pose of tip_link in root_link's frame, T_root_tip, at joint values `q` (one per
  /// joint_names(), [rad | m]). Throws std::invalid_argument for the wrong size.
  Eigen::Isometry3d Pose(const Eigen::VectorXd& q) const;

 private:
  struct Step {
    Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();  ///< parent link → joint frame
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();           ///< unit, joint frame
    int joint = -1;          ///< index into joint_names_, −1: fixed
    bool prismatic = false;  ///< else revolute or continuous
  };
  std::vector<Step> steps_;
  std::vector<std::string> joint_names_;
};

/// A robot from any file rcal accepts, with what is needed to save it calibrated.
struct LoadedRobot {
  std::filesystem::path source;  ///< the file it came from
  bool from_urdf = false;        ///< true: source is a URDF (SaveCalibratedUrdf applies)
  RobotSpec spec;                ///< the description (YAML-able in every case)
  kinematics::KinematicModel model;
};

/// Loads `.yaml`/`.yml` (schema rcal.robot/1; `urdf_options` unused) or `.urdf` files.
LoadedRobot LoadRobot(const std::filesystem::path& path, const UrdfOptions& urdf_options = {});

}  // namespace rcal::io
