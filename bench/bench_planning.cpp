// Planning the stops (identification/pose_planning.hpp, issue 16): 20 stops from 5 000 seeded
// candidates on one core, the budget `rcal plan-poses` promises (< 5 s). Arms not in the tests:
// random D–H arms (sim/random_arm.hpp), positions only; and the same with full poses.
#include <benchmark/benchmark.h>

#include <cstdio>

#include "bench_common.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/random_arm.hpp"

namespace {

using rcal::identification::PlanningProblem;
using rcal::identification::PlanningSettings;

// Everything plan-poses does after loading: candidates, Jacobians, base set, greedy + exchange.
void Plan(benchmark::State& state, rcal::kinematics::MeasurementKind kind) {
  const auto model = rcal::sim::RandomDhArm(static_cast<std::uint64_t>(state.range(0)));
  PlanningSettings s;
  s.kind = kind;
  s.position_sigma_m = 2e-5;
  int exchanges = 0;
  for (auto _ : state) {
    rcal::sim::Rng rng(1);
    const auto candidates = rcal::sim::SampleJoints(model, 5000, rng);
    const PlanningProblem pp(model, model.Nominal(), candidates, s);
    const auto plan = pp.Plan(20);
    exchanges = plan.exchanges;
    benchmark::DoNotOptimize(plan.log_det);
  }
  state.counters["exchanges"] = exchanges;
}

void BM_Plan20From5000PositionOnly(benchmark::State& state) {
  Plan(state, rcal::kinematics::MeasurementKind::kPositionOnly);
}
void BM_Plan20From5000FullPose(benchmark::State& state) {
  Plan(state, rcal::kinematics::MeasurementKind::kFullPose);
}
BENCHMARK(BM_Plan20From5000PositionOnly)->Arg(201)->Arg(202)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Plan20From5000FullPose)->Arg(201)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  if (!rcal::bench::InitializeWithMedians(argc, argv)) return 1;
  rcal::bench::TableReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double ns = reporter.Ns("BM_Plan20From5000PositionOnly");
  if (ns > 0)
    std::printf(
        "\nplanning 20 stops from 5000 candidates (positions only, random_dh_201): %.2f s "
        "real time, median (budget 5 s on one core; on a shared machine read the CPU column)\n",
        ns * 1e-9);
  benchmark::Shutdown();
  return 0;
}
