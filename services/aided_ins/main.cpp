// aided_ins: IMU + POSITION → the tracker-aided INS (rcal::estimation::AidedIns, with an
// rcal::estimation::OrientationKf as its heading source) → INS_ORIENTATION (q_EI, the attitude
// covariance, the gyro bias) after every IMU sample it integrates and INS_TOOL_POSITION (the
// marker's position and velocity in the tracker's frame, with their covariance) after every
// update, HEALTH at 1 Hz of sensor time. The node (stream ordering, message checks, conversions)
// is rcal::transport::AidedInsNode: the filters run on sensor time, each tracker sample taken at
// its own stamp within the IMU step that covers it, so a replay at any speed, in any arrival
// order, gives the same estimates, and `rcal fuse`'s INS on the same recording.
//
// Why beside orientation_kf: the tracker's positions make the accelerometer a gravity sensor in
// any motion (estimation/aided_ins.hpp); on BROAD the INS's attitude is 0.48× VQF's error held out
// against the IMU-only filter's 0.94× (README). The settings are the ones `rcal fuse-loo --ins`
// chose (magnetometer heading σ 0.6 rad, accelerometer noise 0.02 m/s²/√Hz, and the library's
// default shock hypothesis κ = 2, a tap taken as the accelerometer's); the cell gives the
// earth frame, gravity, ranges, the tracker's σ and frame, the accelerometer's lag, the lever arm
// to start from (learned from there) and the channels.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/services/aided_ins_defaults.hpp"
#include "rcal/services/cell_imu.hpp"
#include "rcal/services/common.hpp"
#include "rcal/services/time_options.hpp"
#include "rcal/transport/aided_ins_node.hpp"
#include "rcal/transport/lcm_transport.hpp"

