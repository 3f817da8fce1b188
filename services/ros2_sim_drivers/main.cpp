// ros2_sim_drivers: a simulated cell played as its ROS 2 drivers would publish it, over Cyclone DDS
// with the ROS 2 wire types: the arm's sensor_msgs/JointState, the IMU's sensor_msgs/Imu and
// MagneticField, the tracker's geometry_msgs/PointStamped or PoseStamped, on the topics of the
// cell's `ros2:` section (the sim file names the cell). A source of data like sensor_acquisition's
// simulator: for the demo (deploy/demo --ros2) and the tests, never part of a real cell.
//
// The motion is sensor_acquisition's sensor-level programme (the same stops for the same seed);
// each driver runs at its own rate and stamps with its own clock, as real ones do:
//   joints    --joint-rate (125 Hz), the controller's clock: t_joints = --start-utime + t
//   IMU       the cell's IMU rate (libs/sim ImuModel noise), t_imu = t_joints + --imu-offset
//   tracker   --position-rate (default the cell's), σ of the cell, t = t_joints + --position-offset
//   temperature  1 Hz on the controller's (joints') clock, when the cell names a topic: the arm
//             warming with time constant --sim-warmup as sensor_acquisition's controller reports
//             it (cell::SimArmConditions: the same readings for the same seed)
//   payload   1 Hz with the temperature, and as it changes, when the cell names a topic:
//             geometry_msgs/InertiaStamped of what the controller was told the arm carries (none:
//             0 kg; --sim-payloads: one per stop, as sensor_acquisition's, taken on where
//             --sim-payload-at says: move or stop)
// --sim-effect thermal=κ (or thermal:time=ρ), joint_compliance:JOINT=c, joint_periodic,
// joint_scale and backlash, as sensor_acquisition takes them, make the arm grow with its true
// temperature (or time), its joints give way under gravity and the payload or stand off their
// readings: every marker the tracker sees, and the IMU's motion.
// every stamp but the joints' with Gaussian --jitter. Joint names are listed in a shuffled order
// (--shuffle-seed; 0: chain order) with one extra joint of a gripper a driver might add.
// --imu-restart-at T: at sim time T the IMU driver restarts, its clock starting again from
// --start-utime (stamps jump back). Paced by --speed against the wall clock (0: as fast as
// possible); --linger stays up after the programme (under a supervisor).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>
#include <random>
#include <thread>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/dds/dds_common.hpp"
#include "rcal/dds/ros2_convert.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/services/common.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"

