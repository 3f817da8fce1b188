// ClockOffsetEstimator's cost: the samples per second it takes in (joints 125 Hz, IMU 100 Hz,
// tracker 120 Hz, re-estimating both sources every 2 s of a 20 s buffer, as live), and the time
// of one window's estimate per source. Input: the GRB3016 (config/robots) moving stop-and-go
// between random poses (libs/sim), noise-free, the IMU stamped +37 ms, the tracker −120 ms.
#include <benchmark/benchmark.h>

#include <vector>

#include "rcal/estimation/clock_offset.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/sim/trajectory.hpp"

namespace {

using namespace rcal;

struct Sample {
  int kind;  // 0 joints (q only), 1 gyro, 2 marker
  double t;  // stamp on the source's clock [s]
  Eigen::VectorXd q;
  Eigen::Vector3d v;
};

struct Stream {
  kinematics::KinematicModel model;
  std::vector<Sample> samples;  // in arrival order
  Stream() {
    model = io::LoadRobotYaml(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
    sim::Rng rng(1);
    const sim::ToolMotionTruth truth(model, model.Nominal(),
                                     sim::JointTrajectory(sim::SampleJoints(model, 12, rng)));
    // 1 ms ticks; each stream fires on its own period.
    for (int k = 0; k * 1e-3 <= truth.trajectory().duration(); ++k) {
      const double t = k * 1e-3;
      if (k % 8 == 0) {
        Sample s{0, t, {}, {}};
        truth.trajectory().Sample(t, s.q);
        samples.push_back(s);
      }
      if (k % 10 == 0) samples.push_back({1, t + 0.037, {}, truth.At(t).omega_I});
      if (k % 25 == 3 || k % 25 == 11 || k % 25 == 19)  // three per 25 ms: 120 Hz
        samples.push_back({2, t - 0.120, {}, truth.At(t).p_WM_W});
    }
  }
};

const Stream& Data() {
  static const Stream s;
  return s;
}

void Push(estimation::ClockOffsetEstimator& est, const Sample& s) {
  if (s.kind == 0)
    benchmark::DoNotOptimize(est.PushJoints(s.t, s.q));
  else if (s.kind == 1)
    benchmark::DoNotOptimize(est.PushGyro(s.t, s.v));
  else
    benchmark::DoNotOptimize(est.PushMarker(s.t, s.v));
}

// The whole stream through a fresh estimator (its periodic estimates included): samples/s.
void BM_ClockOffsetStream(benchmark::State& state) {
  const Stream& d = Data();
  for (auto _ : state) {
    estimation::ClockOffsetEstimator est(d.model);
    for (const Sample& s : d.samples) Push(est, s);
    benchmark::DoNotOptimize(est.offset(estimation::ClockSource::kImu));
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(d.samples.size()));
}
BENCHMARK(BM_ClockOffsetStream)->Unit(benchmark::kMillisecond);

// One estimate of a source on full 20 s buffers.
void BM_ClockOffsetEstimate(benchmark::State& state) {
  const Stream& d = Data();
  estimation::ClockOffsetSettings cs;
  cs.estimate_every_s = 1e9;  // only the explicit estimates below
  estimation::ClockOffsetEstimator est(d.model, cs);
  for (const Sample& s : d.samples) Push(est, s);
  const auto source = static_cast<estimation::ClockSource>(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(est.Estimate(source));
  state.SetLabel(estimation::ClockSourceName(source));
}
BENCHMARK(BM_ClockOffsetEstimate)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
