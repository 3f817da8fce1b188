// `rcal experiment paper --sensors --sweep-seeds N` (see sensor_seed_sweep.hpp).
#include "sensor_seed_sweep.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <future>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <stdexcept>

#include "command.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "report.hpp"

namespace rcal::tool::exp {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
// CPU time of the calling thread [s]: what a run costs, whatever else loads the machine.
double ThreadCpuS() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

std::vector<Eigen::VectorXd> JointsOf(const std::vector<kinematics::PoseMeasurement>& ms) {
  std::vector<Eigen::VectorXd> qs;
  for (const auto& m : ms) qs.push_back(m.q);
  return qs;
}

// One run of one configuration.
struct Run {
  unsigned seed_index = 0, seed = 0;
  bool ok = false;  // false: too few windows to calibrate
  double test_position_m = kNaN, test_orientation_rad = kNaN;
  double crb_position_m = kNaN, crb_orientation_rad = kNaN;
  double window_position_m = kNaN, window_orientation_rad = kNaN, window_nees = kNaN;
  int cal_windows = 0, rejected = 0;
  double wall_s = 0, cpu_s = 0;
};

Run RunOne(const io::RobotSpec& spec, const SweepConfig& c, unsigned seed_index) {
  const auto t0 = Clock::now();
  const double c0 = ThreadCpuS();
  Run r;
  r.seed_index = seed_index;
  r.seed = SweepRunSeed(c.number, seed_index);
  const cell::Cell cell = cell::MakeCell(spec, r.seed);
  cell::RunSettings rs = c.settings;
  rs.seed = r.seed;
  const cell::Windows w = cell::SimulateWindows(cell, rs);
  r.cal_windows = static_cast<int>(w.cal.size());
  r.window_position_m = w.mean_position_error_m;
  r.window_orientation_rad = w.mean_orientation_error_rad;
  r.window_nees = w.mean_nees;
  if (w.cal.size() >= 6 && !w.test.empty()) {
    const auto test_q = JointsOf(w.test);
    const cell::OnlineResult on = cell::RunOnline(cell, w.cal, test_q);
    const auto e = identification::ErrorsAgainstTruth(cell.model, on.x, cell.x_true, test_q);
    const Eigen::MatrixXd crb =
        identification::CramerRaoBound(cell.model, cell.base, w.cal, cell.x_true);
    // Seeded as `rcal experiment paper --sensors --seed S` seeds it: the baseline's run i is that
    // command's figure at seed i.
    const auto [crb_p, crb_o] = identification::PredictedMeanErrors(cell.model, cell.base, crb,
                                                                    cell.x_true, test_q, r.seed);
    r.ok = true;
    r.test_position_m = e.mean_position_m;
    r.test_orientation_rad = e.mean_orientation_rad;
    r.crb_position_m = crb_p;
    r.crb_orientation_rad = crb_o;
    r.rejected = on.rejected;
  }
  r.wall_s = Since(t0);
  r.cpu_s = ThreadCpuS() - c0;
  return r;
}

// Order statistics (linear interpolation between order statistics, Hyndman–Fan type 7).
struct Spread {
  int n = 0;
  double median = kNaN, p10 = kNaN, p90 = kNaN, q25 = kNaN, q75 = kNaN, min = kNaN, max = kNaN;
};
double Quantile(const std::vector<double>& sorted, double p) {
  const double h = p * (sorted.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(h));
  const size_t hi = std::min(lo + 1, sorted.size() - 1);
  return sorted[lo] + (h - lo) * (sorted[hi] - sorted[lo]);
}
Spread SpreadOf(std::vector<double> v) {
  std::erase_if(v, [](double x) { return !std::isfinite(x); });
  Spread s;
  s.n = static_cast<int>(v.size());
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.median = Quantile(v, 0.5);
  s.p10 = Quantile(v, 0.1);
  s.p90 = Quantile(v, 0.9);
  s.q25 = Quantile(v, 0.25);
  s.q75 = Quantile(v, 0.75);
  s.min = v.front();
  s.max = v.back();
  return s;
}
json SpreadJson(const Spread& s) {
  auto num = [](double x) { return std::isfinite(x) ? json(x) : json(nullptr); };
  return {{"runs", s.n},       {"median", num(s.median)}, {"p10", num(s.p10)}, {"p90", num(s.p90)},
          {"q25", num(s.q25)}, {"q75", num(s.q75)},       {"min", num(s.min)}, {"max", num(s.max)}};
}
std::vector<double> Field(const std::vector<Run>& runs, double Run::*f) {
  std::vector<double> v;
  for (const auto& r : runs) v.push_back(r.*f);
  return v;
}

struct Row {
  const SweepConfig* config = nullptr;
  std::vector<Run> runs;
  int failed = 0;
  Spread test_position, test_orientation, crb_position, ratio, nees;
};

std::string Mm(double m, int digits = 3) {
  return std::isfinite(m) ? Fmt(m * kMm, digits) : "–";
}
std::string Range(const Spread& s) {
  return Mm(s.p10) + "–" + Mm(s.p90);
}

}  // namespace