namespace {

using namespace rcal;

// What ROS 2 sensor drivers publish with (rclcpp::SensorDataQoS: best effort, keep last 5).
template <typename T>
dds_entity_t Writer(dds_entity_t participant, const std::string& ros_topic) {
  const std::unique_ptr<dds_qos_t, void (*)(dds_qos_t*)> qos(dds::SensorDataQos(5), dds_delete_qos);
  const dds_entity_t w = dds::CreateEndpoint(participant, dds::Descriptor<T>(),
                                             dds::DdsTopicName(ros_topic), qos.get(), true);
  return w;
}

// One timed sample of one driver, ready to publish.
struct Event {
  double t = 0;  // sim time [s]: the publication order
  std::function<void()> publish;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "ros2_sim_drivers: a simulated cell as its ROS 2 drivers (JointState, Imu, MagneticField,\n"
      "PointStamped/PoseStamped, Temperature on the cell's ros2 topics), each driver at its own\n"
      "rate and on its own clock. Cyclone DDS: $CYCLONEDDS_URI, else "
      "config/cyclonedds-loopback.xml."};
  std::string sim_path = "config/cells/grb3016.sim.yaml";
  unsigned seed = 0;
  int poses = 0, test_poses = 50, shuffle_seed = 3;
  double speed = 1.0, joint_rate = 125.0, position_rate = 0.0, imu_offset = 0.037,
         position_offset = -0.120, jitter = 0.0005, imu_restart_at = -1;
  int64_t start_utime = 1'000'000'000;
  int domain = -1;
  bool linger = false;
  app.add_option("--sim", sim_path, "the simulated cell (schema rcal.cell_sim/1)")
      ->capture_default_str();
  app.add_option("--seed", seed, "random seed (default: the sim file's)");
  app.add_option("--poses", poses, "calibration stops (default: the sim file's)");
  app.add_option("--test-poses", test_poses, "test stops drawn after them (not driven to)")
      ->capture_default_str();
  app.add_option("--speed", speed, "sensor time per wall time (0: as fast as possible)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--joint-rate", joint_rate, "JointState rate [Hz]")
      ->check(CLI::Range(1.0, 2000.0))
      ->capture_default_str();
  app.add_option("--position-rate", position_rate, "tracker rate [Hz] (0: the cell's)")
      ->check(CLI::Range(0.0, 2000.0));
  app.add_option("--imu-offset", imu_offset, "IMU clock − joints' clock [s]")
      ->capture_default_str();
  app.add_option("--position-offset", position_offset, "tracker clock − joints' clock [s]")
      ->capture_default_str();
  app.add_option("--jitter", jitter, "σ of the IMU's and tracker's stamp jitter [s]")
      ->check(CLI::Range(0.0, 0.1))
      ->capture_default_str();
  app.add_option("--shuffle-seed", shuffle_seed,
                 "order of the joint names in JointState (0: chain order)")
      ->capture_default_str();
  app.add_option("--imu-restart-at", imu_restart_at,
                 "sim time [s] at which the IMU driver restarts (its clock starts over)");
  app.add_option("--start-utime", start_utime, "the joints' clock at sim time 0 [µs]")
      ->capture_default_str();
  double warmup_s = sim::SessionSettings{}.warmup_time_constant_s;
  app.add_option("--sim-warmup", warmup_s,
                 "time constant [s] of the arm's warm-up (+12 K) the temperature driver reports")
      ->check(CLI::Range(1.0, 1e6))
      ->capture_default_str();
  std::vector<std::string> sim_effects;
  app.add_option("--sim-effect", sim_effects,
                 "a non-geometric effect the simulated arm has, as sensor_acquisition --level "
                 "sensors takes it: thermal growth with its temperature, thermal=KAPPA [1/K], or "
                 "with time, thermal:time=RHO [1/s]; joint compliance under gravity and the "
                 "payload, joint_compliance:JOINT=C [rad/(N·m)]; a gear error, "
                 "joint_periodic:JOINT=A_SIN,A_COS [rad]; a scale error, joint_scale:JOINT=S; "
                 "backlash, backlash:JOINT=B [rad] (repeatable)");
  std::vector<double> payloads_kg;
  app.add_option("--sim-payloads", payloads_kg,
                 "the arm carries a payload per stop drawn from these [kg] (e.g. 0,5,10), as "
                 "sensor_acquisition --sim-payloads; without: none")
      ->delimiter(',')
      ->check(CLI::Range(0.0, 1000.0));
  std::string payload_at_text = "move";
  app.add_option("--sim-payload-at", payload_at_text,
                 "--sim-payloads: where the arm takes a new payload on, as sensor_acquisition "
                 "--sim-payload-at: move (halfway through the move to the stop) or stop (halfway "
                 "through the stop: a grasp at the measurement stop, whose still window "
                 "still_window then refuses)")
      ->check(CLI::IsMember({"move", "stop"}))
      ->capture_default_str();
  app.add_option("--dds-domain", domain, "DDS domain (default: the cell's ros2.domain)");
  app.add_flag("--linger", linger, "stay up after the programme until SIGINT/SIGTERM");
  CLI11_PARSE(app, argc, argv);
  if (app.get_option("--sim-payload-at")->count() > 0 && payloads_kg.empty()) {
    std::fprintf(stderr, "ros2_sim_drivers: --sim-payload-at needs --sim-payloads\n");
    return 2;
  }