int main(int argc, char** argv) {
  using namespace rcal;
  std::string lcm_url, earth = "ned";
  transport::AidedInsNode::Options options;
  estimation::OrientationKfSettings orientation;
  // `rcal fuse-loo --ins`'s choice on BROAD (aided_ins_defaults.hpp), unless the command line says.
  estimation::AidedInsSettings ins = services::AidedInsProcessDefaults();
  CLI::App app{
      "aided_ins: the tracker-aided INS on the IMU and the position sensor.\n"
      "Subscribes IMU, POSITION (and KINEMATIC_PARAMS for a guessed tracker frame); publishes\n"
      "INS_ORIENTATION, INS_TOOL_POSITION and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--earth", earth, "earth frame (the attitude's): ned or enu")
      ->check(CLI::IsMember({"ned", "enu"}))
      ->capture_default_str();
  app.add_option("--gravity", ins.gravity, "local gravity [m/s²]")->capture_default_str();
  app.add_option("--position-sigma", ins.position_sigma, "position sensor σ per axis [m]")
      ->check(CLI::Range(1e-6, 1.0))
      ->capture_default_str();
  app.add_option("--mag-heading-sigma", ins.mag_heading_sigma,
                 "σ of one magnetometer heading [rad] (rcal fuse-loo --ins chose 0.6 on BROAD)")
      ->check(CLI::Range(1e-4, 10.0))
      ->capture_default_str();
  app.add_option("--accel-noise", ins.accel_noise_density,
                 "accelerometer noise density with what the model leaves out [m/s²/√Hz] (rcal "
                 "fuse-loo --ins chose 0.02 on BROAD)")
      ->check(CLI::Range(1e-6, 100.0))
      ->capture_default_str();
  app.add_option("--accel-noise-adaptation-tau", ins.accel_noise_adaptation_tau,
                 "time constant of the accelerometer noise's adaptation to the position "
                 "innovations [s] (0: off; rcal fuse-loo --ins chose 3 on BROAD)")
      ->check(CLI::Range(0.0, 1e4))
      ->capture_default_str();
  app.add_option(
         "--accel-shock-sigma", ins.accel_shock_sigma,
         "κ of the accelerometer-shock hypothesis a gated position is tried under: a step's "
         "integral uncertain by κ times the force's change across it [-] (0: off; rcal "
         "fuse-loo --ins chose 2 on BROAD)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--accel-change-sigma", ins.accel_change_sigma,
                 "the accelerometer weighted by motion: a step's integral uncertain by this "
                 "fraction of the force's change across it, at every step [-] (0: off; rcal "
                 "fuse-loo --ins chose 0.1 on BROAD)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  app.add_option("--accel-delay", ins.accel_delay,
                 "the accelerometer's lag behind its stamps [s] (rcal fuse measures it); default "
                 "the cell's sensors.imu.accel_delay, else 0")
      ->check(CLI::Range(0.0, estimation::kMaxAccelDelay))
      ->capture_default_str();
  std::vector<double> lever_arm;
  app.add_option("--lever-arm", lever_arm,
                 "IMU → marker lever arm r_B to start from, in the IMU's sample axes [m] (x y z); "
                 "default the cell's sensors.imu.to_marker, else zero; learned from there")
      ->expected(3)
      ->check(CLI::Range(-1.0, 1.0));
  app.add_option("--lever-arm-sigma", ins.lever_arm_sigma,
                 "initial σ per axis of the lever arm [m] (0: known, not learned)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_flag("--heading-from-kf", options.heading_from_kf,
               "take the orientation KF's heading instead of the field its heading row accepted, "
               "levelled with the INS's own tilt");
  double position_wait = 0.25, position_timeout = 1.0;
  app.add_option("--position-wait", position_wait,
                 "IMU sensor time a sample waits for a stopped tracker [s]")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  app.add_option("--position-timeout", position_timeout,
                 "host time without a position before the tracker counts as stopped and the IMU "
                 "goes in without it (after --position-wait of IMU time) [s]")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  app.add_option("--sensor-id", options.sensor_id, "IMU to follow")->capture_default_str();
  app.add_option("--marker-id", options.marker_id, "marker to follow")->capture_default_str();
  services::AddTimeGateOptions(app, &options.time, "sample");
  app.add_option("--name", options.name, "process name in HEALTH")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  std::string cell_path;
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): the IMU's earth frame, gravity, ranges, lag and "
                 "lever arm, the position sensor's σ (its largest per axis), first marker and "
                 "frame, the channels; --earth, --gravity, --position-sigma, --accel-delay, "
                 "--lever-arm and --marker-id, when given, override it");
  CLI11_PARSE(app, argc, argv);
  options.position_wait_us = static_cast<int64_t>(position_wait * 1e6);
  options.position_timeout_us = static_cast<int64_t>(position_timeout * 1e6);
  ins.earth = earth == "enu" ? estimation::EarthFrame::kEnu : estimation::EarthFrame::kNed;
  std::string frame = "the identity (no cell)";
  try {
    if (!cell_path.empty()) {
      const io::BuiltCell built = io::LoadCell(services::RepoPath(cell_path));
      const io::CellSpec& cell = built.spec;
      services::ApplyCellImu(cell, app, "aided_ins", &ins.earth, &earth, &ins.gravity,
                             &options.ranges);
      if (app.count("--position-sigma") == 0) ins.position_sigma = cell.position.sigma.maxCoeff();
      if (app.count("--accel-delay") == 0) ins.accel_delay = cell.imu->accel_delay;
      ins.max_step = estimation::MaxStepForRate(cell.imu->rate);  // a slow IMU is not silent
      if (app.count("--marker-id") == 0) options.marker_id = cell.position.markers.front();
      // The cell's lever arm is to its first marker, in the IMU's mounting frame; the filter works
      // in the axes the samples come in (r_B = R_ISᵀ r_I).
      if (options.marker_id == cell.position.markers.front())
        ins.lever_arm_B = cell.imu->R_IS.transpose() * cell.imu->to_marker_I;
      options.imu_channel = cell.channels.imu;
      options.position_channel = cell.channels.position;
      options.orientation_channel = cell.channels.ins_orientation;
      options.tool_position_channel = cell.channels.ins_tool_position;
      options.health_channel = cell.channels.health;
      options.kinematic_params_channel = cell.channels.kinematic_params;
      if (built.model.has_earth()) {
        options.model = std::make_shared<const kinematics::KinematicModel>(built.model);
        if (cell.frames.earth_from_world &&
            cell.frames.earth_from_world->mode == io::SetupMode::kGuess) {
          options.world_from_earth_known = false;
          frame = "the identifier's first estimate (earth_from_world: guess), learned from there";
        } else {
          options.world_from_earth = built.model.EarthFromWorld(built.model.Nominal()).transpose();
          options.world_from_earth_covariance =
              built.model.WorldFromEarthCovariance(built.model.Nominal(), built.PriorSigma());
          frame = options.world_from_earth_covariance.isZero()
                      ? "the cell's earth_from_world, fixed"
                      : "the cell's earth_from_world, a prior, learned";
        }
      }
    }
    orientation.earth = ins.earth;
    orientation.gravity = ins.gravity;
    orientation.max_step = ins.max_step;
    orientation.gyro_range = options.ranges.gyro;
    orientation.accel_range = options.ranges.accel;
    ins.gyro_range = options.ranges.gyro;
    ins.accel_range = options.ranges.accel;
    if (!lever_arm.empty())
      ins.lever_arm_B = Eigen::Vector3d(lever_arm[0], lever_arm[1], lever_arm[2]);
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    transport::AidedInsNode node(t, orientation, ins, options);
    node.Announce();
    spdlog::info(
        "aided_ins on {} (earth {}, tracker σ {} m, frame: {}; lever arm r_B [{}, {}, {}] m ± {} "
        "m, accelerometer lag {} s, magnetometer heading σ {} rad, accelerometer noise {} "
        "m/s²/√Hz, weighted by motion {}, shock hypothesis κ {}) → {}, {}",
        t.url(), earth, ins.position_sigma, frame, ins.lever_arm_B.x(), ins.lever_arm_B.y(),
        ins.lever_arm_B.z(), ins.lever_arm_sigma, ins.accel_delay, ins.mag_heading_sigma,
        ins.accel_noise_density, ins.accel_change_sigma, ins.accel_shock_sigma,
        options.orientation_channel, options.tool_position_channel);
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    node.Finish();
    const auto& h = node.health();
    const auto& c = node.ins().counters();
    spdlog::info("stopped: received {}, rejected {}, published {}", h.received(), h.rejected(),
                 h.published());
    spdlog::info(
        "INS: {} IMU steps, positions applied {} (of them {} as the accelerometer's shock), "
        "refused by the χ² gate {}, taken after the gate {}, magnetometer headings {}, "
        "re-initialised {}, resets {}; {} positions unused awaiting the tracker's frame",
        c.imu_samples, c.positions, c.shocks_taken, c.position_rejected, c.reanchored,
        c.mag_headings, c.reinitialised, c.resets, node.positions_awaiting_frame());
    if (node.ins().initialized()) {
      const Eigen::Vector3d r = node.ins().state().r_BM_B;
      const Eigen::Vector3d rpy_EW = geometry::ToRpy(node.ins().R_WE().transpose());
      spdlog::info(
          "lever arm r_B (IMU → marker, IMU axes) [{:.4f}, {:.4f}, {:.4f}] m; R_EW (earth ← "
          "tracker) rpy [{:.4f}, {:.4f}, {:.4f}] rad",
          r.x(), r.y(), r.z(), rpy_EW.x(), rpy_EW.y(), rpy_EW.z());
    }
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
