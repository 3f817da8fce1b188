// Pose datasets: still poses of the arm with what was measured there (ARCHITECTURE.md, "Data
// formats that people bring").
//
// rcal layout: CSV, one row per still pose (or per marker measured at a pose), `#` comment lines
// before the header, columns found by name in any order, SI units:
//   q1..qN          joint positions as read [rad | m]                         required
//   x, y, z         measured marker position p_WM_W, world frame [m]          required
//   qw, qx, qy, qz  measured tool orientation q_EI (imu → earth), [w,x,y,z]   optional, all four
//                   (norm within 1e-3 of 1, normalised; a row may leave all four empty)
//   marker          integer id ≥ 0 of the measured point (own flange→marker offset) optional, 0
//   temperature [°C], payload [kg], time [s]                                  optional, NaN
//   dq1..dqN        sign (−1, 0, +1) of each joint's last motion before the stop  optional
//   set             `cal` | `test` (empty: unspecified)                        optional
// Other columns are ignored with a warning naming them (PoseDataset::ignored_columns).
//
// FIGAROH layout (e.g. data/figaroh_ur10/calibration.csv), recognised by its `x1` and
// `phix1` columns: per measured marker k = 1, 2, ... the columns xk, yk, zk [m] and optionally
// phixk, phiyk, phizk (roll, pitch, yaw [rad], R = Rz(yaw)·Ry(pitch)·Rx(roll)), world frame; every
// other column is a joint position named after its joint, in the model's joint order. Marker k
// becomes PoseSample::marker = k − 1, one sample per marker and row.
//
// Values no measurement can have are refused naming the row and column: non-finite joints and
// positions, |q| beyond 1000 (rad or m), |x|, |y|, |z| beyond 1e6 m, angles beyond 100 rad,
// temperature outside [−273.15, 1000] °C, payload outside [0, 1e4] kg, |time| beyond 1e10 s.
// What the robot cannot reach is CheckPosesPlausible's: joints beyond their limits, positions
// beyond the arm's reach.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "rcal/kinematics/model.hpp"

namespace rcal::io {

/// What was measured at one still pose.
struct PoseSample {
  enum Set { kUnspecified, kCal, kTest };

  Eigen::VectorXd q;                                 ///< joint positions [rad | m]
  Eigen::Vector3d p_WM_W = Eigen::Vector3d::Zero();  ///< measured marker position, world [m]
  bool has_orientation = false;
  Eigen::Vector4d q_EI_wxyz = Eigen::Vector4d(1, 0, 0, 0);  ///< unit, imu → earth [w,x,y,z]
  int marker = 0;                ///< id of the measured point on the tool
  double temperature = kAbsent;  ///< [°C], NaN when absent
  double payload = kAbsent;      ///< [kg], NaN when absent
  double time = kAbsent;         ///< [s], NaN when absent
  Eigen::VectorXi dq_sign;       ///< sign of the last motion per joint; empty when absent
  Set set = kUnspecified;
  int row = 0;  ///< data row of the file it was read from (1 = first), 0 when not from a file