  try {
    services::InstallStopHandlers();
    const cell::CellSimSpec sim_spec = cell::LoadCellSimSpec(services::RepoPath(sim_path));
    const io::BuiltCell built = io::LoadCell(sim_spec.cell);
    if (!built.spec.ros2) throw std::runtime_error(sim_spec.cell.string() + ": no ros2: section");
    if (!built.spec.imu) throw std::runtime_error(sim_spec.cell.string() + ": no IMU");
    const io::Ros2Spec& ros = *built.spec.ros2;
    if (app.get_option("--seed")->count() == 0) seed = sim_spec.seed;
    if (poses <= 0) poses = sim_spec.num_cal;
    if (position_rate <= 0) position_rate = built.spec.position.rate;
    if (domain < 0) domain = ros.domain;

    // The programme of sensor_acquisition --source sim --level sensors.
    cell::SimProgramme programme = cell::MakeSimProgramme(built, sim_spec, seed, poses, test_poses);
    const cell::Cell& cell = programme.cell;
    const auto& model = cell.model;
    const sim::ToolMotionTruth& truth = programme.truth;
    // The tracker per marker: its own truth (the marker's slot) on the programme's motion.
    std::vector<sim::ToolMotionTruth> marker_truth;
    for (const auto& p : ros.positions)
      marker_truth.emplace_back(
          model.ForMarker(model.markers().empty() ? 0 : model.MarkerSlot(p.marker)), cell.x_true,
          truth.trajectory());
    // The controller's conditions (the temperature driver below), and with --sim-effect the arm
    // growing with them: the IMU's truth and every marker's.
    cell::SimArmConditions conditions(warmup_s, start_utime, seed);
    if (!payloads_kg.empty())
      conditions.SetPayloads(truth.trajectory(), payloads_kg,
                             payload_at_text == "stop"
                                 ? cell::SimArmConditions::PayloadChangeAt::kAtStop
                                 : cell::SimArmConditions::PayloadChangeAt::kMidMove);
    std::vector<sim::ToolMotionTruth*> grown = {&programme.truth};
    for (sim::ToolMotionTruth& m : marker_truth) grown.push_back(&m);
    for (const std::string& line : conditions.ApplyEffects(sim_effects, grown))
      spdlog::info("{}", line);
    const sim::SensorSimSettings ss = cell::SimSensorSettings(built, sim_spec);
    sim::SensorSim sensors(truth, ss, seed);
    const double duration = truth.trajectory().duration();

    const std::string uri = dds::EnsureCycloneConfig();
    dds::EntityGuard participant(
        dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr));
    if (participant.get() < 0)
      throw std::runtime_error(std::string("dds_create_participant: ") +
                               dds_strretcode(participant.get()));
    const dds_entity_t joints_w = Writer<dds::JointState>(participant.get(), ros.joint_states);
    const dds_entity_t imu_w = Writer<dds::Imu>(participant.get(), ros.imu);
    const dds_entity_t mag_w =
        ros.magnetic_field.empty()
            ? 0
            : Writer<dds::MagneticField>(participant.get(), ros.magnetic_field);
    const dds_entity_t temperature_w =
        ros.temperature.empty() ? 0 : Writer<dds::Temperature>(participant.get(), ros.temperature);
    const dds_entity_t payload_w =
        ros.payload.empty() ? 0 : Writer<dds::InertiaStamped>(participant.get(), ros.payload);
    std::vector<dds_entity_t> pos_w;
    for (const auto& p : ros.positions)
      pos_w.push_back(p.pose ? Writer<dds::PoseStamped>(participant.get(), p.topic)
                             : Writer<dds::PointStamped>(participant.get(), p.topic));

    // The driver's joint order: shuffled, plus a gripper joint.
    std::vector<int> order(model.num_joints());
    std::iota(order.begin(), order.end(), 0);
    if (shuffle_seed != 0) {
      std::mt19937_64 shuffle(static_cast<uint64_t>(shuffle_seed));
      std::shuffle(order.begin(), order.end(), shuffle);
    }
    std::mt19937_64 noise(static_cast<uint64_t>(seed) * 7919 + 11);
    std::normal_distribution<double> gauss;
    auto stamp = [&](double t, double offset) {
      return start_utime + std::llround((t + offset + jitter * gauss(noise)) * 1e6);
    };
    int64_t written = 0, failed = 0;
    auto write = [&](dds_entity_t w, const void* sample) {
      if (dds_write(w, sample) < 0)
        ++failed;
      else
        ++written;
    };
    const std::string imu_frame = ros.imu_frame.empty() ? "imu_link" : ros.imu_frame;

