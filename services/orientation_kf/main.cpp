// orientation_kf: IMU → rcal::estimation::OrientationKf → ORIENTATION (q_EI, attitude covariance,
// gyro bias) after every accepted sample, HEALTH at 1 Hz of sensor time. The filter runs on the
// samples' utime, so a replay at any speed gives the same estimates. Bad samples (undecodable,
// NaN, no magnetometer, duplicate or out-of-order utime) are rejected and counted in HEALTH.
// The node (message checks, conversions) is rcal::transport::OrientationKfNode.
//
// Restarts (--state FILE): the filter learns its magnetic reference (field norm and dip) from its
// first samples, which is only right at rest; a process restarted while the arm moves would learn
// a wrong dip from accelerations, then reject the magnetometer and let heading drift. So the
// learned reference (a property of the site, not of the motion) is written atomically to FILE
// (JSON, schema rcal.orientation_kf_state/1) once learned and whenever it moves, and a restart
// starts from it instead of learning again. The attitude itself is not kept (the arm moved while
// the process was down): a restarted filter (the state file exists) waits until the IMU is at
// rest (|ω| < 0.02 rad/s and | |f| − g | < 0.2 m/s² for --rest-time of sensor time) and starts
// there, as the first start does, instead of initialising on a moving sensor and converging for
// tens of seconds.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <tuple>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/services/cell_imu.hpp"
#include "rcal/services/common.hpp"
#include "rcal/services/time_options.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

constexpr const char* kStateSchema = "rcal.orientation_kf_state/1";

// The magnetic reference of a --state file; throws naming the path and key.
std::pair<double, double> LoadMagReference(const std::string& path) {
  try {
    const auto j = nlohmann::json::parse(rcal::io::ReadFile(path));
    if (!j.is_object() || j.value("schema", "") != kStateSchema)
      throw std::runtime_error(std::string("schema: expected ") + kStateSchema);
    for (const char* key : {"mag_ref_norm", "mag_ref_dip"})
      if (!j.contains(key) || !j.at(key).is_number())
        throw std::runtime_error(std::string(key) + ": missing or not a number");
    const double norm = j.at("mag_ref_norm").get<double>(), dip = j.at("mag_ref_dip").get<double>();
    if (!(norm > 0) || !std::isfinite(norm) || !std::isfinite(dip))
      throw std::runtime_error("mag_ref_norm: not a positive finite number");
    return {norm, dip};
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
}

void SaveMagReference(const std::string& path, double norm, double dip) {
  const nlohmann::json j = {{"schema", kStateSchema}, {"mag_ref_norm", norm}, {"mag_ref_dip", dip}};
  rcal::io::AtomicWriteFile(path, j.dump() + "\n");
}

}  // namespace