  static constexpr double kAbsent = std::numeric_limits<double>::quiet_NaN();
};

struct PoseDataset {
  std::vector<PoseSample> samples;
  int num_joints = 0;
  bool has_orientation = false;              ///< every sample has an orientation
  std::vector<std::string> joint_names;      ///< FIGAROH layout: joint columns in order; else empty
  std::vector<std::string> ignored_columns;  ///< columns not understood (warned about)
  std::vector<std::string> comments;         ///< the `#` lines before the header, without the '#'
};

/// Reads a pose dataset, rcal or FIGAROH layout (see the file comment). `expected_num_joints`
/// > 0 makes a different joint count an error; ≤ 0 takes N from the q1..qN columns. For the
/// FIGAROH layout, `joint_names`, when given, picks the joint columns by name in that order
/// (other columns are ignored); otherwise every non-marker column is a joint, in file order.
/// Throws std::runtime_error naming the file, the column and the row (1 = first data row).
PoseDataset LoadPoseDataset(const std::filesystem::path& path, int expected_num_joints = -1,
                            const std::vector<std::string>& joint_names = {});
/// The same from CSV text; `source` names it in errors.
PoseDataset ParsePoseDataset(const std::string& text, const std::string& source,
                             int expected_num_joints = -1,
                             const std::vector<std::string>& joint_names = {});

/// Reads a FIGAROH-layout file (LoadPoseDataset detects it too).
PoseDataset LoadFigarohDataset(const std::filesystem::path& path,
                               const std::vector<std::string>& joint_names = {});
/// The UR10 data of data/figaroh_ur10/calibration.csv: the FIGAROH layout with the six
/// UR joint columns (shoulder_pan_joint … wrist_3_joint) in chain order.
PoseDataset LoadFigarohUr10(const std::filesystem::path& path);

/// How far measured poses may lie from what the robot can do before they are refused as
/// impossible (a wrong unit, a corrupted cell, another robot's file), not just inaccurate.
struct PosePlausibility {
  /// A joint may read this far beyond its limits [rad] (revolute) or [m] (prismatic): limits in
  /// a robot file are often the controller's soft limits, and calibration data sits near them.
  double joint_limit_margin_rad = 0.1;
  double joint_limit_margin_m = 0.01;
  /// A revolute joint whose limits span a full turn or more (a URDF continuous joint gets
  /// [−π, π]) may read any number of turns: it is refused only beyond ±this [rad].
  double wrapping_joint_bound_rad = 100.0;
  /// Positions may lie this far [m] beyond the arm's reach (ArmReach): room for an unknown
  /// marker offset and errors in the drawing.
  double reach_margin_m = 1.0;
};

/// An upper bound [m] on the distance of the marker from the origin of the chain's first frame:
/// the sum of the translations of the chain (link lengths and offsets, a prismatic joint at its
/// largest |limit|, the nominal tool and marker offsets). With `include_base`, the nominal
/// world ← base translation is included (then it bounds |p_WM_W|); without, identified base
/// translations are left out (their nominal is only a guess).
double ArmReach(const kinematics::KinematicModel& model, bool include_base);

/// Refuses a dataset the robot cannot have produced: a joint beyond its limits by more than the
/// margin, or a marker position beyond the arm's reach plus the margin. When the world ← base
/// translation is known (fixed in the model), |p_WM_W| is bounded by ArmReach(model, true); when
/// it is identified (unknown), each position's distance from the median of all positions is
/// bounded by (1 + √3)·ArmReach(model, false) (the median of points in a ball of radius R lies
/// within √3·R of its centre). Throws std::runtime_error "SOURCE: row N column 'q2': ..." naming
/// the first offending row (PoseSample::row, else the sample's position in the dataset) and
/// column, and, when the whole file shows it, the likely cause:
/// - "joints in degrees?": some joint the file limits to less than a turn spans more than two
///   turns (4π; prismatic: more than ten times its travel), or a wrapping joint reads beyond its
///   bound, while every revolute (prismatic) reading × π/180 (× 1e-3) lies within its limits;
/// - "is this the robot that was measured?": more than one pose has a joint beyond the limits
///   (one can be a corrupted cell) and no unit explains it;
/// - "positions in millimetres?": half the positions lie beyond the reach (one corrupted row
///   does not move the median) and × 1e-3 every one lies within it.
void CheckPosesPlausible(const PoseDataset& data, const kinematics::KinematicModel& model,
                         const std::string& source, const PosePlausibility& settings = {});

/// The rcal-layout CSV text of a dataset (full double precision). Optional columns are written
/// when any sample has them; `comments` become `#` lines.
std::string PoseDatasetText(const PoseDataset& data);
/// Writes PoseDatasetText(data) atomically.
void SavePoseDataset(const std::filesystem::path& path, const PoseDataset& data);

}  // namespace rcal::io
