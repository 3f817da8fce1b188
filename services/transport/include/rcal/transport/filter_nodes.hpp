// The sensor-fusion filters as pipeline nodes: message checks and conversions for the raw sensor
// streams (IMU, POSITION) and the estimates (ORIENTATION, TOOL_POSITION), and the two nodes the
// orientation_kf and position_kf processes run. A node owns a library filter and a Health, is
// driven only by messages on a Transport (so the same code runs over UDP multicast, memq:// in
// tests and benchmarks, or a log), and runs the filter on sensor time t = utime · 1e-6 s.
//
// Bad input is rejected, counted in HEALTH with a reason naming the field, and leaves the filter
// untouched: a message that does not decode (wrong type, truncated), non-finite values, values
// beyond the sensor's range (SensorRanges), a non-unit quaternion, an IMU sample without
// magnetometer (the orientation KF needs it). Time: every stream passes its own
// estimation::TimeGate (Options::time): exact duplicates, samples before the last one and
// samples beyond the horizon (or the host-clock ceiling) are refused and counted apart in HEALTH;
// a stream whose time really jumped is re-synchronised after time.resync_samples consistent
// samples, and the filter is then started over. A filter whose state goes non-finite resets
// (HEALTH filter_resets, last_error) and nothing non-finite is ever published.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/transport.hpp"

namespace rcal::transport {

// ---- raw sensor samples -----------------------------------------------------------------------

struct ImuSample {
  int64_t utime = 0;  ///< [µs]
  int32_t sensor_id = 0;
  Eigen::Vector3d gyro_B = Eigen::Vector3d::Zero();  ///< [rad/s], imu axes
  Eigen::Vector3d f_B = Eigen::Vector3d::Zero();     ///< specific force [m/s²], imu axes
  bool has_mag = false;                              ///< m_B valid
  Eigen::Vector3d m_B = Eigen::Vector3d::Zero();     ///< magnetic field [T], imu axes
};

struct PositionSample {
  int64_t utime = 0;  ///< [µs]
  int32_t marker_id = 0;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();           ///< [m]
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< [m²]
};

/// What a sensor can report at most (per axis): a sample beyond it is corrupt, not a measurement.
/// The defaults are above the widest ranges of the IMUs and position sensors rcal is used with.
struct SensorRanges {
  double gyro = 40.0;       ///< [rad/s] (≈ 2300 °/s; MEMS gyros: up to 2000 °/s)
  double accel = 320.0;     ///< [m/s²] (≈ 32 g; MEMS accelerometers: 16–20 g)
  double mag = 5e-3;        ///< [T] (the earth's field: 25–65 µT; magnetometers: ≤ 1.6 mT)
  double position = 100.0;  ///< [m] from the position sensor's origin (laser trackers: ≤ 80 m)
};

imu_sample_t ToMessage(const ImuSample& s);
/// Checks finite gyro and accel, finite mag when has_mag, each within `ranges` (the reason names
/// the field and the range).
std::optional<ImuSample> ImuFromMessage(const imu_sample_t& msg, std::string* error,
                                        const SensorRanges& ranges = {});

position_sample_t ToMessage(const PositionSample& s);
/// Checks finite p within ranges.position of the origin and a finite, symmetric covariance with
/// a non-negative diagonal.
std::optional<PositionSample> PositionFromMessage(const position_sample_t& msg, std::string* error,
                                                  const SensorRanges& ranges = {});

// ---- estimates --------------------------------------------------------------------------------

/// The orientation KF's current estimate (q_EB = q_EI, attitude covariance, gyro bias).
orientation_estimate_t ToOrientationEstimate(const estimation::OrientationKf& kf, int64_t utime);
/// Message → R_EI. Checks finite values and |q| within 1e-6 of 1 (renormalised).
std::optional<Eigen::Matrix3d> RotationFromMessage(const orientation_estimate_t& msg,
                                                   std::string* error);

/// The position KF's current estimate: p, v and the 6×6 covariance of [p; v]; a bank's is the
/// mixture's.
tool_position_estimate_t ToToolPositionEstimate(const estimation::PositionKf& kf, int64_t utime);
tool_position_estimate_t ToToolPositionEstimate(const estimation::PositionKfBank& kf,
                                                int64_t utime);

/// The identifier's estimate of the earth frame, as the position sensor's frame takes it: R_WE
/// (world ← earth) = R_EW(x)ᵀ and the covariance [rad²] of its error from the message's sigmas
/// (KinematicModel::WorldFromEarthCovariance). `msg` is an estimate of `model` (its model_id is
/// the caller's to check). Refused, naming the field: values the model does not take, sigmas of
/// another count, not finite, negative or beyond 1e3.
struct WorldFromEarth {
  Eigen::Matrix3d R_WE;
  Eigen::Matrix3d covariance;
};
std::optional<WorldFromEarth> WorldFromEarthFromMessage(const kinematic_params_t& msg,
                                                        const kinematics::KinematicModel& model,
                                                        std::string* error);

/// Sensor time [s] of a utime [µs]: the one conversion every filter node and offline reference
/// uses, so that both feed the filter bit-identical times.
inline double SensorSeconds(int64_t utime) {
  return static_cast<double>(utime) * 1e-6;
}

// ---- nodes ------------------------------------------------------------------------------------

/// IMU → OrientationKf → ORIENTATION (one estimate per accepted IMU sample, once initialised),
/// HEALTH at 1 Hz of sensor time.
/// What a filter's counter added since it read `before`: after − before, or all of `after` when
/// the filter started over in between (its counters zeroed by a reset). A node keeps its own
/// totals over its life with it.
inline int64_t CounterAdded(int64_t before, int64_t after) {
  return after >= before ? after - before : after;
}

/// HEALTH's activity for a filter that started its attitude again after `silences` IMU silences
/// longer than max_step [s] (OrientationKfSettings::max_step): "attitude started again from the
/// sensors after N IMU silence(s) longer than X s".
std::string ImuSilencesActivity(int64_t silences, double max_step);

class OrientationKfNode {
 public:
  struct Options {
    std::string name = "orientation_kf";  ///< process name in HEALTH
    int32_t sensor_id = 0;                ///< other IMUs' samples are ignored (not rejected)
    std::string imu_channel = "IMU";
    std::string orientation_channel = "ORIENTATION";
    std::string health_channel = "HEALTH";
    estimation::TimeGateSettings time;  ///< the IMU stream's time gate
    SensorRanges ranges;
  };
  OrientationKfNode(Transport& t, const estimation::OrientationKfSettings& settings,
                    Options options);
  OrientationKfNode(Transport& t, const estimation::OrientationKfSettings& settings)
      : OrientationKfNode(t, settings, Options{}) {}

