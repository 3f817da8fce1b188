// Robots and their measurement set-up as YAML files (config/robots/*.yaml).
//
// Schema `rcal.robot/1`. SI units only: lengths in metres, angles in radians. Any angle may be
// written as a number or as a readable multiple of π: `pi`, `-pi/2`, `2*pi/3`, `0.5*pi`.
// Unknown keys, missing required keys, wrong types and non-finite values are errors naming the
// file and the key path, e.g. `grb3016.yaml: links[2].alpah: unknown key (line 14)`. So are
// absurd values: a length (or prismatic limit) beyond 100 m, or lengths adding up to more
// (CheckArmSize); a constant angle (alpha, theta, beta, rpy) beyond a turn (2π) or a revolute
// limit beyond two turns (4π); a lower limit not below the upper one. Where millimetres or
// degrees explain the value the message says so, e.g.
// `links[0].alpha: '-90' rad is beyond a turn (2π): degrees? rcal files are in radians: -90° is
// -pi/2 (line 15)`.
//
//   schema: rcal.robot/1                     # required, exactly this
//   name: grb3016                            # required
//   convention: dh                           # required: dh | mdh | urdf
//   base:   {xyz: [x, y, z], rpy: [r, p, y], identify: true}    # optional: T_WB, world ← base
//   links:                                   # required, at least one joint, in chain order
//     # dh  (standard D–H): Rz(theta + q) · Tz(d) · Tx(a) · Rx(alpha) [· Ry(beta) if hayati]
//     # mdh (modified D–H): Rx(alpha) · Tx(a) · [Ry(beta) ·] Rz(theta + q) · Tz(d)
//     #       (a, alpha are those of the previous axis, a_{i-1} and alpha_{i-1})
//     - a: 0.150                             # [m]      required
//       alpha: -pi/2                         # [rad]    required
//       d: 0.250                             # [m]      required
//       theta: 0                             # [rad]    required (offset added to the joint)
//       hayati: false                        # optional: identify beta instead of d
//       beta: 0                              # [rad]    optional, only with hayati: true
//       joint: {name: j1, type: revolute, lower: -2.96, upper: 2.96}   # required
//     # urdf: T(xyz, rpy) · [6-parameter placement error] · motion about/along axis
//     - xyz: [0, 0, 0.1807]                  # [m]      required
//       rpy: [0, 0, 0]                       # [rad]    required, R = Rz(y)·Ry(p)·Rx(r)
//       axis: [0, 0, 1]                      # unit vector, required with a joint
//       joint: {name: shoulder_pan_joint, type: revolute, lower: -6.28, upper: 6.28}
//       identify: true                       # optional (default true), joint entries only
//     - {name: flange, xyz: [0, 0, 0], rpy: [0, 0, 0]}   # no joint: a fixed transform
//   tool:   {a: 0.01, alpha: 0.1, d: 0.05, theta: 0.2, identify: true}  # optional, D–H tool
//   marker: {xyz: [x, y, z], identify: true}  # optional: p_FM, flange → marker [m] (id 0)
//   markers:                                 # or several measured points on the tool, each id
//     - {id: 1, xyz: [x, y, z], identify: true}  # its own p_FM [m] (the datasets' `marker`)
//   imu:    {rpy: [r, p, y], identify: true}  # optional: R_FI, flange → IMU [rad]
//   earth:  {rpy: [r, p, y], identify: true}  # optional: R_EW, earth ← world [rad]
//
// `joint.type` is revolute or prismatic; `lower`/`upper` are [rad] or [m]. The model is built in
// the order base, links, tool, marker (kinematics::ModelBuilder); imu and earth are the
// orientation-only segments.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "rcal/kinematics/model.hpp"

