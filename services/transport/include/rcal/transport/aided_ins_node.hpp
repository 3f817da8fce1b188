// The tracker-aided INS (estimation/aided_ins.hpp) as a pipeline node: IMU + POSITION →
// estimation::OrientationKf (the heading source: its attitude starts the INS, the field its heading
// row accepts is levelled with the INS's own tilt) and estimation::AidedIns →
// INS_ORIENTATION (orientation_estimate_t: q_EI, the attitude covariance, the gyro bias) and
// INS_TOOL_POSITION (tool_position_estimate_t: the marker in the tracker's frame W), HEALTH at 1 Hz
// of sensor time. Each IMU sample is stepped as `rcal fuse` steps it
// (estimation::StepAfterOrientationKf), so a replay of a recording gives `rcal fuse`'s INS.
//
// Time. The INS integrates the IMU in sensor-time order and takes each tracker sample after the
// first IMU sample at or after its stamp, taken back along that step to its own time (a tracker's
// stamps need not fall on the IMU's; AidedIns::UpdatePosition). So an IMU sample waits until the
// POSITION stream has reached its utime: whatever order the two streams' messages arrive in, and
// at whatever speed, the updates are the same. The tracker is slower than the IMU (20 Hz against
// 100–1000 Hz) and its samples come later: the estimates lag by up to one tracker period plus its
// latency. Without positions (none yet, or none for `position_timeout_us` of the host's steady
// clock: a tracker that stopped or lost the marker) IMU samples go in once the IMU stream is
// `position_wait_us` past them, and a position that then comes too late for its step is refused
// and counted. Bad input is rejected and counted in HEALTH with a reason naming the field, as in
// filter_nodes.hpp; each stream has its own time gate; a filter that goes non-finite resets.
//
// The tracker's frame: Options::world_from_earth (a cell's earth_from_world, fixed or a prior: its
// covariance then lets the INS learn it), or, for a guessed frame, the identifier's first estimate
// (KINEMATIC_PARAMS of the cell's model): until it comes, positions are not used (counted in
// positions_awaiting_frame() and said in HEALTH's activity) and the INS does not start. Each later
// estimate of a frame that is not fixed adds the information the identifier gained since its
// previous one (AidedIns::UpdateWorldFromEarth: its estimates are cumulative, so each is not
// counted as new); the INS learns the frame from its own measurements besides. HEALTH's activity
// says which: "R_WE: fixed", "R_WE: the cell's prior, learned", "R_WE: awaiting the identifier's
// (N positions unused)", "R_WE: the identifier's (N estimates; M positions unused before)".
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/transport.hpp"

