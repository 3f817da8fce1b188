// The core of ros2_input: a cell's ROS 2 drivers' samples (decoded DDS samples of the ROS 2 wire
// types) in, the pipeline's sensor events out, on the arm's clock. No DDS entities, no LCM: the
// process (main.cpp) takes samples from DDS readers and publishes what this returns; tests feed it
// directly.
//
//   joints     sensor_msgs/JointState, mapped by name (dds::JointNameMap) → JOINTS, stamped with
//              the arm controller's clock: the reference clock of the pipeline.
//   IMU        sensor_msgs/Imu (+ the latest sensor_msgs/MagneticField of the same driver within
//              mag_pairing of its stamp) → IMU, the stamp moved to the joints' clock.
//   positions  geometry_msgs/PointStamped (laser tracker) or PoseStamped (motion capture), one
//              topic per marker → POSITION with the cell's σ², the stamp moved to the joints'
//              clock.
//   temperature  sensor_msgs/Temperature of the arm (optional) → ARM_CONDITIONS, through the
//              reorder buffer with the samples: still_window takes the report standing at each
//              window's middle and refuses a window within which the payload changed, so a
//              report must reach it in time order with the samples around it. With clock_offsets
//              `none` the report keeps its own stamp. With `estimate` its driver's clock is moved
//              to the joints' by the median, over its topic's last kConditionsLags reports, of
//              (the newest joints' stamp when the report arrived − its stamp): a temperature or a
//              payload shows nothing to estimate a clock from, but the median of its arrivals
//              is good to the transport's usual latency, whatever one report's delay (a report
//              stamped on its arrival alone, as before, stood as late as ros2_input was slow to
//              take it: under a loaded CPU a grasp made inside a still window was stamped after
//              the window's end, and the window measured under two loads went out as a pose).
//   payload    geometry_msgs/InertiaStamped of what the arm carries (optional; its mass m [kg])
//              → ARM_CONDITIONS, as the temperature. The two make one stream of conditions: as
//              they leave the buffer, each report carries the newest of both (NaN for one not yet
//              reported; still_window takes a NaN payload as 0), at a time after the last report
//              (a report that would stand at or before it stands 1 µs after it). A report older
//              than what already left the buffer is not dropped (the conditions would stay wrong
//              until the next report, which may come only at the next change): it leaves at
//              once, at its time, counted (conditions_late); still_window decides a window only
//              once the conditions have been reported past its end.
//
// Clocks. Every driver stamps with its own clock. With clock_offsets `estimate` each source's
// offset against the joints (offset = t_source − t_joints) is estimated from the motion itself
// (estimation::ClockOffsetEstimator: the angular rate the joints give through the kinematics
// against the gyro, the marker speed against the forward-kinematics speed) and a sample is
// published at t_source − offset; before the offset is locked the current estimate is used (0 at
// first) and CLOCK_OFFSET says so, so still_window forms no window from it. With `none` the
// drivers share the joints' clock.
//
// Order. The pipeline (still_window's PosePipeline) takes the three streams in one time order,
// but drivers deliver with their own latencies. The events wait in a reorder buffer and leave in
// time order (on the joints' clock) once they are `reorder_delay` older than the newest event; one
// that arrives older than what already left is dropped as late, counted. Before the clocks are
// locked, a source whose offset is not yet removed may so be late: counted, and no window is
// formed from that time anyway.
//
// Time and restarts. Each stream has an estimation::TimeGate on the driver's own stamps:
// duplicates, out-of-order and far-future stamps are refused and counted; a driver restart
// (its stamps jump back and go on consistently) re-synchronises the stream, counted, and its clock
// offset is estimated anew (the joints' restart restarts every offset). Bad samples (NaN, units,
// frames, sizes, missing joints) are refused naming the field (dds/ros2_convert.hpp), counted in
// HEALTH, and never stop the stream.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "rcal/clock_offset_t.hpp"
#include "rcal/dds/ros2_convert.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/transport/health.hpp"
#include "sources.hpp"

namespace rcal::ros2 {

/// Settings, all from the cell file (FromCell) but the tolerances.
struct Ros2InputSettings {
  std::vector<std::string> joint_names;  ///< chain order, as the driver names them
  std::string joint_topic = "/joint_states", imu_topic, mag_topic;
  std::string imu_frame;  ///< header.frame_id IMU messages must carry (empty: any)
  struct Position {
    std::string topic;
    int32_t marker = 0;
    bool pose = false;     ///< PoseStamped (else PointStamped)
    std::string frame_id;  ///< required header.frame_id (empty: any)
  };
  std::vector<Position> positions;
  std::string temperature_topic;  ///< empty: none
  std::string payload_topic;      ///< geometry_msgs/InertiaStamped; empty: none
  /// The temperature's and the payload's time gates take reports this far apart [s] (a
  /// controller that reports on change, or slowly; the sensors' horizon is 10 s).
  double temperature_horizon = 3600.0;
  Eigen::Matrix3d position_covariance = Eigen::Matrix3d::Zero();  ///< [m²], the cell's σ²
  transport::SensorRanges ranges;                                 ///< the cell's IMU ranges
  bool estimate_clock_offsets = true;
  double max_clock_offset = 0.5;  ///< [s]
  /// An IMU sample carries the magnetometer reading nearest to it in time when that is at most
  /// this much older or newer [s] (magnetometers often run slower than the gyro; the field
  /// changes slowly).
  double mag_pairing = 0.1;
  /// Events leave the reorder buffer this long after the newest event [s] (the spread of the
  /// drivers' latencies it absorbs).
  double reorder_delay = 0.2;
  /// The offset is good enough for still windows when 3σ is below this [s] (CLOCK_OFFSET's
  /// state `locked`).
  double lock_sigma = 0.002;
  estimation::TimeGateSettings gate;
};

/// The settings of `cell` (its `ros2:` section; throws std::runtime_error naming the cell file when
/// it has none).
Ros2InputSettings FromCell(const io::BuiltCell& cell);

/// CLOCK_OFFSET's per-source states.
enum class ClockState : int8_t { kUnknown = 0, kEstimating = 1, kLocked = 2, kFixed = 3 };

/// One source's clock against the joints'.
struct ClockStatus {
  std::string source;  ///< "imu", "position/<marker id>"
  ClockState state = ClockState::kUnknown;
  double offset = 0.0;                                     ///< t_source − t_joints [s]
  double sigma = std::numeric_limits<double>::infinity();  ///< [s]
  int32_t resets = 0;
};

class ClockOffsetTracker;  // the estimator behind the clock statuses (ros2_input.cpp)

class Ros2Input {
 public:
  /// `model`: the cell's arm (the nominal kinematics of the clock-offset estimate; copied).
  Ros2Input(const Ros2InputSettings& settings, const kinematics::KinematicModel& model,
            transport::Health& health);
  ~Ros2Input();

