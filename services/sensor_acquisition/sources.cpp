#include "sources.hpp"

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/io/pose_dataset.hpp"
#include "rcal/transport/adapters.hpp"

namespace rcal::sensors {

int64_t Utime(const SensorEvent& e) {
  return std::visit([](const auto& s) -> int64_t { return s.utime; }, e);
}

RawCsvReplaySource::RawCsvReplaySource(const std::string& path,
                                       const RawCsvReplaySettings& settings)
    : path_(path) {
  const io::CsvTable table = io::CsvTable::Load(path);
  const Eigen::VectorXd t = table.Column("t_s");
  const char* imu_columns[9] = {"gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y",
                                "acc_z", "mag_x", "mag_y", "mag_z"};
  std::vector<Eigen::VectorXd> imu;
  for (const char* c : imu_columns) imu.push_back(table.Column(c));
  const bool has_pos = table.Has("pos_x") && table.Has("pos_y") && table.Has("pos_z");
  Eigen::VectorXd px, py, pz;
  if (has_pos) {
    px = table.Column("pos_x");
    py = table.Column("pos_y");
    pz = table.Column("pos_z");
  }
  const int rows = settings.max_rows > 0
                       ? static_cast<int>(std::min<int64_t>(settings.max_rows, table.rows()))
                       : table.rows();
  const double period = settings.position_rate > 0 ? 1.0 / settings.position_rate : 0.0;
  double next_pos_t = -std::numeric_limits<double>::infinity();
  const Eigen::Matrix3d cov =
      settings.position_sigma * settings.position_sigma * Eigen::Matrix3d::Identity();
  for (int k = 0; k < rows; ++k) {
    const int64_t utime = std::llround(t(k) * 1e6) + settings.utime_offset;
    transport::ImuSample s;
    s.utime = utime;
    s.sensor_id = settings.sensor_id;
    s.gyro_B = Eigen::Vector3d(imu[0](k), imu[1](k), imu[2](k));
    s.f_B = Eigen::Vector3d(imu[3](k), imu[4](k), imu[5](k));
    s.has_mag = true;
    s.m_B = settings.mag_scale * Eigen::Vector3d(imu[6](k), imu[7](k), imu[8](k));
    events_.push_back(s);
    ++imu_count_;
    if (!has_pos) continue;
    const Eigen::Vector3d p(px(k), py(k), pz(k));
    if (!p.allFinite() || t(k) < next_pos_t - 1e-9) continue;
    next_pos_t = (std::isfinite(next_pos_t) ? next_pos_t : t(k)) + period;
    transport::PositionSample ps;
    ps.utime = utime;
    ps.marker_id = settings.marker_id;
    ps.p = p;
    ps.covariance = cov;
    events_.push_back(ps);
    ++position_count_;
  }
}

std::string RawCsvReplaySource::Describe() const {
  return "raw-stream CSV " + path_ + " (" + std::to_string(imu_count_) + " IMU, " +
         std::to_string(position_count_) + " POSITION samples)";
}

std::optional<SensorEvent> RawCsvReplaySource::Next(int /*timeout_ms*/) {
  if (Finished()) return std::nullopt;
  return events_[next_++];
}

bool IsRawStreamCsv(const std::string& path) {
  const io::CsvTable table = io::CsvTable::Load(path);
  return table.Has("t_s") && table.Has("gyr_x");
}

PoseDatasetReplaySource::PoseDatasetReplaySource(const std::string& path,
                                                 const PoseDatasetReplaySettings& settings)
    : path_(path) {
  const io::PoseDataset data = io::LoadPoseDataset(
      path, settings.model != nullptr ? settings.model->num_joints() : settings.num_joints);
  if (settings.model != nullptr) io::CheckPosesPlausible(data, *settings.model, path);
  std::vector<const io::PoseSample*> rows;
  for (const auto& s : data.samples)
    if (settings.include_test || s.set != io::PoseSample::kTest) rows.push_back(&s);
  bool timed = !rows.empty();
  for (const auto* s : rows) timed = timed && std::isfinite(s->time);
  const double period_us = 1e6 / settings.rate;
  for (size_t k = 0; k < rows.size(); ++k) {
    const io::PoseSample& s = *rows[k];
    const int64_t utime =
        timed ? std::llround(s.time * 1e6)
              : settings.start_utime + static_cast<int64_t>(std::llround(k * period_us));
    kinematics::PoseMeasurement z;
    z.q = s.q;
    z.p_WM_W = s.p_WM_W;
    z.has_orientation = s.has_orientation;
    const int dim = z.dimension();
    z.covariance = Eigen::MatrixXd::Identity(dim, dim);
    z.covariance.topLeftCorner(3, 3) *= settings.position_sigma * settings.position_sigma;
    if (s.has_orientation) {
      const Eigen::Vector4d& w = s.q_EI_wxyz;
      z.R_EI = Eigen::Quaterniond(w(0), w(1), w(2), w(3)).normalized().toRotationMatrix();
      z.covariance.bottomRightCorner(3, 3) *=
          settings.orientation_sigma * settings.orientation_sigma;
    }
    joint_state_t js;
    js.utime = utime;
    js.num_joints = static_cast<int32_t>(s.q.size());
    for (int j = 0; j < s.q.size(); ++j) {
      std::string name = std::to_string(j + 1);
      name.insert(name.begin(), 'q');
      js.names.push_back(name);
    }
    js.q.assign(s.q.data(), s.q.data() + s.q.size());
    js.dq.assign(s.q.size(), 0.0);
    events_.push_back(js);
    events_.push_back(transport::ToMessage(z, utime, static_cast<int32_t>(k), s.marker));
    ++poses_;
  }
}

std::string PoseDatasetReplaySource::Describe() const {
  return "pose dataset " + path_ + " (" + std::to_string(poses_) + " poses)";
}

std::optional<SensorEvent> PoseDatasetReplaySource::Next(int /*timeout_ms*/) {
  if (Finished()) return std::nullopt;
  return events_[next_++];
}

namespace {

constexpr const char* kSimCheckpointSchema = "rcal.sensor_acquisition_checkpoint/1";

const nlohmann::json& Key(const nlohmann::json& j, const std::string& key) {
  if (!j.is_object() || !j.contains(key))
    throw std::runtime_error("sensor_acquisition checkpoint: " + key + ": missing");
  return j.at(key);
}

}  // namespace

std::string SimCheckpointText(const SimCheckpoint& c) {
  const auto& p = c.programme;
  const nlohmann::json j = {{"schema", kSimCheckpointSchema},
                            {"level", p.level},
                            {"seed", p.seed},
                            {"poses", p.poses},
                            {"test_poses", p.test_poses},
                            {"start_utime", p.start_utime},
                            {"rate", p.rate},
                            {"next_tick", c.next_tick},
                            {"next_utime", c.next_utime},
                            {"finished", c.finished}};
  return j.dump() + "\n";
}

SimCheckpoint ParseSimCheckpoint(const std::string& text) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("sensor_acquisition checkpoint: not JSON: ") + e.what());
  }
  if (!j.is_object() || j.value("schema", "") != kSimCheckpointSchema)
    throw std::runtime_error(std::string("sensor_acquisition checkpoint: schema: expected ") +
                             kSimCheckpointSchema);
  SimCheckpoint c;
  std::string key;
  try {
    auto get = [&](const char* k) -> const nlohmann::json& {
      key = k;
      return Key(j, k);
    };
    c.programme.level = get("level").get<std::string>();
    c.programme.seed = get("seed").get<uint64_t>();
    c.programme.poses = get("poses").get<int64_t>();
    c.programme.test_poses = get("test_poses").get<int64_t>();
    c.programme.start_utime = get("start_utime").get<int64_t>();
    c.programme.rate = get("rate").get<double>();
    c.next_tick = get("next_tick").get<int64_t>();
    c.next_utime = get("next_utime").get<int64_t>();
    c.finished = get("finished").get<bool>();
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error("sensor_acquisition checkpoint: " + key + ": wrong type (" + e.what() +
                             ")");
  }
  if (c.next_tick < 0)
    throw std::runtime_error("sensor_acquisition checkpoint: next_tick: negative");
  return c;
}