    // Build the whole programme's events in time order (joints, IMU + mag, tracker), then play.
    std::vector<Event> events;
    const int64_t n_joints = static_cast<int64_t>(std::floor(duration * joint_rate));
    for (int64_t k = 0; k <= n_joints; ++k) {
      const double t = static_cast<double>(k) / joint_rate;
      events.push_back({t, [&, t] {
                          Eigen::VectorXd q, qd;
                          truth.trajectory().Sample(t, q, &qd);
                          joint_state_t js = transport::ToJointState(
                              model, q, start_utime + std::llround(t * 1e6), qd);
                          js.names = built.ros2_joint_names;
                          // A gripper joint the driver also lists: not the arm's.
                          js.names.push_back("gripper_finger_joint");
                          js.q.push_back(0.01);
                          js.dq.push_back(0.0);
                          js.num_joints += 1;
                          std::vector<int> o = order;
                          o.push_back(js.num_joints - 1);
                          std::string error;
                          auto s = dds::ToRos(js, o, "", &error);
                          if (s) write(joints_w, &s->get());
                        }});
    }
    while (auto f = sensors.Next()) {
      const double t = f->t;
      const bool restarted = imu_restart_at >= 0 && t >= imu_restart_at;
      const double imu_clock_shift = restarted ? -imu_restart_at : 0.0;
      transport::ImuSample imu;
      imu.utime = stamp(t + imu_clock_shift, imu_offset);
      imu.gyro_B = f->imu.gyro_S;
      imu.f_B = f->imu.accel_S;
      const dds::MagReading mag{imu.utime, f->imu.mag_S * 1e-6};  // µT → T
      events.push_back({t, [&, imu, mag] {
                          std::string error;
                          if (mag_w)
                            if (auto m = dds::ToRos(mag, imu_frame.c_str(), &error))
                              write(mag_w, &m->get());
                          if (auto s = dds::ToRos(imu, imu_frame.c_str(), &error))
                            write(imu_w, &s->get());
                        }});
    }
    std::normal_distribution<double> pos_noise(0.0, built.spec.position.sigma.maxCoeff());
    const int64_t n_pos = static_cast<int64_t>(std::floor(duration * position_rate));
    for (int64_t k = 0; k <= n_pos; ++k) {
      const double t = static_cast<double>(k) / position_rate;
      for (size_t i = 0; i < ros.positions.size(); ++i) {
        transport::PositionSample p;
        p.utime = stamp(t, position_offset);
        p.p = marker_truth[i].At(t).p_WM_W +
              Eigen::Vector3d(pos_noise(noise), pos_noise(noise), pos_noise(noise));
        const bool pose = ros.positions[i].pose;
        const std::string frame =
            ros.positions[i].frame_id.empty() ? "tracker" : ros.positions[i].frame_id;
        const dds_entity_t w = pos_w[i];
        events.push_back({t, [&, p, pose, frame, w] {
                            std::string error;
                            if (pose) {
                              if (auto s = dds::ToRosPose(p, frame.c_str(), &error))
                                write(w, &s->get());
                            } else if (auto s = dds::ToRosPoint(p, frame.c_str(), &error)) {
                              write(w, &s->get());
                            }
                          }});
      }
    }
    // The controller's temperature and payload, once per second of its clock (no jitter: the
    // joints' clock), and the payload also as it changes (a pick or place is reported as it is
    // made, as sensor_acquisition's controller does).
    const double variance = std::pow(conditions.session().temperature_noise_c, 2);
    const auto report = [&](double t, bool temperature) {
      transport::ArmConditions c;
      c.utime = start_utime + std::llround(t * 1e6);
      c.temperature_c = conditions.Reported(t, std::llround(t * ss.rate_hz));
      c.payload_kg = conditions.ReportedPayload(t);
      events.push_back({t, [&, c, temperature] {
                          std::string error;
                          if (temperature && temperature_w)
                            if (auto s = dds::ToRos(c, variance, "arm", &error))
                              write(temperature_w, &s->get());
                          if (payload_w)
                            if (auto s = dds::ToRosPayload(c, "tool0", &error))
                              write(payload_w, &s->get());
                        }});
    };
    for (int64_t k = 0; (temperature_w || payload_w) && static_cast<double>(k) <= duration; ++k)
      report(static_cast<double>(k), true);
    for (const double t : conditions.PayloadReportTimes())
      if (payload_w && t <= duration) report(t, false);
    std::stable_sort(events.begin(), events.end(),
                     [](const Event& a, const Event& b) { return a.t < b.t; });
    spdlog::info(
        "ros2_sim_drivers: cell {} ({}), seed {}, {} stops, {:.1f} s: joints {} Hz, IMU {} Hz "
        "(clock {:+.1f} ms), tracker {} Hz (clock {:+.1f} ms), jitter {:.2f} ms, DDS domain {} "
        "(CYCLONEDDS_URI {})",
        built.spec.name, sim_spec.source, seed, poses, duration, joint_rate, ss.rate_hz,
        1e3 * imu_offset, position_rate, 1e3 * position_offset, 1e3 * jitter, domain, uri);
    // Let the readers discover the writers before the first sample (best effort drops what is
    // written before a match).
    std::this_thread::sleep_for(std::chrono::milliseconds(500));

    const long long wall0 = services::MonotonicMicros();
    for (const Event& e : events) {
      if (services::StopRequested()) break;
      if (speed > 0) {
        const long long due = wall0 + static_cast<long long>(e.t * 1e6 / speed);
        for (long long now = services::MonotonicMicros(); now < due && !services::StopRequested();
             now = services::MonotonicMicros())
          std::this_thread::sleep_for(std::chrono::microseconds(std::min(due - now, 20'000LL)));
      }
      e.publish();
    }
    spdlog::info("done: {} samples written, {} failed", written, failed);
    if (linger) {
      spdlog::info("lingering until stopped");
      while (!services::StopRequested())
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return failed == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
