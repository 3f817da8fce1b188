// `rcal fuse`'s filters on one core (issue 17): samples per second of the orientation KF alone
// and of the whole per-sample fuse (orientation KF, FQA of the raw sample as the report scores
// it, position KF accelerometer update with the lever arm, and the position sensor at 20 Hz),
// both with the BROAD settings `rcal fuse` ships (tools/rcal/fuse_settings.cpp). Input: BROAD
// trial 07 (fast rotation, 100 Hz, ../shared/data/broad), looped with time kept increasing.
//   ./build/bench/bench_fuse --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <vector>

#include "fuse_settings.hpp"
#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/io/imu_csv.hpp"

namespace {

using namespace rcal;

const io::ImuCsv& Trial() {
  static const io::ImuCsv t = io::LoadImuCsv(RCAL_SHARED_DIR "/data/broad/broad_07_100hz.csv");
  return t;
}

// Time of sample i of the endless loop [s] (laps appended, 10 ms apart).
double LoopTime(const io::ImuCsv& d, long i) {
  const long n = static_cast<long>(d.t.size());
  return d.t[i % n] + static_cast<double>(i / n) * (d.t.back() + 0.01);
}

// state.range(0): the hard-iron fit on (1, as shipped) or off (0), for its share of the cost.
void BM_OrientationKfBroadSettings(benchmark::State& state) {
  const io::ImuCsv& d = Trial();
  const long n = static_cast<long>(d.t.size());
  estimation::OrientationKfSettings settings = tool::BroadSettingsWith({}).orientation;
  settings.estimate_hard_iron = state.range(0) != 0;
  estimation::OrientationKf kf(settings);
  long i = 0;
  for (auto _ : state) {
    const long k = i % n;
    benchmark::DoNotOptimize(kf.Update(LoopTime(d, i), d.gyro[k], d.accel[k], d.mag_uT[k]).ok());
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_OrientationKfBroadSettings)->ArgName("hard_iron")->Arg(1)->Arg(0);

void BM_WholeFuse(benchmark::State& state) {
  const io::ImuCsv& d = Trial();
  const long n = static_cast<long>(d.t.size());
  const tool::FuseSettings s = tool::BroadSettingsWith({});
  estimation::OrientationKf okf(s.orientation);
  estimation::PositionKf pkf(s.position);
  estimation::FqaSettings fqa;
  fqa.earth = estimation::EarthFrame::kEnu;
  fqa.m_ref_E = estimation::MagneticNorth(fqa.earth);
  long i = 0;
  for (auto _ : state) {
    const long k = i % n;
    const double t = LoopTime(d, i);
    benchmark::DoNotOptimize(okf.Update(t, d.gyro[k], d.accel[k], d.mag_uT[k]).ok());
    benchmark::DoNotOptimize(estimation::Fqa(d.accel[k], d.mag_uT[k], fqa).ok());
    benchmark::DoNotOptimize(pkf.UpdateAccel(t, d.accel[k], okf.R_EB(), okf.omega_B()).ok());
    if (i % 5 == 0 && d.p_truth[k].allFinite())
      benchmark::DoNotOptimize(pkf.UpdatePosition(t, d.p_truth[k]).ok());
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_WholeFuse);

}  // namespace

BENCHMARK_MAIN();