unsigned SweepRunSeed(int config_number, unsigned seed_index) {
  if (config_number < 0 || seed_index < 1 || seed_index >= 10000)
    throw std::invalid_argument("sweep seed index must be in [1, 9999]");
  return 10000u * static_cast<unsigned>(config_number) + seed_index;
}

std::vector<SweepConfig> SensorSweepConfigs(int num_cal, int num_test) {
  cell::RunSettings b;
  b.num_cal = num_cal;
  b.num_test = num_test;
  b.num_extra = 0;
  std::vector<SweepConfig> c;
  int number = 0;
  auto add = [&](std::string id, std::string factor, std::string value, cell::RunSettings s) {
    c.push_back({std::move(id), number++, std::move(factor), std::move(value), s});
  };
  add("baseline", "baseline", "×1 noise, 1.5 s stops, " + std::to_string(num_cal) + " poses", b);
  for (double s : {0.5, 2.0, 4.0}) {
    cell::RunSettings r = b;
    r.noise_scale = s;
    add("noise-" + Fmt(s, s < 1 ? 1 : 0), "sensor noise", "×" + Fmt(s, s < 1 ? 1 : 0), r);
  }
  for (double t : {0.9, 3.0}) {
    cell::RunSettings r = b;
    r.still_time = t;
    add("still-" + Fmt(t, t < 1 ? 1 : 0), "still stop", Fmt(t, t < 1 ? 1 : 0) + " s", r);
  }
  for (int n : {10, 20, 30}) {
    cell::RunSettings r = b;
    r.num_cal = n;
    add("poses-" + std::to_string(n), "calibration poses", std::to_string(n), r);
  }
  for (double d : {0.1, 0.5}) {
    cell::RunSettings r = b;
    r.dropout = d;
    add("dropout-" + Fmt(d * 100, 0), "position dropouts", Fmt(d * 100, 0) + " %", r);
  }
  {
    cell::RunSettings r = b;
    r.gyro_bias = true;
    add("gyro-bias", "gyro bias",
        "0.3 °/s + random walks (gyro 1e-5 rad/s/√s, accelerometer 1e-4 m/s²/√s)", r);
  }
  {
    cell::RunSettings r = b;
    r.mag_disturbance = true;
    add("mag-disturbance", "magnetic disturbance", "15 µT at 20 % of stops", r);
  }
  return c;
}

