// rcal accel-lag LOG: the accelerometer's lag behind its stamps, measured from a recorded run
// (lcm-logger, the logger service) of a real cell: its IMU samples, the orientation KF's estimates
// paired with them (ORIENTATION carries the IMU sample's utime) and the position sensor's samples
// of the tool's marker, through estimation::EstimateAccelLag (accel_lag.hpp). Prints the figure
// and the cell line that takes it out (sensors.imu.accel_delay, read by position_kf). Every
// event is decoded against its schema and checked as the filter nodes check it; what is refused
// is counted, and a lossy log is refused unless --allow-gaps. Where the cell does not fix the
// position sensor's frame (no cell, or earth_from_world only guessed), the estimator finds it too
// (AccelLagSettings::estimate_R_WE) and prints it.
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "accel_lag_json.hpp"
#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/estimation/accel_lag.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/lcm_log.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_schema.hpp"

namespace rcal::tool {
namespace {

namespace est = rcal::estimation;

struct AccelLagOptions {
  std::string log, cell, json;
  std::string imu_channel = transport::channels::kImu;
  std::string orientation_channel = transport::channels::kOrientation;
  std::string position_channel = transport::channels::kPosition;
  int marker_id = -1;  // -1: the cell's first marker, else 0
  int sensor_id = 0;   // the tool's IMU (others' samples are ignored, as orientation_kf does)
  std::string earth;   // ned | enu; empty: the cell's, else ned
  bool allow_gaps = false;
  double position_step =
      0.05;  // [s] each triplet's outer samples at least this far (accel_lag.hpp)
};

// Events of one channel: how many, how many refused, the first reason.
struct ChannelCount {
  long events = 0, refused = 0;
  std::string first;
  void Refuse(io::LcmLogReader& log, const io::LcmLogEvent& e, const std::string& why,
              bool undecodable) {
    if (undecodable) log.Skip(e, why);
    if (refused++ == 0) first = why;
  }
};

int RunAccelLag(const AccelLagOptions& o) {
  est::AccelLagSettings settings;
  settings.min_position_step = o.position_step;
  settings.estimate_R_WE = true;  // unless the cell fixes the frame (below)
  int marker_id = o.marker_id < 0 ? 0 : o.marker_id;
  std::string imu = o.imu_channel, orientation = o.orientation_channel,
              position = o.position_channel;
  std::string frame = "estimated (no cell)";
  if (!o.cell.empty()) {
    const io::BuiltCell built = io::LoadCell(ResolvePath(o.cell));
    const io::CellSpec& cell = built.spec;
    if (!cell.imu) throw std::runtime_error("accel-lag: the cell " + o.cell + " has no IMU");
    settings.earth = cell.imu->earth;
    settings.gravity = cell.imu->gravity;
    if (o.marker_id < 0) marker_id = cell.position.markers.front();
    imu = cell.channels.imu;
    orientation = cell.channels.orientation;
    position = cell.channels.position;
    const bool guessed =
        cell.frames.earth_from_world && cell.frames.earth_from_world->mode == io::SetupMode::kGuess;
    if (built.model.has_earth() && !guessed) {
      settings.R_WE = built.model.EarthFromWorld(built.model.Nominal()).transpose();
      settings.estimate_R_WE = false;
      frame = "the cell's earth_from_world";
    } else {
      frame = "estimated (the cell does not fix earth_from_world)";
    }
  }
  if (!o.earth.empty())
    settings.earth = o.earth == "enu" ? est::EarthFrame::kEnu : est::EarthFrame::kNed;

  io::LcmLogReader log(ResolvePath(o.log));  // throws naming the file
  std::map<int64_t, transport::ImuSample> imu_at;
  std::map<int64_t, std::pair<Eigen::Matrix3d, Eigen::Vector3d>> attitude_at;  // R_EB, bias
  std::map<int64_t, Eigen::Vector3d> p_at;
  ChannelCount n_imu, n_att, n_pos;
  while (const auto e = log.Next()) {
    std::string why;
    if (e->channel == imu) {
      ++n_imu.events;
      imu_sample_t m{};
      if (why = transport::DecodeLcm(e->data.data(), e->data.size(), &m); !why.empty()) {
        n_imu.Refuse(log, *e, "does not decode as imu_sample_t: " + why, true);
      } else if (const auto s = transport::ImuFromMessage(m, &why); !s) {
        n_imu.Refuse(log, *e, why, false);
      } else if (s->sensor_id == o.sensor_id && !imu_at.emplace(s->utime, *s).second) {
        n_imu.Refuse(log, *e, "imu_sample.utime " + std::to_string(s->utime) + " repeated", false);
      }
    } else if (e->channel == orientation) {
      ++n_att.events;
      orientation_estimate_t m{};
      if (why = transport::DecodeLcm(e->data.data(), e->data.size(), &m); !why.empty()) {
        n_att.Refuse(log, *e, "does not decode as orientation_estimate_t: " + why, true);
      } else if (const auto R = transport::RotationFromMessage(m, &why); !R) {
        n_att.Refuse(log, *e, why, false);
      } else if (const Eigen::Vector3d b(m.gyro_bias[0], m.gyro_bias[1], m.gyro_bias[2]);
                 !b.allFinite()) {
        n_att.Refuse(log, *e, "orientation_estimate.gyro_bias: not finite", false);
      } else {
        attitude_at[m.utime] = {*R, b};  // a republished estimate replaces the earlier one
      }
    } else if (e->channel == position) {
      ++n_pos.events;
      position_sample_t m{};
      if (why = transport::DecodeLcm(e->data.data(), e->data.size(), &m); !why.empty()) {
        n_pos.Refuse(log, *e, "does not decode as position_sample_t: " + why, true);
      } else if (const auto s = transport::PositionFromMessage(m, &why); !s) {
        n_pos.Refuse(log, *e, why, false);
      } else if (s->marker_id == marker_id && !p_at.emplace(s->utime, s->p).second) {
        n_pos.Refuse(log, *e, "position_sample.utime " + std::to_string(s->utime) + " repeated",
                     false);
      }
    }
  }
  CheckLogGaps(o.log, log.stats(), o.allow_gaps);
  for (const auto& [name, c] :
       {std::pair{imu, &n_imu}, std::pair{orientation, &n_att}, std::pair{position, &n_pos}})
    if (c->refused > 0)
      spdlog::warn("{}: {} of {} {} events refused (first: {})", o.log, c->refused, c->events, name,
                   c->first);

  // Each IMU sample with the orientation estimate that followed it (same utime); the rate with
  // that estimate's bias removed, as position_kf feeds its filter.
  est::AccelLagData data;
  long unpaired = 0;
  for (const auto& [utime, s] : imu_at) {
    const auto a = attitude_at.find(utime);
    if (a == attitude_at.end()) {
      ++unpaired;
      continue;
    }
    data.t_imu.push_back(transport::SensorSeconds(utime));
    data.f_B.push_back(s.f_B);
    data.R_EB.push_back(a->second.first);
    data.omega_B.push_back(s.gyro_B - a->second.second);
  }
  for (const auto& [utime, p] : p_at) {
    data.t_position.push_back(transport::SensorSeconds(utime));
    data.p_WM_W.push_back(p);
  }
  std::printf(
      "%s: %zu IMU samples with their orientation (%ld without one), %zu position samples of "
      "marker %d; R_WE: %s\n",
      o.log.c_str(), data.t_imu.size(), unpaired, data.t_position.size(), marker_id, frame.c_str());
  const auto lag = est::EstimateAccelLag(data, settings);
  if (!lag) throw std::runtime_error("accel-lag: " + o.log + ": " + lag.error());
  std::printf(
      "accelerometer lag: %.3f ± %.3f ms (%d position triplets, jerk %.1f m/s³ RMS, residual "
      "%.3f m/s² per axis); lever arm r_B [%.1f, %.1f, %.1f] mm\n"
      "cell: sensors.imu.accel_delay: %.6f\n",
      lag->delay * 1e3, lag->delay_sigma * 1e3, lag->triplets, lag->jerk_rms, lag->residual_rms,
      lag->lever_arm_B.x() * 1e3, lag->lever_arm_B.y() * 1e3, lag->lever_arm_B.z() * 1e3,
      std::max(lag->delay, 0.0));
  const Eigen::Quaterniond q_WE(lag->R_WE);
  if (lag->R_WE_estimated)
    std::printf(
        "position sensor's frame W from the IMU's earth frame E, estimated: q_WE [w, x, y, z] = "
        "[%.5f, %.5f, %.5f, %.5f] (%.2f deg from the identity)\n",
        q_WE.w(), q_WE.x(), q_WE.y(), q_WE.z(),
        Eigen::AngleAxisd(lag->R_WE).angle() * 180.0 / std::numbers::pi);
  if (lag->delay < 0.0 || lag->delay > est::kMaxAccelDelay)
    spdlog::warn(
        "the lag is outside what position_kf takes ([0, {}] s): a lead, or not the sensor's own "
        "lag (a clock offset between the IMU and the position sensor?)",
        est::kMaxAccelDelay);
  if (!o.json.empty()) {
    nlohmann::json j = AccelLagJson(*lag);
    j["log"] = o.log;
    j["imu_samples"] = data.t_imu.size();
    j["imu_without_orientation"] = unpaired;
    j["position_samples"] = data.t_position.size();
    j["marker_id"] = marker_id;
    j["q_WE"] = {q_WE.w(), q_WE.x(), q_WE.y(), q_WE.z()};
    j["R_WE_estimated"] = lag->R_WE_estimated;
    j["min_position_step_s"] = settings.min_position_step;
    j["refused"] = {{imu, n_imu.refused}, {orientation, n_att.refused}, {position, n_pos.refused}};
    io::AtomicWriteFile(o.json, j.dump(2) + "\n");
  }
  return 0;
}

const RegisterCommand kRegisterAccelLag(
    "accel-lag",
    "the accelerometer's lag behind its stamps, from a recorded run's IMU, ORIENTATION and "
    "POSITION events (the cell line that takes it out)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<AccelLagOptions>();
      sub.add_option("log", o->log, "LCM event log (lcm-logger, logger service)")->required();
      sub.add_option("--cell", o->cell,
                     "cell file: the IMU's earth frame and gravity, the channels, the first "
                     "marker and the position sensor's frame (earth_from_world)");
      sub.add_option("--marker-id", o->marker_id, "the tool's marker (default the cell's first)");
      sub.add_option("--sensor-id", o->sensor_id, "the tool's IMU")->capture_default_str();
      sub.add_option("--earth", o->earth, "the IMU's earth frame, ned or enu (default the cell's)")
          ->check(cli::IsMember({"ned", "enu"}));
      sub.add_option("--imu-channel", o->imu_channel, "without --cell")->capture_default_str();
      sub.add_option("--orientation-channel", o->orientation_channel, "without --cell")
          ->capture_default_str();
      sub.add_option("--position-channel", o->position_channel, "without --cell")
          ->capture_default_str();
      sub.add_option("--json", o->json, "write the figures (SI) to this file");
      sub.add_option("--position-step", o->position_step,
                     "each position triplet's outer samples at least this far from its middle "
                     "one [s] (a fast tracker's neighbours are mostly noise); 0: the neighbours")
          ->check(cli::Range(0.0, 1.0))
          ->capture_default_str();
      sub.add_flag("--allow-gaps", o->allow_gaps,
                   "go on when the log lost events or bytes (warned, not refused)");
      return [o] { return RunAccelLag(*o); };
    });

}  // namespace
}  // namespace rcal::tool
