// rcal plan-poses-report [--arms N] [--first-arm A] [--seeds S] [--out DIR]: held-out error
// against the number of stops for four ways of choosing them (random, planned offline, online
// next-best, IROC-style greedy), on random D–H arms never used to build or tune the planner
// (sim/random_arm.hpp, seeds from --first-arm), positions only. Per arm the plans are made once
// at the nominal (a user plans before knowing the errors); per seed a simulated cell
// (calibration_sweep.hpp MakeSweepCell: geometric errors, world ← base 1–3 m away, an unknown
// marker offset) is measured at each strategy's stops and calibrated (identification::Calibrate,
// noise unknown), and judged against the truth on held-out random poses. Writes DIR/report.md,
// DIR/errors.png and DIR/report.json (SI).
// With --sim FILE, instead: the same four strategies on a simulated cell of rcal's own (the demo's
// config/cells/grb3016.sim.yaml), seeds 1..S as sensor_acquisition --seed draws its programme,
// measured with the still windows' noise and identified by the live identifier's logic
// (plan_poses.hpp CellStrategyErrors), judged at the programme's test stops.
#include <spdlog/spdlog.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>

#include "calibration_sweep.hpp"
#include "command.hpp"
#include "parallel.hpp"
#include "plan_poses.hpp"
#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/sim/random_arm.hpp"
#include "report.hpp"

