// Throughput of ros2_input's core (services/ros2_input/ros2_input.hpp): decoded ROS 2 driver
// samples in, the pipeline's events out — checks, joint names mapped, the magnetometer paired,
// the reorder buffer, and (Arg 1) every source's clock offset estimated against the joints.
// The streams are the demo cell's simulated drivers (ros2_sim_drivers' rates: JointState 125 Hz,
// Imu + MagneticField 100 Hz, PointStamped 100 Hz), 60 s of them, decoded once beforehand;
// items/s counts driver samples.
//
//   ./build/bench/bench_ros2_input
#include <benchmark/benchmark.h>

#include <variant>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "ros2_input.hpp"

namespace {

using namespace rcal;

struct Stream {
  io::BuiltCell cell;
  std::vector<std::variant<dds::Sample<dds::JointState>, dds::Sample<dds::Imu>,
                           dds::Sample<dds::MagneticField>, dds::Sample<dds::PointStamped>>>
      samples;
};

// 60 s of the demo cell's drivers, in arrival order (IMU +37 ms, tracker −120 ms).
const Stream& DemoStream() {
  static const Stream s = [] {
    Stream out{io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml"), {}};
    const cell::CellSimSpec sim =
        cell::LoadCellSimSpec(RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml");
    const cell::Cell c = cell::MakeSimCell(out.cell, sim);
    sim::Rng rng(1003);
    const auto stops = sim::SampleJoints(c.model, 8, rng);
    sim::TrajectorySettings ts;
    ts.still_time = 1.5;
    const sim::ToolMotionTruth truth(c.model, c.x_true, sim::JointTrajectory(stops, ts));
    sim::SensorSim sensors(truth, cell::SimSensorSettings(out.cell, sim), 1);
    std::string error;
    const int64_t t0 = 1'000'000'000;
    double next_joint = 0.0;
    while (auto f = sensors.Next()) {
      if (f->t > 60.0) break;
      for (; next_joint <= f->t; next_joint += 1.0 / 125.0) {
        Eigen::VectorXd q, qd;
        truth.trajectory().Sample(next_joint, q, &qd);
        joint_state_t js =
            transport::ToJointState(c.model, q, t0 + std::llround(next_joint * 1e6), qd);
        js.names = out.cell.ros2_joint_names;
        out.samples.emplace_back(std::move(*dds::ToRos(js, {}, "", &error)));
      }
      transport::ImuSample imu;
      imu.utime = t0 + std::llround((f->t + 0.037) * 1e6);
      imu.gyro_B = f->imu.gyro_S;
      imu.f_B = f->imu.accel_S;
      out.samples.emplace_back(std::move(
          *dds::ToRos(dds::MagReading{imu.utime, f->imu.mag_S * 1e-6}, "imu_link", &error)));
      out.samples.emplace_back(std::move(*dds::ToRos(imu, "imu_link", &error)));
      transport::PositionSample p;
      p.utime = t0 + std::llround((f->t - 0.120) * 1e6);
      p.p = f->truth.p_WM_W;
      out.samples.emplace_back(std::move(*dds::ToRosPoint(p, "tracker", &error)));
    }
    return out;
  }();
  return s;
}

void BM_Ros2InputSamples(benchmark::State& state) {
  const Stream& s = DemoStream();
  ros2::Ros2InputSettings settings = ros2::FromCell(s.cell);
  settings.estimate_clock_offsets = state.range(0) != 0;
  int64_t events = 0;
  for (auto _ : state) {
    transport::Health health("bench");
    ros2::Ros2Input in(settings, s.cell.model, health);
    for (const auto& v : s.samples) {
      if (const auto* j = std::get_if<dds::Sample<dds::JointState>>(&v))
        in.OnJointState(j->get());
      else if (const auto* i = std::get_if<dds::Sample<dds::Imu>>(&v))
        in.OnImu(i->get());
      else if (const auto* m = std::get_if<dds::Sample<dds::MagneticField>>(&v))
        in.OnMagneticField(m->get());
      else
        in.OnPoint(0, std::get<dds::Sample<dds::PointStamped>>(v).get());
      events += static_cast<int64_t>(in.Ready().size());
    }
    events += static_cast<int64_t>(in.Ready(true).size());
  }
  benchmark::DoNotOptimize(events);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(s.samples.size()));
  state.counters["samples"] = static_cast<double>(s.samples.size());
}
BENCHMARK(BM_Ros2InputSamples)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