namespace rcal::io {

enum class Convention { kDh, kModifiedDh, kUrdf };

/// One entry of `links:`. Which fields matter depends on the convention (see the file comment).
struct LinkSpec {
  // dh / mdh [m, rad]
  double a = 0.0, alpha = 0.0, d = 0.0, theta = 0.0;
  bool hayati = false;
  double beta = 0.0;  ///< nominal Hayati β [rad]
  // urdf: the joint's origin in its parent frame [m, rad] and its axis (unit, joint frame)
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  bool identify = true;  ///< urdf: the 6-parameter placement error is identified
  std::string name;      ///< urdf fixed entries: the URDF joint name (informational)
  /// The joint; absent only for urdf fixed transforms.
  std::optional<kinematics::Joint> joint;
};

/// The paper's D–H tool transform after the last joint [m, rad].
struct ToolSpec {
  double a = 0.0, alpha = 0.0, d = 0.0, theta = 0.0;
  bool identify = true;
};

/// A 6-DoF frame (translation [m], roll-pitch-yaw [rad]).
struct FrameSpec {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Eigen::Vector3d rpy = Eigen::Vector3d::Zero();
  bool identify = true;
};

/// A measured point on the tool: its id (the datasets' `marker` column) and offset p_FM [m] in the
/// flange frame.
struct MarkerSpec {
  int id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  bool identify = true;
};

/// Everything a robot file says: the arm and its measurement set-up.
struct RobotSpec {
  std::string name;
  /// The chain's first and last links: the URDF link names it ran between; "base" and "flange"
  /// for a YAML robot (not in the file). Reports name the chain and the frames of the set-up
  /// offsets with them (world ← base_link, tip_link → marker).
  std::string base_link = "base", tip_link = "flange";
  Convention convention = Convention::kDh;
  std::vector<LinkSpec> links;
  std::optional<FrameSpec> base;    ///< T_WB, world ← base
  std::optional<ToolSpec> tool;     ///< D–H tool after the last link
  std::vector<MarkerSpec> markers;  ///< flange → marker offsets, one per id (ids distinct)
  std::optional<FrameSpec> imu;     ///< R_FI = rpy (xyz unused)
  std::optional<FrameSpec> earth;   ///< R_EW = rpy (xyz unused)
};

/// Parses YAML text of schema rcal.robot/1. `source` names the file in error messages.
/// Throws std::runtime_error "SOURCE: KEY.PATH: what is wrong (line N)".
RobotSpec ParseRobotYaml(const std::string& text, const std::string& source = "<text>");
/// Reads and parses a robot file. Throws std::runtime_error naming the file and the key.
RobotSpec LoadRobotSpec(const std::filesystem::path& path);

/// Builds the kinematic model a spec describes. Throws std::runtime_error on an inconsistent spec.
kinematics::KinematicModel BuildModel(const RobotSpec& spec);

/// Refuses a robot whose links add up (Σ|a| + |d| per D–H link and tool, |xyz| per URDF origin)
/// to more than 100 m, the bound of one length: no arm is that long (the largest industrial arms
/// reach about 4 m), while every length alone may be below it (a small arm in millimetres). The
/// message names millimetres. ParseRobotYaml and ParseUrdfRobotSpec call it. Throws
/// std::runtime_error "SOURCE: links: ...".
void CheckArmSize(const RobotSpec& spec, const std::string& source);

/// Loads a robot YAML file straight into a model: BuildModel(LoadRobotSpec(path)).
kinematics::KinematicModel LoadRobotYaml(const std::filesystem::path& path);

/// The spec whose nominal values are `model`'s at parameter errors `x` [m, rad]: each identified
/// error is folded into the nominal value it belongs to, so BuildModel(result) at x = 0 has the
/// same kinematics as `model` at x. `model` must be BuildModel(spec) (same parameter names);
/// throws std::runtime_error otherwise.
RobotSpec CalibratedSpec(const RobotSpec& spec, const kinematics::KinematicModel& model,
                         const Eigen::VectorXd& x);

/// The YAML text of a spec (schema rcal.robot/1, full double precision, multiples of π written as
/// `pi/2` etc. when exact). `header` lines are written as `#` comments at the top.
std::string RobotYamlText(const RobotSpec& spec, const std::vector<std::string>& header = {});

/// Writes a spec as YAML, atomically.
void SaveRobotYaml(const std::filesystem::path& path, const RobotSpec& spec,
                   const std::vector<std::string>& header = {});

/// Writes the calibrated robot (CalibratedSpec(spec, model, x)) as YAML, atomically.
void SaveCalibratedRobotYaml(const std::filesystem::path& path, const RobotSpec& spec,
                             const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const std::vector<std::string>& header = {});

/// Parses a readable angle [rad]: a number, or a product/quotient of numbers and `pi` with an
/// optional sign (`-pi/2`, `2*pi/3`, `0.25*pi`). Returns nullopt when `text` is not one.
std::optional<double> ParseAngle(const std::string& text);

/// Composes a URDF joint origin with its identified 6-parameter error, in the order
/// kinematics::ModelBuilder::UrdfJoint lays the ETs out:
///   origin' = T(xyz, rpy) · T(dx, dy, dz) · Rz(drz) · Ry(dry) · Rx(drx).
/// `error` is [dx, dy, dz, drz, dry, drx] [m, rad]. Returns the new xyz [m] and rpy [rad]
/// (pitch in [−π/2, π/2]).
void ComposeUrdfOrigin(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy,
                       const Eigen::Matrix<double, 6, 1>& error, Eigen::Vector3d* xyz_out,
                       Eigen::Vector3d* rpy_out);

/// Roll-pitch-yaw [rad] of a rotation with R = Rz(yaw)·Ry(pitch)·Rx(roll), pitch in [−π/2, π/2],
/// accurate to machine precision also near pitch = ±π/2 (roll is taken from the rotation left
/// after yaw and pitch, so FromRpy(result) reproduces R).
Eigen::Vector3d RobustRpy(const Eigen::Matrix3d& R);

}  // namespace rcal::io