  /// Publishes one HEALTH with utime 0 (outside the 1 Hz schedule) so listeners know the process
  /// is up before any sample came.
  void Announce();
  /// Publishes the final HEALTH (on a clean stop): the counts up to the end.
  void Finish() { health_.Final(t_, o_.health_channel); }
  /// Handles one IMU message (what the subscription calls; public for tests).
  void OnImu(const imu_sample_t& msg);
  /// Handles bytes on the IMU channel that did not decode.
  void OnUndecodable(const std::string& reason);

  const estimation::OrientationKf& filter() const { return kf_; }
  const Health& health() const { return health_; }

 private:
  void Reject(const std::string& reason);
  void Beat();
  Transport& t_;
  Options o_;
  estimation::OrientationKf kf_;
  Health health_;
  estimation::TimeGate gate_;
  // IMU silences the filter started again after (OrientationKfSettings::max_step) over the
  // node's life: the filter's own count starts over with it (a restarted driver).
  int64_t silences_ = 0;
};

/// The host's steady (monotonic) clock [µs]: only to tell a stopped stream from a late one.
int64_t SteadyNowUs();

/// What the nodes that merge several streams (PositionKfNode, AidedInsNode) share: HEALTH, whose
/// heartbeat after a refusal follows the latest sensor time any stream has reached, the refusals
/// (counted, with the reason naming the field) and each stream's time gate.
class MergingNode {
 public:
  /// As OrientationKfNode::Announce().
  void Announce();
  /// As OrientationKfNode::Finish().
  void Finish() { health_.Final(t_, health_channel_); }
  /// Bytes on a subscribed channel that did not decode: received, rejected.
  void OnUndecodable(const std::string& reason);
  const Health& health() const { return health_; }

