// rcal detection-sweep-imu --seeds N --json FILE: how often the IMU-stream analysis of rcal analyze
// names a hidden IMU effect (right cause) and how often it reports one that is not there, over a
// seeded sweep of simulated streams (sim/imu_stream.hpp: 4 rests and 3 motions of 15 s at 100 Hz,
// the simulator's noise, a constant gyro bias, the positions read by an optical tracker of
// 0.1 mm; one effect per stream at magnitudes around the detection floor). Not a timed
// benchmark: the figures are rates.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>

#include "command.hpp"
#include "rcal/discrepancy/imu_analysis.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/sim/draw.hpp"
#include "rcal/sim/imu_stream.hpp"
#include "report.hpp"

namespace rcal::tool {
namespace {

namespace disc = rcal::discrepancy;
using nlohmann::json;

struct Options {
  int seeds = 50;
  unsigned first_seed = 5000;
  std::string json_path;
  double alpha = 0.01;
};

// One cell of the sweep: the hidden cause ("" for clean streams), its size and unit for the table,
// and the causes the hidden one implies (not counted as another cause): a time offset of the whole
// IMU is its accelerometer late behind the positions too (accel_lag); an accelerometer lag is only
// seen while the tool accelerates (accel_motion).
struct Cell {
  std::string cause, label;
  sim::ImuStreamEffects effects;
  std::vector<std::string> implied = {};
};

std::vector<Cell> Cells() {
  std::vector<Cell> cells{{"", "clean stream", {}}};
  for (double k : {5e-5, 1e-4, 2e-4}) {
    Cell c{"gyro_bias", "gyro bias walk " + Fmt(k * 1e6, 0) + "e-6 rad/s/√s (z)", {}};
    c.effects.gyro_bias_random_walk = Eigen::Vector3d(0.0, 0.0, k);
    cells.push_back(c);
  }
  for (double uT : {3.0, 5.0, 8.0}) {
    Cell c{"magnetic_disturbance", "magnet " + Fmt(uT, 0) + " µT for 8 s", {}};
    c.effects.mag_disturbance = true;
    c.effects.mag_disturbance_start_s = 20.0;  // inside the first motion (15–30 s)
    c.effects.mag_disturbance_end_s = 28.0;
    c.effects.mag_disturbance_uT = Eigen::Vector3d(uT, 0.0, 0.0);
    cells.push_back(c);
  }
  for (double a : {0.05, 0.1, 0.3}) {
    Cell c{"accel_motion", "linear acceleration " + Fmt(a, 2) + " m/s²", {}};
    c.effects.linear_accel = a;
    cells.push_back(c);
  }
  for (double ms : {1.0, 2.0, 4.0}) {
    Cell c{"time_offset", "time offset " + Fmt(ms, 0) + " ms", {}, {"accel_lag"}};
    c.effects.time_offset_s = ms * 1e-3;
    cells.push_back(c);
  }
  for (double ms : {1.0, 2.0, 4.0}) {
    Cell c{"accel_lag", "accelerometer lag " + Fmt(ms, 0) + " ms (3 m/s²)", {}, {"accel_motion"}};
    c.effects.linear_accel = 3.0;
    c.effects.accel_delay_s = ms * 1e-3;
    cells.push_back(c);
  }
  return cells;
}

constexpr double kTrackerSigma = 1e-4;  // the optical tracker's noise per axis [m]

int Run(const Options& o) {
  sim::ImuStreamSettings ss;
  ss.motion_segments = 3;
  ss.rest_s = 15.0;
  ss.motion_s = 15.0;
  ss.imu.constant_bias = true;  // the base model allows a constant gyro bias
  ss.imu.gyro_bias = Eigen::Vector3d(0.002, -0.001, 0.003);
  disc::ImuAnalysisSettings as;
  as.alpha = o.alpha;
  // The analysis narrates each run at info level; the sweep prints one line per cell instead.
  const auto level = spdlog::get_level();
  spdlog::set_level(spdlog::level::warn);

  std::vector<std::vector<std::string>> table;
  json rows = json::array();
  const auto cells = Cells();
  for (size_t k = 0; k < cells.size(); ++k) {
    const Cell& cell = cells[k];
    int found = 0, wrong = 0;
    for (int s = 0; s < o.seeds; ++s) {
      std::mt19937_64 rng(o.first_seed + 1000 * k + s);
      auto data = disc::FromSimulatedStream(sim::SimulateImuStream(ss, cell.effects, rng));
      std::normal_distribution<double> tracker(0.0, kTrackerSigma);
      for (auto& p : data.p_W) p += sim::Draw3(tracker, rng);
      const auto a = disc::AnalyzeImuStream(data, as);
      bool hit = false, other = false;
      for (const auto* e : a.effects()) {
        const bool implied =
            std::find(cell.implied.begin(), cell.implied.end(), e->cause) != cell.implied.end();
        if (e->cause == cell.cause)
          hit = true;
        else if (!implied)
          other = true;
      }
      found += hit;
      wrong += other;
    }
    std::fprintf(stderr, "  %-40s found %d / %d, other cause %d\n", cell.label.c_str(), found,
                 o.seeds, wrong);
    table.push_back({cell.label, cell.cause.empty() ? "–" : Fmt(100.0 * found / o.seeds, 0) + " %",
                     Fmt(100.0 * wrong / o.seeds, 0) + " %"});
    rows.push_back({{"cause", cell.cause},
                    {"label", cell.label},
                    {"runs", o.seeds},
                    {"found", found},
                    {"other_cause", wrong}});
  }
  spdlog::set_level(level);
  std::printf("%s", MdTable({"hidden effect", "named", "another cause reported"}, table).c_str());
  const json j = {
      {"seeds", o.seeds}, {"first_seed", o.first_seed}, {"alpha", o.alpha}, {"rows", rows}};
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  return 0;
}

const RegisterCommand kSweepImu(
    "detection-sweep-imu",
    "Detection and false-positive rates of the IMU-stream analysis on simulated streams",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--seeds", o->seeds, "streams per cell")->capture_default_str();
      sub.add_option("--first-seed", o->first_seed, "seed of the first stream")
          ->capture_default_str();
      sub.add_option("--alpha", o->alpha, "false-positive rate of the whole selection")
          ->capture_default_str();
      sub.add_option("--json", o->json_path, "write the rates here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