namespace rcal::transport {

/// The INS's attitude as an ORIENTATION message: q_EI = q_EB, the covariance of its attitude error
/// (left, earth frame, as the orientation KF's), its gyro bias [rad/s].
orientation_estimate_t ToOrientationEstimate(const estimation::AidedIns& ins, int64_t utime);
/// The INS's marker as a TOOL_POSITION message: p_WM_W [m], v_WM_W [m/s] and the covariance of
/// [p; v] (estimation::AidedIns::marker_covariance), in the tracker's frame W.
tool_position_estimate_t ToToolPositionEstimate(const estimation::AidedIns& ins, int64_t utime);

class AidedInsNode : public MergingNode {
 public:
  struct Options {
    std::string name = "aided_ins";  ///< process name in HEALTH
    int32_t sensor_id = 0;           ///< other IMUs' samples are ignored (not rejected)
    int32_t marker_id = 0;           ///< other markers' samples are ignored (not rejected)
    /// The heading from the orientation KF's attitude instead of its accepted field
    /// (estimation::StepAfterOrientationKf).
    bool heading_from_kf = false;
    int64_t position_wait_us = 250'000;  ///< IMU sensor time before the fallback [µs]
    /// Host steady-clock time without a POSITION before the tracker counts as stopped [µs].
    int64_t position_timeout_us = 1'000'000;
    /// The host's steady clock [µs] (tests inject one).
    std::function<int64_t()> steady_now_us = SteadyNowUs;
    size_t max_pending = 10'000;  ///< IMU and position samples kept waiting, each, at most
    std::string imu_channel = "IMU";
    std::string position_channel = "POSITION";
    std::string orientation_channel = "INS_ORIENTATION";
    std::string tool_position_channel = "INS_TOOL_POSITION";
    std::string health_channel = "HEALTH";
    std::string kinematic_params_channel = "KINEMATIC_PARAMS";
    estimation::TimeGateSettings time;  ///< each stream's time gate (IMU, POSITION)
    SensorRanges ranges;
    /// R_WE (tracker ← earth) and the covariance [rad²] of its error (AidedIns::SetWorldFromEarth:
    /// zero when known). A rotation: the constructor throws std::invalid_argument otherwise.
    Eigen::Matrix3d world_from_earth = Eigen::Matrix3d::Identity();
    Eigen::Matrix3d world_from_earth_covariance = Eigen::Matrix3d::Zero();
    /// False (a cell whose earth_from_world is a guess): the frame is the identifier's first
    /// estimate of `model` (header comment), which then must have an earth frame.
    bool world_from_earth_known = true;
    std::shared_ptr<const kinematics::KinematicModel> model;
  };
  /// Throws std::invalid_argument naming a setting outside its domain (the filters' own checks)
  /// or options that cannot work (an unknown frame without a model with an earth frame).
  AidedInsNode(Transport& t, const estimation::OrientationKfSettings& orientation,
               const estimation::AidedInsSettings& ins, Options options);

  void OnImu(const imu_sample_t& msg);
  void OnPosition(const position_sample_t& msg);
  void OnKinematicParams(const kinematic_params_t& msg);

  const estimation::AidedIns& ins() const { return ins_; }
  const estimation::OrientationKf& orientation_kf() const { return okf_; }
  /// Positions not used while the tracker's frame was unknown.
  int64_t positions_awaiting_frame() const { return positions_awaiting_frame_; }
  /// KINEMATIC_PARAMS taken (the frame's estimates), and those left: of another model, for a
  /// fixed frame.
  int64_t frame_estimates() const { return frame_estimates_; }
  int64_t ignored_params() const { return ignored_params_; }

 private:
  void StartOver() override;
  // Sensor time up to which IMU samples may be integrated: both streams have reached it, or the
  // tracker has stopped and the IMU is position_wait_us past it.
  int64_t Watermark() const;
  void Flush();
  void StepImu(int64_t utime, const ImuSample& s);
  void ApplyPosition(int64_t utime, const Eigen::Vector3d& p_WM_W);
  void Publish(int64_t utime, bool attitude);
  void Failed(const std::string& reason, int64_t resets_before);
  // HEALTH's activity: where R_WE comes from and, once there are any, the positions the INS did
  // not simply take (refused by its χ² gate, taken as the accelerometer's shock, re-anchored) and
  // the IMU silences it started again after.
  void SayActivity();

  Options o_;
  estimation::OrientationKf okf_;
  estimation::AidedIns ins_;
  estimation::TimeGate imu_gate_, position_gate_;
  std::optional<int64_t> last_imu_, last_position_, last_stepped_;
  std::optional<int64_t> last_position_arrival_us_;  // host steady clock [µs]
  bool frame_known_ = true, frame_fixed_ = false;
  std::map<int64_t, ImuSample> pending_imu_;
  std::multimap<int64_t, Eigen::Vector3d> pending_position_;
  int64_t positions_awaiting_frame_ = 0, ignored_params_ = 0, frame_estimates_ = 0;
  // The positions the INS refused by its gate, took as shocks and re-anchored, over the node's
  // life (the INS's own counters start again at each of its resets), and what the activity said.
  std::array<int64_t, 3> position_totals_{0, 0, 0}, said_positions_{0, 0, 0};
  // IMU silences the INS re-initialised after (AidedInsSettings::max_step), over the node's life.
  int64_t silences_ = 0;
};

}  // namespace rcal::transport