 protected:
  MergingNode(Transport& t, const std::string& name, std::string health_channel);
  ~MergingNode() = default;
  void Reject(const std::string& reason);
  // Offers utime to `gate`; false when refused. On a re-synchronisation the node starts over.
  bool Admit(estimation::TimeGate& gate, int64_t utime, const char* field);
  // One stream's time base moved: the queued samples and the filters belong to the old one.
  virtual void StartOver() = 0;
  Transport& t_;
  Health health_;
  std::string health_channel_;
  int64_t latest_ = 0;  // the latest sensor time any stream reached [µs]
};

/// IMU + ORIENTATION + POSITION → PositionKf → TOOL_POSITION, HEALTH at 1 Hz of sensor time.
///
/// The accelerometer of IMU sample k needs the orientation estimate at the same utime, which
/// arrives later from orientation_kf: accelerometer samples wait until their ORIENTATION comes
/// (matched by utime; an accelerometer sample whose orientation never comes is dropped when a
/// later orientation arrives; an orientation that overtakes its IMU sample, which two senders
/// cannot rule out, waits for it). Position samples wait until both the IMU and the orientation
/// stream have reached their utime, so updates are applied in sensor-time order, accelerometer
/// before position at equal utime, whatever order the messages arrive in and at whatever speed.
/// Without orientations (none yet, or none for `orientation_timeout_us` of the host's steady clock:
/// an orientation_kf that stopped) positions go in once the IMU stream is `orientation_wait_us`
/// past them. The wall-clock condition is what tells a stopped orientation stream from one
/// that is merely behind a burst of sensor samples (a driver or a replay catching up after a
/// stall: 1.5 s of a 4x replay sent at once moved the IMU stream 6 s ahead of the orientations,
/// and 118 accelerometer updates were lost when the fallback took sensor time alone). A position
/// sample that comes after a later update was applied is rejected as out of order. The position
/// sensor frame is taken as the orientation's earth frame (the filter's convention). Each
/// accelerometer update gets ω_B = its gyro sample less the paired orientation's gyro bias (the
/// lever arm's rotational terms; an orientation with a non-finite bias is refused). One
/// TOOL_POSITION per applied update, once initialised.
class PositionKfNode : public MergingNode {
 public:
  struct Options {
    std::string name = "position_kf";
    int32_t sensor_id = 0;
    int32_t marker_id = 0;                    ///< other markers' samples are ignored (not rejected)
    int64_t orientation_wait_us = 1'000'000;  ///< IMU sensor time before the fallback [µs]
    /// Host steady-clock time without an ORIENTATION before the stream counts as stopped [µs].
    int64_t orientation_timeout_us = 1'000'000;
    /// The host's steady clock [µs] (tests inject one).
    std::function<int64_t()> steady_now_us = SteadyNowUs;
    size_t max_pending = 10'000;  ///< pending accelerometer samples kept at most
    std::string imu_channel = "IMU";
    std::string orientation_channel = "ORIENTATION";
    std::string position_channel = "POSITION";
    std::string tool_position_channel = "TOOL_POSITION";
    std::string health_channel = "HEALTH";
    std::string kinematic_params_channel = "KINEMATIC_PARAMS";
    estimation::TimeGateSettings time;  ///< each stream's time gate (IMU, ORIENTATION, POSITION)
    SensorRanges ranges;
    /// The position sensor's frame against the IMU's earth frame, R_WE (world ← earth), until
    /// the identifier's first estimate (a cell's earth_from_world given as a prior; identity:
    /// W = E, the paper's). A rotation: the constructor throws std::invalid_argument otherwise.
    Eigen::Matrix3d world_from_earth = Eigen::Matrix3d::Identity();
    /// The covariance [rad²] of world_from_earth's error (PositionKf::SetWorldFromEarth): zero
    /// when known, large (1 rad² per axis) when W = E is only a stand-in for a guessed frame.
    Eigen::Matrix3d world_from_earth_covariance = Eigen::Matrix3d::Zero();
    /// The cell's model. With an earth frame, R_WE follows the identifier's estimate of it
    /// (KINEMATIC_PARAMS of this model: R_WE = R_EW(x)ᵀ, its covariance from the message's
    /// sigmas by KinematicModel::WorldFromEarthCovariance); another model's estimates are ignored
    /// (counted in ignored_params()). Null: R_WE stays world_from_earth.
    std::shared_ptr<const kinematics::KinematicModel> model;
  };
  /// A bank of motion models (estimation::PositionKfBank): TOOL_POSITION is their mixture.
  PositionKfNode(Transport& t, const estimation::PositionKfBankSettings& settings, Options options);
  /// One filter (a bank of one: its estimates unchanged).
  PositionKfNode(Transport& t, const estimation::PositionKfSettings& settings, Options options)
      : PositionKfNode(t, estimation::PositionKfBankSettings{{settings}}, std::move(options)) {}
  PositionKfNode(Transport& t, const estimation::PositionKfSettings& settings)
      : PositionKfNode(t, settings, Options{}) {}