int RunSensorsSeedSweep(const SeedSweepOptions& o) {
  const auto t_start = Clock::now();
  if (o.seeds < 1) throw std::invalid_argument("--sweep-seeds must be at least 1");
  if (o.first_seed < 1 || o.first_seed + o.seeds > 10000)
    throw std::invalid_argument("sweep seed indices must lie in [1, 9999]");
  const io::LoadedRobot robot = io::LoadRobot(ResolvePath(o.robot));
  const auto all = SensorSweepConfigs(o.num_cal, o.num_test);
  std::vector<Row> rows;
  {
    std::set<std::string> wanted(o.configs.begin(), o.configs.end());
    for (const auto& id : wanted) {
      if (std::none_of(all.begin(), all.end(), [&](const SweepConfig& c) { return c.id == id; })) {
        std::string known;
        for (const auto& c : all) known += (known.empty() ? "" : ", ") + c.id;
        throw std::invalid_argument("--sweep-configs: unknown configuration '" + id +
                                    "' (known: " + known + ")");
      }
    }
    for (const auto& c : all)
      if (wanted.empty() || wanted.count(c.id)) {
        Row r;
        r.config = &c;
        rows.push_back(std::move(r));
      }
  }
  for (auto& r : rows) r.runs.resize(o.seeds);

  // Jobs in a fixed order, results stored by index: the figures do not depend on --jobs.
  const size_t total = rows.size() * o.seeds;
  std::atomic<size_t> next{0}, done{0};
  std::mutex log_mutex;
  spdlog::info("sensor sweep: {} configurations × {} seeds = {} runs, {} jobs", rows.size(),
               o.seeds, total, o.jobs);
  auto worker = [&] {
    for (size_t j = next++; j < total; j = next++) {
      Row& row = rows[j / o.seeds];
      const unsigned index = o.first_seed + static_cast<unsigned>(j % o.seeds);
      Run r = RunOne(robot.spec, *row.config, index);
      row.runs[j % o.seeds] = r;
      const size_t n = ++done;
      const double elapsed = Since(t_start);
      std::lock_guard lock(log_mutex);
      spdlog::info(
          "[{}/{}] {} seed {} (run seed {}): test {} mm, Cramér–Rao {} mm ({:.1f} s CPU); "
          "{:.0f} s elapsed, ~{:.0f} s left",
          n, total, row.config->id, index, r.seed, Mm(r.test_position_m, 4),
          Mm(r.crb_position_m, 4), r.cpu_s, elapsed, elapsed / n * static_cast<double>(total - n));
    }
  };
  {
    std::vector<std::future<void>> pool;
    for (int k = 1; k < std::max(1, o.jobs); ++k)
      pool.push_back(std::async(std::launch::async, worker));
    worker();
    for (auto& f : pool) f.get();
  }

  for (auto& row : rows) {
    std::vector<double> ratio;
    for (const auto& r : row.runs) {
      row.failed += !r.ok;
      ratio.push_back(r.ok ? r.test_position_m / r.crb_position_m : kNaN);
    }
    row.test_position = SpreadOf(Field(row.runs, &Run::test_position_m));
    row.test_orientation = SpreadOf(Field(row.runs, &Run::test_orientation_rad));
    row.crb_position = SpreadOf(Field(row.runs, &Run::crb_position_m));
    row.nees = SpreadOf(Field(row.runs, &Run::window_nees));
    row.ratio = SpreadOf(ratio);
  }
  const double runtime_s = Since(t_start);
  double cpu_s = 0;
  for (const auto& row : rows)
    for (const auto& r : row.runs) cpu_s += r.cpu_s;
  const std::string seeds_text = "seed indices " + std::to_string(o.first_seed) + "–" +
                                 std::to_string(o.first_seed + o.seeds - 1);

  // ---- Tables ------------------------------------------------------------------------------
  std::vector<std::vector<std::string>> full;
  for (size_t k = 0; k < rows.size(); ++k) {
    const Row& r = rows[k];
    full.push_back({std::to_string(k + 1), r.config->factor + ": " + r.config->value,
                    std::to_string(r.test_position.n) +
                        (r.failed ? " (" + std::to_string(r.failed) + " failed)" : ""),
                    Mm(r.test_position.median, 4), Range(r.test_position),
                    Mm(r.test_position.q25) + "–" + Mm(r.test_position.q75),
                    Mm(r.crb_position.median, 4),
                    std::isfinite(r.ratio.median) ? Fmt(r.ratio.median, 2) : "–",
                    std::isfinite(r.nees.median) ? Fmt(r.nees.median, 1) : "–"});
  }
  const std::string full_table =
      MdTable({"#", "configuration", "runs", "test position, median [mm]",
               "10th–90th percentile [mm]", "25th–75th percentile [mm]", "Cramér–Rao, median [mm]",
               "error / Cramér–Rao, median", "window NEES, median"},
              full);
  // The README's layout: one line per factor, values joined by " / ".
  std::vector<std::vector<std::string>> compact;
  const Row* baseline = nullptr;
  for (size_t k = 0; k < rows.size();) {
    size_t e = k;
    while (e < rows.size() && rows[e].config->factor == rows[k].config->factor) ++e;
    if (rows[k].config->id == "baseline") {
      baseline = &rows[k];
      k = e;
      continue;
    }
    std::string values, med, spread, crb;
    for (size_t i = k; i < e; ++i) {
      const std::string sep = i > k ? " / " : "";
      values += sep + rows[i].config->value;
      med += sep + Mm(rows[i].test_position.median);
      spread += sep + Range(rows[i].test_position);
      crb += sep + Mm(rows[i].crb_position.median);
    }
    compact.push_back({rows[k].config->factor + " " + values, med, spread, crb});
    k = e;
  }
  const std::string base_text = baseline
                                    ? "baseline " + Mm(baseline->test_position.median) + " mm, " +
                                          Range(baseline->test_position) + " mm; Cramér–Rao " +
                                          Mm(baseline->crb_position.median) + " mm"
                                    : "baseline not run";
  const std::string compact_table =
      MdTable({"change from the baseline (" + base_text + ")", "test error, median [mm]",
               "10th–90th percentile [mm]", "Cramér–Rao, median [mm]"},
              compact);

  // ---- Files -------------------------------------------------------------------------------
  const fs::path out(o.out);
  fs::create_directories(out);
  std::vector<double> xs, med, p10, p90, crb;
  std::vector<std::pair<double, std::string>> names;  // the x axis: each configuration named
  for (size_t k = 0; k < rows.size(); ++k) {
    xs.push_back(k + 1);
    names.emplace_back(k + 1, rows[k].config->factor + " " + rows[k].config->value);
    med.push_back(rows[k].test_position.median * kMm);
    p10.push_back(rows[k].test_position.p10 * kMm);
    p90.push_back(rows[k].test_position.p90 * kMm);
    crb.push_back(rows[k].crb_position.median * kMm);
  }
  io::PlotSpec plot{"Test position error after calibration over " + std::to_string(o.seeds) +
                        " seeds per configuration",
                    "",
                    "mean test position error against truth [mm]",
                    {{"median", xs, med, "points"},
                     {"10th percentile", xs, p10, "points"},
                     {"90th percentile", xs, p90, "points"},
                     {"Cramér–Rao prediction, median", xs, crb, "points"}},
                    false,
                    true};
  plot.xtics = names;
  plot.height_px = 600;  // room for the turned configuration names
  io::PlotPng(plot, out / "sweep_seeds.png");

  std::ostringstream md;
  md << "# rcal experiment paper --sensors --sweep-seeds " << o.seeds << "\n\n"
     << "What sensor a user needs, over seeds: each configuration changes one thing from the "
        "baseline programme ("
     << o.num_cal << " calibration + " << o.num_test
     << " testing stops, the sensors of `rcal experiment paper --sensors`) and runs on "
     << seeds_text
     << ". Run i of configuration number k has its own seed 10000·k + i for the "
        "cell and the streams (the baseline's run i is `rcal experiment paper --sensors --seed "
        "i`), so no run depends on which others are made. Figure: mean position error of the "
        "online EKF's model against the truth on the run's testing poses; Cramér–Rao: the error "
        "the run's own window covariances allow on the same poses.\n\n"
     << compact_table << "\n## Every configuration\n\n"
     << full_table << "\n![sweep](sweep_seeds.png)\n\n"
     << "Failed runs (fewer than 6 calibration windows) are counted, not in the statistics. "
     << "Whole sweep: " << Fmt(runtime_s, 0) << " s with " << o.jobs << " jobs, " << Fmt(cpu_s, 0)
     << " s of CPU.\n";
  io::AtomicWriteFile(out / "report.md", md.str());

  json configs = json::array();
  for (const auto& row : rows) {
    json runs = json::array();
    for (const auto& r : row.runs)
      runs.push_back(
          {{"seed_index", r.seed_index},
           {"seed", r.seed},
           {"ok", r.ok},
           {"test_mean_position_error_m", r.ok ? json(r.test_position_m) : json()},
           {"test_mean_orientation_error_rad", r.ok ? json(r.test_orientation_rad) : json()},
           {"crb_test_mean_position_error_m", r.ok ? json(r.crb_position_m) : json()},
           {"crb_test_mean_orientation_error_rad", r.ok ? json(r.crb_orientation_rad) : json()},
           {"window_mean_position_error_m", r.window_position_m},
           {"window_mean_orientation_error_rad", r.window_orientation_rad},
           {"window_mean_nees", r.window_nees},
           {"cal_windows", r.cal_windows},
           {"ekf_rejected", r.rejected},
           {"wall_time_s", r.wall_s},
           {"cpu_time_s", r.cpu_s}});
    const auto& s = row.config->settings;
    configs.push_back({{"id", row.config->id},
                       {"number", row.config->number},
                       {"factor", row.config->factor},
                       {"value", row.config->value},
                       {"settings",
                        {{"num_cal_poses", s.num_cal},
                         {"num_test_poses", s.num_test},
                         {"noise_scale", s.noise_scale},
                         {"still_time_s", s.still_time},
                         {"gyro_bias", s.gyro_bias},
                         {"mag_disturbance", s.mag_disturbance},
                         {"position_dropout_probability", s.dropout}}},
                       {"failed_runs", row.failed},
                       {"test_mean_position_error_m", SpreadJson(row.test_position)},
                       {"test_mean_orientation_error_rad", SpreadJson(row.test_orientation)},
                       {"crb_test_mean_position_error_m", SpreadJson(row.crb_position)},
                       {"ekf_to_crb_ratio", SpreadJson(row.ratio)},
                       {"window_mean_nees", SpreadJson(row.nees)},
                       {"runs", runs}});
  }
  const json j = {{"robot", robot.model.name()},
                  {"mode", "sensors_seed_sweep"},
                  {"seeds", o.seeds},
                  {"first_seed_index", o.first_seed},
                  {"seed_rule", "run seed = 10000 * configuration number + seed index"},
                  {"statistics", "median, p10/p90, q25/q75: Hyndman-Fan type 7 over the runs"},
                  {"jobs", o.jobs},
                  {"wall_time_s", runtime_s},
                  {"cpu_time_s", cpu_s},
                  {"configurations", configs}};
  io::AtomicWriteFile(out / "results.json", j.dump(2));
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));

  std::printf(
      "\nrcal experiment paper --sensors --sweep-seeds %d — %s, %zu runs, %.0f s (%.0f s CPU)\n\n"
      "%s\n%s",
      o.seeds, seeds_text.c_str(), total, runtime_s, cpu_s, compact_table.c_str(),
      full_table.c_str());
  std::printf("  report: %s\n", (out / "report.md").c_str());
  return 0;
}

}  // namespace rcal::tool::exp
