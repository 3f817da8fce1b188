// orientation_kf: IMU → rcal::estimation::OrientationKf → ORIENTATION (q_EI, attitude covariance,
// gyro bias) after every accepted sample, HEALTH at 1 Hz of sensor time. The filter runs on the
// samples' utime, so a replay at any speed gives the same estimates. Bad samples (undecodable,
// NaN, no magnetometer, duplicate or out-of-order utime) are rejected and counted in HEALTH.
// The node (message checks, conversions) is rcal::transport::OrientationKfNode.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>

#include "rcal/services/common.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_transport.hpp"

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
  app.add_option("--name", options.name, "process name in HEALTH")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  CLI11_PARSE(app, argc, argv);
  settings.earth = earth == "enu" ? estimation::EarthFrame::kEnu : estimation::EarthFrame::kNed;

  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    transport::OrientationKfNode node(t, settings, options);
    node.Announce();
    spdlog::info("orientation_kf on {} (earth {})", t.url(), earth);
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    const auto& h = node.health();
    spdlog::info("stopped: received {}, rejected {}, published {}", h.received(), h.rejected(),
                 h.published());
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