  void OnImu(const imu_sample_t& msg);
  void OnOrientation(const orientation_estimate_t& msg);
  void OnPosition(const position_sample_t& msg);
  /// The identifier's estimate: R_WE from its earth frame, from the next accelerometer sample on.
  /// HEALTH's activity says where R_WE comes from: "R_WE: fixed" (no model with an earth frame),
  /// "R_WE: the cell's, awaiting the identifier's", then "R_WE: the identifier's (N estimates)".
  void OnKinematicParams(const kinematic_params_t& msg);

  /// The models' filters and their weights.
  const estimation::PositionKfBank& bank() const { return kf_; }
  /// The first model's filter (the only one when built from one PositionKfSettings).
  const estimation::PositionKf& filter() const { return kf_.filters().front(); }
  /// KINEMATIC_PARAMS R_WE was taken from, and those of another model (ignored).
  int64_t world_from_earth_updates() const { return world_from_earth_updates_; }
  int64_t ignored_params() const { return ignored_params_; }
  /// Accelerometer samples dropped because their orientation never came.
  int64_t unpaired_accel() const { return unpaired_accel_; }

 private:
  void Flush(int64_t watermark);
  // Sensor time up to which every accelerometer sample is settled (paired with its orientation,
  // or known never to get one): both streams have reached it. INT64_MIN before both have begun.
  int64_t PairedUpTo() const;
  // Sensor time up to which positions may go in without their orientation: the IMU stream less
  // orientation_wait_us while the orientation stream is stopped, else none.
  int64_t ImuWatermark() const;
  void Applied(int64_t utime);
  void StartOver() override;
  void FilterFailed(const std::string& reason, int64_t resets_before);
  // HEALTH's activity: where R_WE comes from and, once there are any, the positions each of the
  // bank's filters refused by its χ² gate and the times it re-initialised.
  void SayActivity();
  Options o_;
  estimation::PositionKfBank kf_;
  std::string frame_activity_;  // where R_WE comes from
  // Per filter of the bank: positions refused by its gate and its re-initialisations over the
  // node's life (a filter's own counters start again at each of its resets).
  std::vector<std::array<int64_t, 2>> position_totals_;
  // The filters' own counts read before each position update (a buffer: no allocation per sample).
  std::vector<std::array<int64_t, 2>> position_counts_before_;
  std::optional<int64_t> last_imu_, last_orientation_, last_position_, last_applied_;
  std::optional<int64_t> last_orientation_arrival_us_;  // host steady clock [µs]
  // An IMU sample as the position filter uses it: specific force [m/s²] and rate [rad/s], body.
  struct AccelSample {
    Eigen::Vector3d f_B, gyro_B;
  };
  // An orientation estimate as it uses it: R_EB and the gyro bias [rad/s] (ω_B = gyro − bias,
  // for the lever arm's rotational terms).
  struct Attitude {
    Eigen::Matrix3d R_EB;
    Eigen::Vector3d bias_B;
  };
  std::map<int64_t, AccelSample> pending_accel_;   // utime → sample waiting for its orientation
  std::map<int64_t, Attitude> early_orientation_;  // utime → orientation ahead of its IMU sample
  // Ready accelerometer updates (with their orientation) and waiting position samples.
  std::multimap<int64_t, std::pair<AccelSample, Attitude>> ready_accel_;
  std::multimap<int64_t, Eigen::Vector3d> pending_position_;
  int64_t unpaired_accel_ = 0;
  int64_t world_from_earth_updates_ = 0, ignored_params_ = 0;
  estimation::TimeGate imu_gate_, orientation_gate_, position_gate_;
};

}  // namespace rcal::transport