namespace rcal::tool {
namespace {

using nlohmann::json;

struct Options {
  int arms = 4;
  unsigned first_arm = 101;
  int seeds = 5;
  std::vector<int> counts{15, 20, 25, 30, 40, 50};
  int candidates = 5000;
  double position_sigma_mm = 0.02;
  int jobs = 1;
  std::string criterion = "d-optimal";
  double stop_cost = identification::kDefaultStopCost;
  std::string out = "out/plan_poses_report";
  std::string sim;                       // --sim: the cell mode
  double orientation_sigma_mrad = 0.61;  // cell mode
  bool position_sigma_given = false;
};

void CheckCounts(const std::vector<int>& counts) {
  if (counts.empty() || !std::is_sorted(counts.begin(), counts.end()) || counts[0] < 6)
    throw std::runtime_error("--counts: ascending, each at least 6");
}

// The first count at which `next_best(c)` (the median error at count index c) is at or below
// `target`, as text; "> max" when none is.
std::string StopsToReach(const std::vector<int>& counts,
                         const std::function<double(size_t)>& next_best, double target) {
  for (size_t c = 0; c < counts.size(); ++c)
    if (next_best(c) <= target) return std::to_string(counts[c]);
  return "> " + std::to_string(counts.back());
}

// The four strategies' medians against stops as DIR/errors.png (its Markdown link appended to
// `md` when written), and the JSON rows by count; `all_of(strategy, count index)`: every error
// [m] of that strategy at that count.
json PlotAndRows(const std::vector<int>& counts,
                 const std::function<std::vector<double>(int, size_t)>& all_of, io::PlotSpec plot,
                 const std::filesystem::path& dir, const std::string& alt, std::string& md) {
  plot.xlabel = "stops measured";
  plot.logy = true;
  json rows = json::array();
  for (size_t c = 0; c < counts.size(); ++c) rows.push_back({{"stops", counts[c]}});
  for (int st = 0; st < 4; ++st) {
    io::Series ser;
    ser.title = kStrategyNames[st];
    ser.style = "linespoints";
    for (size_t c = 0; c < counts.size(); ++c) {
      const std::vector<double> all = all_of(st, c);
      const double median = SummarizeRatios(all).median;
      ser.x.push_back(counts[c]);
      ser.y.push_back(median * 1e6);
      rows[c][kStrategyNames[st]] = {{"median_m", median}, {"all_m", all}};
    }
    plot.series.push_back(ser);
  }
  if (io::PlotPng(plot, dir / "errors.png")) md += "\n![" + alt + "](errors.png)\n";
  return rows;
}

// The cell mode (--sim): the report for one simulated cell of rcal's own.
int RunCell(const Options& o) {
  if (o.seeds < 1) throw std::runtime_error("--seeds: at least 1");
  CheckCounts(o.counts);
  const cell::CellSimSpec spec = cell::LoadCellSimSpec(o.sim);
  const io::BuiltCell built = io::LoadCell(spec.cell);
  CellReportSettings s;
  s.counts = o.counts;
  s.settle_distance = o.stop_cost;
  if (o.position_sigma_given) s.position_sigma_m = o.position_sigma_mm / kMm;
  s.orientation_sigma_rad = o.orientation_sigma_mrad * 1e-3;
  const CellPlans plans = PlanCell(built, s);
  spdlog::info("{}: {} identifiable parameters; planned", built.spec.name, plans.identifiable);
  std::vector<std::array<std::vector<double>, 4>> errors(static_cast<size_t>(o.seeds));
  std::mutex log_mutex;
  std::atomic<int> done{0};
  Parallel(o.seeds, o.jobs, [&](int k) {
    errors[static_cast<size_t>(k)] =
        CellStrategyErrors(built, spec, plans, s, static_cast<unsigned>(k + 1));
    std::lock_guard lock(log_mutex);
    spdlog::info("{}/{} programmes done", ++done, o.seeds);
  });
  const size_t nc = o.counts.size();
  const auto all_of = [&](int strategy, size_t c) {
    std::vector<double> v;
    for (const auto& e : errors) v.push_back(e[strategy][c]);
    return v;
  };
  const auto median_of = [&](int strategy, size_t c) {
    return SummarizeRatios(all_of(strategy, c)).median;
  };
  const bool orientation = built.spec.measures_orientation();
  std::string md = "# Choosing the stops on " + built.spec.name + "\n\n";
  md += "The simulated cell of `" + o.sim + "` (its truth: arm errors and set-up frames), " +
        std::to_string(o.seeds) + " programmes (seeds 1 … " + std::to_string(o.seeds) +
        ", as `sensor_acquisition --seed` draws them), each pose measured with a still window's "
        "noise (" +
        Fmt(s.position_sigma_m * kMm, 3) + " mm" +
        (orientation ? ", " + Fmt(s.orientation_sigma_rad * 1e3, 2) + " mrad" : std::string()) +
        " per axis) and identified by the live identifier's logic (the set-up guess, then the "
        "EKF); mean position error at the programme's " +
        std::to_string(s.test_poses) +
        " test stops against the truth, median over the programmes, µm. Random: the programme's "
        "own stops; online next-best: the programme's stops until the identifier starts, then the "
        "best suggestion of NEXT_POSES after each pose (a pose-level cell following it).\n\n";
  std::vector<std::string> header = {"stops"};
  for (const char* n : kStrategyNames) header.push_back(n);
  std::vector<std::vector<std::string>> rows;
  for (size_t c = 0; c < nc; ++c) {
    std::vector<std::string> r = {std::to_string(o.counts[c])};
    for (int st = 0; st < 4; ++st) r.push_back(Fmt(median_of(st, c) * 1e6, 1));
    rows.push_back(r);
  }
  md += MdTable(header, rows);
  const auto it50 = std::find(o.counts.begin(), o.counts.end(), 50);
  std::string reach = "–";
  if (it50 != o.counts.end()) {
    const double r50 = median_of(kRandom, static_cast<size_t>(it50 - o.counts.begin()));
    reach = StopsToReach(
        o.counts, [&](size_t c) { return median_of(kNextBest, c); }, r50);
    md += "\nOnline next-best reaches the error of 50 random stops (" + Fmt(r50 * 1e6, 1) +
          " µm) at " + reach + " stops.";
  }
  if (plans.bound20_rms_m > 0 && plans.random50_rms_m > 0)
    md += " Linearised at the nominal over the workspace, no 20 stops from the " +
          std::to_string(s.candidates) + " candidates predict below " +
          Fmt(plans.bound20_rms_m * 1e6, 1) +
          " µm RMS (certified: "
          "`PlanningProblem::TaskMeanSquaredBound`), while 50 random ones predict " +
          Fmt(plans.random50_rms_m * 1e6, 1) + " µm.";
  md += "\n";
  io::PlotSpec plot;
  plot.title = "Test-stop position error against stops, " + built.spec.name;
  plot.ylabel = "mean test-stop position error [µm]";
  const std::filesystem::path dir(o.out);
  const json jc = PlotAndRows(o.counts, all_of, plot, dir, "test-stop error against stops", md);
  io::AtomicWriteFile(dir / "report.md", md);
  io::AtomicWriteFile(dir / "report.json",
                      json{{"sim", o.sim},
                           {"cell", built.spec.name},
                           {"seeds", o.seeds},
                           {"candidates", s.candidates},
                           {"identifiable", plans.identifiable},
                           {"stop_cost_rad", o.stop_cost},
                           {"position_noise_m", s.position_sigma_m},
                           {"orientation_noise_rad", orientation ? s.orientation_sigma_rad : 0.0},
                           {"test_poses", s.test_poses},
                           {"next_best_stops_to_random50", reach},
                           {"predicted_rms_any20_at_least_m", plans.bound20_rms_m},
                           {"predicted_rms_random50_m", plans.random50_rms_m},
                           {"by_count", jc}}
                          .dump(2));
  std::printf("%s", md.c_str());
  std::printf("\nwrote %s\n", (dir / "report.md").c_str());
  return 0;
}

int Run(const Options& o) {
  if (!o.sim.empty()) return RunCell(o);
  if (o.arms < 1 || o.seeds < 1) throw std::runtime_error("--arms and --seeds: at least 1");
  CheckCounts(o.counts);
  PlanningReportSettings s;
  s.counts = o.counts;
  s.candidates = o.candidates;
  s.position_sigma_m = o.position_sigma_mm / kMm;
  s.settle_distance = o.stop_cost;
  if (o.criterion == "workspace")
    s.criterion = identification::PlanCriterion::kTaskRegion;
  else if (o.criterion != "d-optimal")
    throw std::runtime_error("--criterion: d-optimal or workspace, not '" + o.criterion + "'");
  std::vector<kinematics::KinematicModel> arms;
  for (int a = 0; a < o.arms; ++a) arms.push_back(sim::RandomDhArm(o.first_arm + a));

  std::vector<ArmPlans> plans(o.arms);
  std::mutex log_mutex;
  Parallel(o.arms, o.jobs, [&](int a) {
    plans[a] = PlanArm(arms[a], s, 0xa2b1u + o.first_arm + a);
    std::lock_guard lock(log_mutex);
    spdlog::info("{}: {} identifiable parameters, planned 20 stops in {:.2f} s", arms[a].name(),
                 plans[a].identifiable, plans[a].plan_seconds);
  });
  // errors[arm][seed][strategy][count]
  std::vector<std::vector<std::array<std::vector<double>, 4>>> errors(
      o.arms, std::vector<std::array<std::vector<double>, 4>>(o.seeds));
  std::atomic<int> done{0};
  Parallel(o.arms * o.seeds, o.jobs, [&](int k) {
    const int a = k / o.seeds, seed = k % o.seeds;
    errors[a][seed] = StrategyErrors(arms[a], arms[a].name(), plans[a], s, seed + 1);
    std::lock_guard lock(log_mutex);
    spdlog::info("{}/{} cells done", ++done, o.arms * o.seeds);
  });

  const size_t nc = o.counts.size();
  const auto all_of = [&](int strategy, size_t c, int arm) {  // arm < 0: all arms
    std::vector<double> v;
    for (int a = 0; a < o.arms; ++a)
      if (arm < 0 || arm == a)
        for (int sd = 0; sd < o.seeds; ++sd) v.push_back(errors[a][sd][strategy][c]);
    return v;
  };
  const auto median_of = [&](int strategy, size_t c, int arm) {
    return SummarizeRatios(all_of(strategy, c, arm)).median;
  };
  std::string md = "# Choosing the stops: held-out error against the number of stops\n\n";
  md += std::to_string(o.arms) + " random D–H arms (random_dh_" + std::to_string(o.first_arm) +
        " … " + std::to_string(o.first_arm + o.arms - 1) + ", not used to build the planner) × " +
        std::to_string(o.seeds) +
        " simulated cells each (geometric errors 0.5 mm / 1 mrad, world ← base 1–3 m away, "
        "unknown marker offset), positions only, " +
        Fmt(o.position_sigma_mm, 3) + " mm noise per axis; " + std::to_string(o.candidates) +
        " candidate configurations per arm; mean position error on " +
        std::to_string(s.test_poses) +
        " held-out random poses against the truth after `Calibrate` (noise unknown). Median over "
        "arms and cells, µm:\n\n";
  std::vector<std::string> header = {"stops"};
  for (const char* n : kStrategyNames) header.push_back(n);
  header.push_back("planned / random");
  std::vector<std::vector<std::string>> rows;
  for (size_t c = 0; c < nc; ++c) {
    std::vector<std::string> r = {std::to_string(o.counts[c])};
    for (int st = 0; st < 4; ++st) r.push_back(Fmt(median_of(st, c, -1) * 1e6, 1));
    r.push_back(Fmt(median_of(kPlanned, c, -1) / median_of(kRandom, c, -1), 2));
    rows.push_back(r);
  }
  md += MdTable(header, rows);

  // Per arm: 20 planned stops against 40 random ones (the figure), and the online
  // next-best stops needed to reach 50 random stops.
  const auto index_of = [&](int n) {
    const auto it = std::find(o.counts.begin(), o.counts.end(), n);
    return it == o.counts.end() ? -1 : static_cast<int>(it - o.counts.begin());
  };
  const int i20 = index_of(20), i40 = index_of(40), i50 = index_of(50);
  json jarms = json::array();
  if (i20 >= 0 && i40 >= 0) {
    md += "\nPer arm (median over its cells, µm):\n\n";
    std::vector<std::vector<std::string>> arows;
    for (int a = 0; a < o.arms; ++a) {
      const double p20 = median_of(kPlanned, i20, a), r20 = median_of(kRandom, i20, a),
                   r40 = median_of(kRandom, i40, a), g20 = median_of(kIroc, i20, a);
      const std::string nb =
          i50 < 0 ? "–"
                  : StopsToReach(
                        o.counts, [&](size_t c) { return median_of(kNextBest, c, a); },
                        median_of(kRandom, i50, a));
      const auto& path = plans[a].path20;
      arows.push_back(
          {arms[a].name(), std::to_string(plans[a].identifiable), Fmt(r20 * 1e6, 1),
           Fmt(r40 * 1e6, 1), Fmt(p20 * 1e6, 1), Fmt(g20 * 1e6, 1), p20 <= r40 ? "yes" : "**no**",
           nb,
           Fmt(path[kRandom], 0) + " / " + Fmt(path[kPlanned], 0) + " / " +
               Fmt(path[kNextBest], 0) + " / " + Fmt(path[kIroc], 0),
           Fmt(plans[a].plan_seconds, 2),
           Fmt(plans[a].bound20_rms_m * 1e6, 1) + " / " + Fmt(plans[a].random40_rms_m * 1e6, 1)});
      jarms.push_back({{"arm", arms[a].name()},
                       {"predicted_rms_any20_at_least_m", plans[a].bound20_rms_m},
                       {"predicted_rms_random40_m", plans[a].random40_rms_m},
                       {"identifiable", plans[a].identifiable},
                       {"random20_m", r20},
                       {"random40_m", r40},
                       {"planned20_m", p20},
                       {"iroc20_m", g20},
                       {"next_best_stops_to_random50", nb},
                       {"path20_rad",
                        {{"random", plans[a].path20[kRandom]},
                         {"planned", plans[a].path20[kPlanned]},
                         {"next_best", plans[a].path20[kNextBest]},
                         {"iroc", plans[a].path20[kIroc]}}},
                       {"plan20_cpu_s", plans[a].plan_seconds}});
    }
    md += MdTable({"arm", "identifiable", "random 20", "random 40", "planned 20", "IROC 20",
                   "planned 20 ≤ random 40", "next-best stops to reach random 50",
                   "joint path of 20 stops [rad]: random / planned / next-best / IROC",
                   "planning CPU [s]", "predicted RMS [µm]: any 20 stops ≥ / 40 random"},
                  arows);
    md +=
        "\nThe last column is the linearised prediction over the workspace: the least RMS error "
        "any 20 stops drawn from the candidates can give (the approximate-design relaxation, "
        "solved to a certified lower bound: `identification::PlanningProblem::"
        "TaskMeanSquaredBound`), against the median of 40 random candidates. Where the first "
        "figure is above the second, no planner choosing among these candidates can make 20 "
        "stops as good as 40 random ones.\n";
  }

  io::PlotSpec plot;
  plot.title = "Held-out position error against stops (median over arms and cells)";
  plot.ylabel = "mean held-out position error [µm]";
  const std::filesystem::path dir(o.out);
  const json jc = PlotAndRows(
      o.counts, [&](int st, size_t c) { return all_of(st, c, -1); }, plot, dir,
      "held-out error against stops", md);
  io::AtomicWriteFile(dir / "report.md", md);

  io::AtomicWriteFile(dir / "report.json", json{{"arms", o.arms},
                                                {"first_arm", o.first_arm},
                                                {"seeds", o.seeds},
                                                {"candidates", o.candidates},
                                                {"criterion", o.criterion},
                                                {"stop_cost_rad", o.stop_cost},
                                                {"position_noise_m", s.position_sigma_m},
                                                {"test_poses", s.test_poses},
                                                {"by_count", jc},
                                                {"by_arm", jarms}}
                                               .dump(2));
  std::printf("%s", md.c_str());
  std::printf("\nwrote %s\n", (dir / "report.md").c_str());
  return 0;
}

const RegisterCommand kPlanPosesReport(
    "plan-poses-report",
    "Held-out error against stops: random, planned, online next-best, IROC-style greedy",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--arms", o->arms, "random D–H arms")->capture_default_str();
      sub.add_option("--first-arm", o->first_arm, "seed of the first arm")->capture_default_str();
      sub.add_option("--seeds", o->seeds, "simulated cells per arm")->capture_default_str();
      sub.add_option("--counts", o->counts, "stop counts, ascending")
          ->delimiter(',')
          ->capture_default_str();
      sub.add_option("--candidates", o->candidates, "candidate configurations per arm")
          ->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm,
                     "position noise σ per axis (--sim: default 0.051, a still window's)")
          ->capture_default_str()
          ->check(cli::PositiveNumber)
          ->each([o](const std::string&) { o->position_sigma_given = true; });
      sub.add_option("--sim", o->sim,
                     "instead of random arms: a simulated cell of rcal's own (a sim file, e.g. "
                     "config/cells/grb3016.sim.yaml), identified as the live pipeline does");
      sub.add_option("--orientation-sigma-mrad", o->orientation_sigma_mrad,
                     "--sim: orientation noise σ per axis of a still window's pose")
          ->capture_default_str()
          ->check(cli::PositiveNumber);
      sub.add_option("--jobs", o->jobs, "worker threads (the figures do not depend on it)")
          ->capture_default_str()
          ->check(cli::Range(1, 64));
      sub.add_option("--criterion", o->criterion,
                     "planned stops: d-optimal, or workspace (predicted error over the workspace)")
          ->capture_default_str();
      sub.add_option("--stop-cost", o->stop_cost,
                     "online next-best: a stop's cost as joint-space distance [rad | m] "
                     "(ekf_identifier --next-poses-stop-cost)")
          ->capture_default_str()
          ->check(cli::NonNegativeNumber);
      sub.add_option("--out", o->out, "report folder")->capture_default_str();
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
