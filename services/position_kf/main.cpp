// position_kf: IMU + ORIENTATION + POSITION → rcal::estimation::PositionKf → TOOL_POSITION
// (marker position, velocity and their 6×6 covariance) after every applied update, HEALTH at
// 1 Hz of sensor time. Each accelerometer sample is paired with the orientation estimate of the
// same utime; updates are applied in sensor-time order (rcal::transport::PositionKfNode), so a
// replay at any speed gives the same estimates. Bad samples are rejected and counted in HEALTH.
// The IMU → marker lever arm (cell sensors.imu.to_marker, --lever-arm, --estimate-lever-arm) gets
// ω_B = gyro − the paired orientation's gyro bias; an estimated lever arm is logged at exit.
// By default a bank of two motion models run side by side, whose mixture is published, each
// weighted by how well it predicts the position samples (estimation::PositionKfBank,
// DefaultBankModels; --bank-evidence-tau): the paper's white-jerk filter and the
// accelerometer-driven one (the accelerometer drives the acceleration state, a world-frame
// acceleration bias takes the orientation's error), both with an accelerometer noise that adapts
// to the position innovations, an accelerometer χ² gate that refuses taps (--accel-gate), and
// each taking back the accelerometer a position sample shows wrong (a tap or shock the gate let
// in; --accel-rollback-span). rcal position-kf-sweep chose it: closer than the paper's filter on
// every one of 96 simulated and real cases (README). --motion-model white-jerk (the paper's
// filter alone) or accelerometer-driven run one model, with the noise options.
// The filter works in the position sensor's frame W: accelerations are turned from the IMU's earth
// frame by R_WE, the cell's earth_from_world (given as a prior or fixed) until the identifier's
// KINEMATIC_PARAMS of the cell's model say where it found that frame (a guessed earth frame: the
// identity until then, as without a cell).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/services/cell_imu.hpp"
#include "rcal/services/common.hpp"
#include "rcal/services/time_options.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_transport.hpp"