int main(int argc, char** argv) {
  using namespace rcal;
  std::string lcm_url, earth = "ned";
  transport::OrientationKfNode::Options options;
  estimation::OrientationKfSettings settings;
  CLI::App app{
      "orientation_kf: the orientation Kalman filter on the IMU stream.\n"
      "Subscribes IMU; publishes ORIENTATION and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--earth", earth, "earth frame of the estimate: ned or enu (BROAD: enu)")
      ->check(CLI::IsMember({"ned", "enu"}))
      ->capture_default_str();
  app.add_option("--gravity", settings.gravity, "local gravity [m/s²]")->capture_default_str();
  app.add_option("--sensor-id", options.sensor_id, "IMU to follow")->capture_default_str();
  services::AddTimeGateOptions(app, &options.time, "sample");
  app.add_option("--name", options.name, "process name in HEALTH")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  std::string state_path;
  double rest_time = 0.3;
  app.add_option("--rest-time", rest_time,
                 "with an existing --state file: sensor time the IMU must be at rest before the "
                 "restarted filter starts [s]")
      ->capture_default_str();
  app.add_option("--state", state_path,
                 "file keeping the learned magnetic reference across restarts (JSON, written "
                 "atomically); a restart starts from it instead of learning it while moving");
  std::string cell_path;
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): the IMU's earth frame, gravity and ranges and "
                 "the channels; --earth and --gravity, when given, override it");
  CLI11_PARSE(app, argc, argv);
  settings.earth = earth == "enu" ? estimation::EarthFrame::kEnu : estimation::EarthFrame::kNed;

  try {
    if (!cell_path.empty()) {
      const io::CellSpec cell = io::LoadCellSpec(services::RepoPath(cell_path));
      services::ApplyCellImu(cell, app, "orientation_kf", &settings.earth, &earth,
                             &settings.gravity, &options.ranges);
      settings.max_step = estimation::MaxStepForRate(cell.imu->rate);  // a slow IMU is not silent
      options.imu_channel = cell.channels.imu;
      options.orientation_channel = cell.channels.orientation;
      options.health_channel = cell.channels.health;
    }
    services::InstallStopHandlers();
    if (!state_path.empty() && std::filesystem::exists(state_path)) {
      std::tie(settings.mag_ref_norm, settings.mag_ref_dip) = LoadMagReference(state_path);
      spdlog::info("{}: magnetic reference norm {:.6g}, dip {:.4f} rad (not learned again)",
                   state_path, settings.mag_ref_norm, settings.mag_ref_dip);
    }
    // Declared before the transport: the rest-wait subscription below stays registered for the
    // process's life, so what it writes must outlive the transport.
    std::optional<int64_t> rest_since;
    bool at_rest = false;
    transport::LcmTransport t(lcm_url);
    if (settings.mag_ref_norm > 0) {
      // A restart: wait for the sensor to be at rest (see the file comment).
      t.Subscribe<imu_sample_t>(options.imu_channel, [&](const imu_sample_t& m) {
        std::string error;
        const auto s = transport::ImuFromMessage(m, &error);
        if (!s) return;
        const bool still = s->gyro_B.norm() < 0.02 &&
                           std::abs(s->f_B.norm() - settings.gravity) < 0.2 &&
                           (!rest_since || s->utime >= *rest_since);
        if (!still) {
          rest_since.reset();
          return;
        }
        if (!rest_since) rest_since = s->utime;
        at_rest |= s->utime - *rest_since >= static_cast<int64_t>(rest_time * 1e6);
      });
      spdlog::info("orientation_kf on {}: restarted, waiting for the IMU to be at rest", t.url());
      while (!at_rest && !services::StopRequested())
        if (t.HandleTimeout(100) < 0) return 1;
      if (services::StopRequested()) return 0;
    }
    transport::OrientationKfNode node(t, settings, options);
    node.Announce();
    spdlog::info("orientation_kf on {} (earth {})", t.url(), earth);
    double saved_norm = settings.mag_ref_norm, saved_dip = settings.mag_ref_dip;
    auto keep_state = [&] {
      const auto& kf = node.filter();
      if (state_path.empty() || !(kf.mag_ref_norm() > 0)) return;
      // Learned, or moved (mag_reference_tau / a new reference) by more than rounding.
      if (std::abs(kf.mag_ref_norm() - saved_norm) <= 1e-6 * kf.mag_ref_norm() &&
          std::abs(kf.mag_ref_dip() - saved_dip) <= 1e-6)
        return;
      SaveMagReference(state_path, kf.mag_ref_norm(), kf.mag_ref_dip());
      saved_norm = kf.mag_ref_norm();
      saved_dip = kf.mag_ref_dip();
      spdlog::info("magnetic reference norm {:.6g}, dip {:.4f} rad saved to {}", saved_norm,
                   saved_dip, state_path);
    };
    if (const int rc = rcal::services::ServeUntilStopped([&](int ms) {
          const int r = t.HandleTimeout(ms);
          keep_state();
          return r;
        });
        rc != 0)
      return rc;
    node.Finish();
    const auto& h = node.health();
    spdlog::info("stopped: received {}, rejected {}, published {}", h.received(), h.rejected(),
                 h.published());
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
