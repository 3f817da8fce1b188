// Where sensor_acquisition's raw streams come from. A source yields IMU, POSITION and JOINTS
// samples in sensor-time order with utime from the source; the process publishes them.
//
// A real sensor driver implements SensorSource: Next() blocks (up to the timeout) for the next
// sample from the device, stamps it with the device's own clock (utime [µs], SI units, sensor
// axes), and Recorded() returns false so the process publishes it at once instead of pacing it.
// Recorded sources (files) return true and the process paces them by utime (--speed).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "rcal/joint_state_t.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/filter_nodes.hpp"

namespace rcal::sensors {

/// One sample of a source, published on its channel (ARM_CONDITIONS for the arm's conditions: a
/// live source such as ros2_input's drivers orders them with the samples).
using SensorEvent = std::variant<transport::ImuSample, transport::PositionSample, joint_state_t,
                                 pose_measurement_t, transport::ArmConditions>;

/// Sensor time of an event [µs].
int64_t Utime(const SensorEvent& e);

class SensorSource {
 public:
  virtual ~SensorSource() = default;
  /// One line for the log: what the source reads.
  virtual std::string Describe() const = 0;
  /// The next sample, or nullopt when none came within `timeout_ms` (live) or the stream ended
  /// (then Finished() is true).
  virtual std::optional<SensorEvent> Next(int timeout_ms) = 0;
  virtual bool Finished() const = 0;
  /// True for files: the caller paces samples by utime. False for live drivers.
  virtual bool Recorded() const = 0;
};

/// A raw-stream CSV in the BROAD layout (../shared/data/broad/README.md): `t_s` [s],
/// `gyr_x..z` [rad/s], `acc_x..z` [m/s²], `mag_x..z` [file unit, µT in BROAD], optional
/// `pos_x..z` [m] (NaN where the marker was hidden); other columns are ignored. Each row is one
/// IMU sample with utime = round(t_s · 1e6) + utime_offset; the position, where finite, is
/// decimated to `position_rate` (the first finite row, then every 1/position_rate s of file
/// time) and published after the IMU sample of its row.
struct RawCsvReplaySettings {
  double position_rate = 20.0;   ///< [Hz]; 0: every row with a finite position
  double mag_scale = 1e-6;       ///< file unit → T (BROAD's µT)
  double position_sigma = 1e-3;  ///< σ per axis in the published covariance [m]
  int64_t max_rows = 0;          ///< rows to replay (0: all)
  int64_t utime_offset = 0;      ///< added to every utime [µs]
  int32_t sensor_id = 0;
  int32_t marker_id = 0;
};

class RawCsvReplaySource final : public SensorSource {
 public:
  /// Reads the whole file. Throws std::runtime_error naming the file and a missing column.
  RawCsvReplaySource(const std::string& path, const RawCsvReplaySettings& settings);
  std::string Describe() const override;
  std::optional<SensorEvent> Next(int timeout_ms) override;
  bool Finished() const override { return next_ >= events_.size(); }
  bool Recorded() const override { return true; }
  size_t size() const { return events_.size(); }

 private:
  std::string path_;
  std::vector<SensorEvent> events_;
  size_t next_ = 0;
  int64_t imu_count_ = 0, position_count_ = 0;
};

/// True when the CSV at `path` has the raw-stream columns (t_s, gyr_x); otherwise it is taken as a
/// pose dataset. Throws std::runtime_error naming the file when it cannot be read.
bool IsRawStreamCsv(const std::string& path);

/// A pose dataset (ARCHITECTURE.md "Data formats", read by io::LoadPoseDataset): each still pose
/// becomes JOINTS and a POSE_MEASUREMENT (pose_index = row among the replayed ones) with the
/// covariance diag(σ_p² I, σ_R² I). utime: the `time` column when every replayed row has one,
/// else start_utime + k / rate. Rows of the `test` set are skipped unless include_test.
struct PoseDatasetReplaySettings {
  double rate = 2.0;                    ///< [poses/s] when the file has no time column
  int64_t start_utime = 1'000'000;      ///< [µs]
  double position_sigma = 5e-5;         ///< [m]
  double orientation_sigma = 1.745e-3;  ///< [rad]
  bool include_test = false;
  int num_joints = -1;  ///< expected joints (−1: from the q1..qN columns, or the model's)
  /// When set, every row is checked against this robot before anything is published: its
  /// joint count, joints within its limits, positions within its reach
  /// (io::CheckPosesPlausible); a row it cannot have produced refuses the whole file.
  const kinematics::KinematicModel* model = nullptr;
};

class PoseDatasetReplaySource final : public SensorSource {
 public:
  PoseDatasetReplaySource(const std::string& path, const PoseDatasetReplaySettings& settings);
  std::string Describe() const override;
  std::optional<SensorEvent> Next(int timeout_ms) override;
  bool Finished() const override { return next_ >= events_.size(); }
  bool Recorded() const override { return true; }
  size_t size() const { return events_.size(); }

 private:
  std::string path_;
  std::vector<SensorEvent> events_;
  size_t next_ = 0;
  int poses_ = 0;
};

/// The simulated programme a sensor_acquisition checkpoint belongs to: a restart resumes only the
/// same programme (same level, seed, stop counts, start time and rate).
struct SimProgramme {
  std::string level;  ///< "poses" | "sensors"
  uint64_t seed = 1;
  int64_t poses = 0;        ///< calibration stops (pose level: 0 = unlimited)
  int64_t test_poses = 0;   ///< sensors level: test stops drawn after them
  int64_t start_utime = 0;  ///< [µs] sensor time of tick (pose) 0
  double rate = 0.0;        ///< [Hz] ticks (sensors level) or poses (pose level) per second
};

/// Where a restarted simulated source resumes (`--checkpoint FILE`, JSON, schema
/// `rcal.sensor_acquisition_checkpoint/1`, written atomically). It is a lease, written *before*
/// the ticks it covers are published: `next_tick` is the first tick the process has not yet
/// been allowed to publish, so a process killed anywhere inside the lease resumes at `next_tick`
/// and never publishes a tick (a sensor time) twice; at most one lease of ticks is lost.
/// `next_utime` is that tick's sensor time (for people; the programme defines it).
struct SimCheckpoint {
  SimProgramme programme;
  int64_t next_tick = 0;
  int64_t next_utime = 0;
  bool finished = false;  ///< the programme was published to its end
};

/// JSON text of a checkpoint.
std::string SimCheckpointText(const SimCheckpoint& c);
/// Parses SimCheckpointText output. Throws std::runtime_error naming the key on a malformed text.
SimCheckpoint ParseSimCheckpoint(const std::string& text);
/// Writes atomically (temporary file + rename). Throws std::runtime_error naming the path.
void SaveSimCheckpoint(const std::filesystem::path& path, const SimCheckpoint& c);
/// The checkpoint at `path` for `programme`: nullopt when there is no file; throws
/// std::runtime_error naming the path and the key when it cannot be parsed or belongs to another
/// programme (a different seed, stop count, ...: resuming it would publish another programme's
/// sensor time).
std::optional<SimCheckpoint> LoadSimCheckpoint(const std::filesystem::path& path,
                                               const SimProgramme& programme);

}  // namespace rcal::sensors