void SaveSimCheckpoint(const std::filesystem::path& path, const SimCheckpoint& c) {
  io::AtomicWriteFile(path, SimCheckpointText(c));
}

std::optional<SimCheckpoint> LoadSimCheckpoint(const std::filesystem::path& path,
                                               const SimProgramme& programme) {
  if (!std::filesystem::exists(path)) return std::nullopt;
  try {
    SimCheckpoint c = ParseSimCheckpoint(io::ReadFile(path));
    const auto& p = c.programme;
    auto differs = [&](const std::string& key, const std::string& has, const std::string& want) {
      throw std::runtime_error("sensor_acquisition checkpoint: " + key + ": " + has +
                               " is not this programme's " + want +
                               " (remove the file to start the programme afresh)");
    };
    if (p.level != programme.level) differs("level", p.level, programme.level);
    if (p.seed != programme.seed)
      differs("seed", std::to_string(p.seed), std::to_string(programme.seed));
    if (p.poses != programme.poses)
      differs("poses", std::to_string(p.poses), std::to_string(programme.poses));
    if (p.test_poses != programme.test_poses)
      differs("test_poses", std::to_string(p.test_poses), std::to_string(programme.test_poses));
    if (p.start_utime != programme.start_utime)
      differs("start_utime", std::to_string(p.start_utime), std::to_string(programme.start_utime));
    if (p.rate != programme.rate)
      differs("rate", std::to_string(p.rate), std::to_string(programme.rate));
    return c;
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(path.string() + ": " + e.what());
  }
}

}  // namespace rcal::sensors