int main(int argc, char** argv) {
  using namespace rcal;
  std::string lcm_url, earth = "ned";
  double orientation_wait = 1.0;
  transport::PositionKfNode::Options options;
  // The bank by default (header comment). --motion-model accelerometer-driven takes
  // estimation::AccelerometerDrivenSettings() (its σ and bias walk unless given); white-jerk the
  // paper's filter, with the settings' defaults unless given.
  estimation::PositionKfSettings settings;
  std::string motion_model = "bank";
  CLI::App app{
      "position_kf: the position Kalman filter on the position sensor and the accelerometer.\n"
      "Subscribes IMU, ORIENTATION, POSITION; publishes TOOL_POSITION and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--earth", earth, "earth frame (the orientation estimate's): ned or enu")
      ->check(CLI::IsMember({"ned", "enu"}))
      ->capture_default_str();
  app.add_option("--gravity", settings.gravity, "local gravity [m/s²]")->capture_default_str();
  app.add_option("--position-sigma", settings.position_sigma, "position sensor σ per axis [m]")
      ->capture_default_str();
  app.add_option("--accel-sigma", settings.accel_sigma,
                 "σ of one world-frame acceleration [m/s²] (the accelerometer's noise and the "
                 "orientation's error that the bias state does not take)")
      ->check(CLI::Range(1e-6, 100.0))
      ->capture_default_str();
  app.add_option(
         "--motion-model", motion_model,
         "bank (the two models below side by side, each with its adaptive accelerometer "
         "noise, their estimates weighted by how well each predicts the positions; the motion "
         "noise options do not apply), or one model: where the jerk noise enters, white-jerk "
         "(the paper's Eq. 30) or accelerometer-driven (the acceleration alone: position and "
         "velocity integrate the accelerometer, with an acceleration bias state; --accel-sigma "
         "and --accel-bias-walk default to 0.1 then)")
      ->check(CLI::IsMember({"accelerometer-driven", "white-jerk", "bank"}))
      ->capture_default_str();
  app.add_option("--accel-bias-walk", settings.accel_bias_walk,
                 "random walk of the world-frame acceleration bias state (the orientation's error "
                 "times g, the accelerometer's bias) [m/s²/√s]; 0 = no bias state")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--jerk-noise", settings.jerk_noise,
                 "white-jerk PSD of the marker's motion model [m/s³/√Hz] (the paper's w′: how "
                 "fast the tool's acceleration may change; lower trusts the accelerometer between "
                 "position samples more)")
      ->check(CLI::Range(1e-3, 1e4))
      ->capture_default_str();
  app.add_option("--accel-relative-sigma", settings.accel_relative_sigma,
                 "the accelerometer's error that grows with the tool's acceleration, relative "
                 "[-] (σ_rel |a| joins --accel-sigma in quadrature: an orientation error turns "
                 "the acceleration, a scale error scales it); accelerometer-driven defaults to "
                 "its chosen value")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--accel-noise-adaptation", settings.accel_noise_adaptation_tau,
                 "time constant of the accelerometer noise's adaptation to the position "
                 "innovations [s] (a factor on the accelerometer's variance and the jerk noise "
                 "that keeps the NIS at its dimension); 0 = constant; accelerometer-driven "
                 "defaults to 0.1")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  estimation::PositionKfBankSettings bank;
  app.add_option("--bank-evidence-tau", bank.evidence_tau,
                 "--motion-model bank: how long a position sample's evidence counts in the "
                 "models' weights [s]")
      ->check(CLI::Range(1e-3, 3600.0))
      ->capture_default_str();
  app.add_option("--accel-gate", settings.accel_gate_chi2,
                 "χ² gate on the accelerometer's 3-dof innovation (a tap or shock the motion "
                 "cannot have is refused and counted; 11.34 is the 0.99 quantile, 16.27 the "
                 "0.999 of the positions' gate); 0 = off; default: the bank's 11.34 (rcal "
                 "position-kf-sweep), off for one motion model")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--accel-rollback-span", settings.accel_rollback_span,
                 "how far back a position sample may take back the accelerometer it shows wrong "
                 "(a tap or shock the gate let in) [s]; 0 = off")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  app.add_option("--accel-delay", settings.accel_delay,
                 "the accelerometer's lag behind its stamps [s] (its internal low-pass; rcal fuse "
                 "measures it from a recording, accel_lag in its JSON): each sample is turned to "
                 "its own time's attitude and extrapolated to its stamp; default the cell's "
                 "sensors.imu.accel_delay, else 0 (taken as stamped)")
      ->check(CLI::Range(0.0, estimation::kMaxAccelDelay))
      ->capture_default_str();
  app.add_option("--orientation-wait", orientation_wait,
                 "IMU sensor time a position sample waits for a stopped orientation stream [s]")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  double orientation_timeout = 1.0;
  app.add_option("--orientation-timeout", orientation_timeout,
                 "host time without an orientation before the stream counts as stopped and "
                 "positions go in without it (after --orientation-wait of IMU time) [s]")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  std::vector<double> lever_arm;
  app.add_option("--lever-arm", lever_arm,
                 "IMU → marker lever arm r_B in the IMU's sample axes [m] (x y z); default the "
                 "cell's sensors.imu.to_marker, else zero (the IMU taken at the marker)")
      ->expected(3)
      ->check(CLI::Range(-1.0, 1.0));
  bool estimate_lever_arm = false;
  app.add_flag("--estimate-lever-arm", estimate_lever_arm,
               "estimate the lever arm (three constant states, observed while the tool turns; "
               "starting from --lever-arm or the cell's value)");
  app.add_option("--lever-arm-sigma", settings.lever_arm_sigma,
                 "initial σ per axis of an estimated lever arm [m]")
      ->check(CLI::Range(1e-6, 1.0))
      ->capture_default_str();
  app.add_option("--sensor-id", options.sensor_id, "IMU to follow")->capture_default_str();
  app.add_option("--marker-id", options.marker_id, "marker to follow")->capture_default_str();
  services::AddTimeGateOptions(app, &options.time, "sample");
  app.add_option("--name", options.name, "process name in HEALTH")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  std::string cell_path;
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): the IMU's earth frame, gravity and ranges, the "
                 "position sensor's σ (its largest per axis) and first marker, the channels; "
                 "--earth, --gravity, --position-sigma and --marker-id, when given, override it");
  CLI11_PARSE(app, argc, argv);
  settings.earth = earth == "enu" ? estimation::EarthFrame::kEnu : estimation::EarthFrame::kNed;
  if (motion_model == "accelerometer-driven") {
    const estimation::PositionKfSettings driven = estimation::AccelerometerDrivenSettings();
    settings.motion_model = driven.motion_model;
    if (app.count("--accel-sigma") == 0) settings.accel_sigma = driven.accel_sigma;
    if (app.count("--accel-bias-walk") == 0) settings.accel_bias_walk = driven.accel_bias_walk;
    if (app.count("--accel-relative-sigma") == 0)
      settings.accel_relative_sigma = driven.accel_relative_sigma;
    if (app.count("--accel-noise-adaptation") == 0)
      settings.accel_noise_adaptation_tau = driven.accel_noise_adaptation_tau;
  }
  if (motion_model == "bank") {
    // The bank's models are DefaultBankModels (chosen by rcal position-kf-sweep): a motion noise
    // given here would apply to neither, so it is refused rather than ignored.
    for (const char* o : {"--accel-sigma", "--accel-bias-walk", "--jerk-noise",
                          "--accel-relative-sigma", "--accel-noise-adaptation"})
      if (app.count(o) > 0) {
        spdlog::error(
            "{} sets one motion model's noise: with --motion-model white-jerk or "
            "accelerometer-driven (the bank, the default, runs its own two)",
            o);
        return 2;
      }
  } else if (app.count("--bank-evidence-tau") > 0) {
    spdlog::error("--bank-evidence-tau applies to --motion-model bank only");
    return 2;
  }
  options.orientation_wait_us = static_cast<int64_t>(orientation_wait * 1e6);
  options.orientation_timeout_us = static_cast<int64_t>(orientation_timeout * 1e6);

  try {
    if (!cell_path.empty()) {
      const io::BuiltCell built = io::LoadCell(services::RepoPath(cell_path));
      const io::CellSpec& cell = built.spec;
      services::ApplyCellImu(cell, app, "position_kf", &settings.earth, &earth, &settings.gravity,
                             &options.ranges);
      if (app.count("--position-sigma") == 0)
        settings.position_sigma = cell.position.sigma.maxCoeff();
      if (cell.imu && app.count("--accel-delay") == 0) settings.accel_delay = cell.imu->accel_delay;
      if (app.count("--marker-id") == 0) options.marker_id = cell.position.markers.front();
      // The cell gives the lever arm to its first marker, in the IMU's mounting frame; the filter
      // works in the axes the samples come in (r_B = R_ISᵀ r_I).
      if (cell.imu && options.marker_id == cell.position.markers.front()) {
        settings.lever_arm_B = cell.imu->R_IS.transpose() * cell.imu->to_marker_I;
        settings.estimate_lever_arm = cell.imu->estimate_to_marker;
      } else if (cell.imu && (!cell.imu->to_marker_I.isZero() || cell.imu->estimate_to_marker)) {
        spdlog::warn("sensors.imu.to_marker is the lever arm to marker {}, not {}: taken as zero",
                     cell.position.markers.front(), options.marker_id);
      }
      options.imu_channel = cell.channels.imu;
      options.orientation_channel = cell.channels.orientation;
      options.position_channel = cell.channels.position;
      options.tool_position_channel = cell.channels.tool_position;
      options.health_channel = cell.channels.health;
      options.kinematic_params_channel = cell.channels.kinematic_params;
      if (built.model.has_earth()) {
        options.model = std::make_shared<const kinematics::KinematicModel>(built.model);
        const bool guessed = cell.frames.earth_from_world &&
                             cell.frames.earth_from_world->mode == io::SetupMode::kGuess;
        if (guessed)
          options.world_from_earth_covariance = Eigen::Matrix3d::Identity();  // 1 rad² per axis
        else {
          options.world_from_earth = built.model.EarthFromWorld(built.model.Nominal()).transpose();
          options.world_from_earth_covariance =
              built.model.WorldFromEarthCovariance(built.model.Nominal(), built.PriorSigma());
        }
        spdlog::info(
            "position sensor frame ← IMU earth frame: {}; then the identifier's estimate "
            "({})",
            guessed ? "the identity until the identifier's first estimate (earth_from_world: guess)"
                    : "the cell's earth_from_world",
            options.kinematic_params_channel);
      }
    }
    if (!lever_arm.empty())
      settings.lever_arm_B = Eigen::Vector3d(lever_arm[0], lever_arm[1], lever_arm[2]);
    if (estimate_lever_arm) settings.estimate_lever_arm = true;
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    // One model is a bank of one (its estimates unchanged).
    bank.models = motion_model == "bank" ? estimation::DefaultBankModels(settings)
                                         : std::vector<estimation::PositionKfSettings>{settings};
    // --accel-gate, when given, on every model (the bank's own is kBankAccelGateChi2).
    if (app.count("--accel-gate") > 0)
      for (estimation::PositionKfSettings& m : bank.models)
        m.accel_gate_chi2 = settings.accel_gate_chi2;
    transport::PositionKfNode node(t, bank, options);
    node.Announce();
    spdlog::info(
        "position_kf on {} (earth {}, lever arm r_B [{}, {}, {}] m{}, accelerometer lag "
        "{} s; {} model{})",
        t.url(), earth, settings.lever_arm_B.x(), settings.lever_arm_B.y(),
        settings.lever_arm_B.z(), settings.estimate_lever_arm ? ", estimated" : "",
        settings.accel_delay, motion_model,
        motion_model == "bank" ? fmt::format(", evidence τ {} s", bank.evidence_tau)
                               : std::string());
    for (const estimation::PositionKfSettings& m : bank.models)
      spdlog::info(
          "  {} motion model: acceleration bias walk {} m/s²/√s, σ {} m/s², relative σ {}, "
          "noise adaptation τ {} s, accelerometer gate χ² {}",
          m.motion_model == estimation::MotionModel::kAccelerometerDriven ? "accelerometer-driven"
                                                                          : "white-jerk",
          m.accel_bias_walk, m.accel_sigma, m.accel_relative_sigma, m.accel_noise_adaptation_tau,
          m.accel_gate_chi2 > 0.0 ? fmt::format("{}", m.accel_gate_chi2) : std::string("off"));
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    node.Finish();
    const auto& h = node.health();
    spdlog::info("stopped: received {}, rejected {}, published {}", h.received(), h.rejected(),
                 h.published());
    if (options.model) {
      const Eigen::Vector3d rpy_EW = geometry::ToRpy(node.filter().R_WE().transpose());
      spdlog::info(
          "R_EW (earth ← position sensor frame) rpy [{:.4f}, {:.4f}, {:.4f}] rad, from {} "
          "identifier estimates ({} of another model ignored)",
          rpy_EW.x(), rpy_EW.y(), rpy_EW.z(), node.world_from_earth_updates(),
          node.ignored_params());
    }
    const auto& filters = node.bank().filters();
    for (size_t i = 0; i < filters.size(); ++i) {
      const estimation::PositionKf& f = filters[i];
      const std::string which =
          filters.size() > 1
              ? fmt::format("model {} (weight {:.3f}): ", i + 1, node.bank().probabilities()[i])
              : std::string();
      spdlog::info(
          "{}position samples refused by the χ² gate {}, accelerometer samples {}; accelerometer "
          "taken back {} times ({} samples), refused samples reinstated {} times ({} samples)",
          which, f.counters().position_rejected, f.counters().accel_rejected,
          f.counters().accel_rollbacks, f.counters().accel_rolled_back,
          f.counters().accel_reinstatements, f.counters().accel_reinstated);
      if (bank.models[i].accel_bias_walk > 0.0) {
        const Eigen::Vector3d b_W = f.accel_bias_W();
        spdlog::info(
            "{}acceleration bias b_W (position sensor frame) at exit: [{:.4f}, {:.4f}, {:.4f}] "
            "m/s²",
            which, b_W.x(), b_W.y(), b_W.z());
      }
      if (settings.estimate_lever_arm) {
        const Eigen::Vector3d r_B = f.lever_arm_B();
        const Eigen::Vector3d sigma = f.lever_arm_covariance().diagonal().cwiseSqrt();
        spdlog::info(
            "{}lever arm r_B (IMU → marker, IMU axes) estimated: [{:.4f}, {:.4f}, {:.4f}] m ± "
            "[{:.4f}, {:.4f}, {:.4f}] m",
            which, r_B.x(), r_B.y(), r_B.z(), sigma.x(), sigma.y(), sigma.z());
      }
    }
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