  /// One driver sample: checked, its stamp moved to the joints' clock, into the reorder buffer.
  void OnJointState(const dds::JointState& m);
  void OnImu(const dds::Imu& m);
  void OnMagneticField(const dds::MagneticField& m);
  /// `i`: the index in settings().positions.
  void OnPose(size_t i, const dds::PoseStamped& m);
  void OnPoint(size_t i, const dds::PointStamped& m);
  /// The arm's temperature → into the reorder buffer, stamped on the joints' clock (file
  /// comment); false: refused and counted (or no joints' time yet to move it by, under
  /// `estimate`).
  bool OnTemperature(const dds::Temperature& m);
  /// The payload the arm carries → into the reorder buffer, as OnTemperature.
  bool OnPayload(const dds::InertiaStamped& m);
  /// The events to publish now, in time order: those reorder_delay older than the newest
  /// (`flush`: all). A transport::ArmConditions event carries the newest of both conditions.
  std::vector<sensors::SensorEvent> Ready(bool flush = false);

  /// Every source's clock now.
  std::vector<ClockStatus> Clocks() const;
  /// CLOCK_OFFSET at joints' time `utime`.
  clock_offset_t ClockMessage(int64_t utime) const;
  /// Latest joints' time seen [µs] (0 before any).
  int64_t joints_utime() const { return joints_utime_; }

  /// Events dropped because they arrived older than what had left the reorder buffer.
  int64_t late() const { return late_; }
  /// IMU samples published with a magnetometer reading.
  int64_t mag_paired() const { return mag_paired_; }
  /// Temperature reports turned into ARM_CONDITIONS.
  int64_t temperatures() const { return temperatures_; }
  /// Payload reports turned into ARM_CONDITIONS.
  int64_t payloads() const { return payloads_; }
  /// Conditions reports that arrived older than what had left the buffer (published at once, not
  /// dropped).
  int64_t conditions_late() const { return conditions_late_; }
  /// How many reports the conditions' clock is taken from (the median of their arrival lags).
  static constexpr size_t kConditionsLags = 21;
  const Ros2InputSettings& settings() const { return s_; }

 private:
  struct Stream {
    Stream(std::string topic, estimation::TimeGate time_gate)
        : name(std::move(topic)), gate(std::move(time_gate)) {}
    std::string name;
    estimation::TimeGate gate;
    // A conditions topic's last (newest joints' stamp on arrival − own stamp) [µs], newest last.
    std::deque<int64_t> lags;
  };
  // Gates the driver's own stamp; false when refused (counted). Resets the source's clock on a
  // re-synchronisation.
  bool Admit(Stream& st, int64_t utime, int clock_source);
  // Into the reorder buffer at `utime` (joints' clock), or dropped as late.
  void Queue(int64_t utime, sensors::SensorEvent e);
  void Refuse(const std::string& reason);
  void OnPosition(size_t i, std::optional<transport::PositionSample> p, const std::string& frame_id,
                  const std::string& error);
  // A temperature or payload report (the other field NaN) of stream `st` → stamped on the joints'
  // clock (see the file comment) and queued; false: refused.
  bool Conditions(std::optional<transport::ArmConditions> c, Stream& st, const std::string& error);

  Ros2InputSettings s_;
  transport::Health& health_;
  dds::JointNameMap names_;
  Stream joints_, imu_, mag_, temperature_, payload_;  // the streams' time gates
  std::vector<Stream> positions_;
  // The recent magnetometer readings, increasing stamps (the IMU sample takes the nearest: the
  // two topics arrive in no fixed order relative to each other).
  std::deque<dds::MagReading> mags_;
  std::unique_ptr<ClockOffsetTracker> clocks_;
  // The reorder buffer: (utime, arrival sequence) → event.
  std::map<std::pair<int64_t, int64_t>, sensors::SensorEvent> queue_;
  int64_t sequence_ = 0, newest_ = std::numeric_limits<int64_t>::min(),
          released_ = std::numeric_limits<int64_t>::min();
  int64_t joints_utime_ = 0, late_ = 0, mag_paired_ = 0, temperatures_ = 0, payloads_ = 0,
          conditions_late_ = 0;
  // The newest conditions released: their time [µs, joints' clock], temperature and payload.
  transport::ArmConditions conditions_{std::numeric_limits<int64_t>::min()};
};

}  // namespace rcal::ros2
