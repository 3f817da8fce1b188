// rcal position-kf-sweep [--seeds N] [--cell NAME] [--rate HZ] [--taps] [--broad] [--banks-only]
// [--json FILE]:
// how estimation::AccelerometerDrivenSettings() were chosen, and why position_kf runs the bank of
// it and the paper's model (estimation::PositionKfBank of DefaultBankModels, the last candidates)
// by default with the accelerometer gate kBankAccelGateChi2, rerun. The simulated cells' own
// streams (GRB3016 demo, 0.5 mm tracker; Panda, 30 µm) at two tracker rates (20, 100 Hz), with the
// IMU at the marker and 14 cm off it (told to the filter), from a navigation-grade IMU (the cells'
// own) and a consumer-grade one (10× gyro noise, 5× accelerometer noise, constant and walking
// biases), each with N seeds; the orientation KF on the IMU as orientation_kf runs it, and the
// position KF told the true R_WE. With --taps each simulated case has a tapped copy too
// (sim::ImuTaps' defaults: 30–70 m/s², one sample or ringing for 80 ms, every 2 s on average,
// seeded by the case), the taps added to the IMU's accelerometer before the orientation KF and the
// position KFs read it; the accelerometer gate and the rollback are for them. Every 100 Hz estimate
// is scored against the simulated marker while it moves (faster than 5 cm/s) and at the tracker's
// samples, after the first 5 s. With
// --broad, the BROAD trials in ../shared/data/broad are cases too (real IMU and optical truth; a 1
// mm-per-axis tracker simulated from the truth at 20 Hz, N seeds; the lever arm estimated, as rcal
// fuse does; scored at every row after 5 s). The grid: the accelerometer-driven model with a bias
// state, σ × bias walk, with and without the adaptive noise, and the bank, ungated and with the
// accelerometer's χ² gate at three quantiles; the reference: the paper's filter (white jerk, no
// bias, σ 0.3 m/s²). The choice is the minimax of the RMSE ratio to the paper's over every case,
// a tie (candidates that differ only where they are not the worst) broken by the geometric mean
// ratio; each leave-one-group-out
// fold (an IMU class, real or simulated data, a cell, a rate or the taps left out) chooses on the
// rest and is scored on what it left out. Not a timed benchmark: the figures are errors.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <stdexcept>

#include "command.hpp"
#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/numeric/median.hpp"
#include "rcal/sim/imu_taps.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "report.hpp"

namespace rcal::tool {
namespace {

using nlohmann::json;

struct Options {
  int seeds = 3;
  bool broad = false;
  bool taps = false;                          // tapped copies of the simulated cases (sim::ImuTaps)
  std::vector<double> rates = {20.0, 100.0};  // the tracker's rates [Hz]
  std::vector<std::string> cells = {"grb3016", "panda"};  // simulated cells (config/cells/NAME)
  std::vector<std::string> broad_trials;                  // empty: every trial
  bool banks_only = false;  // the paper's filter and the bank's gates only
  std::string json_path;
};

struct Case {
  std::string imu, cell;  // imu "BROAD": cell is the trial's file
  double rate_hz = 20;
  bool lever = false;
  unsigned seed = 1;
  bool taps = false;  // the IMU is tapped (sim::ImuTaps)
};

// One filter's figures on one case [m].
struct Score {
  double moving = 0, at_samples = 0, nees = 0;
};

struct Config {
  double accel_sigma = 0.3, bias_walk = 0.0;  // bias_walk 0: the paper's motion model, no bias
  double adapt_tau = 0.0;                     // the adaptive accelerometer noise's τ [s]; 0: off
  double relative_sigma = 0.0;                // the motion-proportional accelerometer noise [-]
  bool bank = false;  // estimation::PositionKfBank of DefaultBankModels (the fields above unused)
  double accel_gate = 0.0;  // the bank's accelerometer χ² gate (accel_gate_chi2); 0: off
  std::string Name() const {
    if (bank)
      return "bank (paper + accelerometer-driven)" +
             (accel_gate > 0.0 ? " gate " + Fmt(accel_gate, 2) : std::string());
    std::string n =
        bias_walk == 0.0
            ? "paper" + (accel_sigma == 0.3 ? std::string() : " sigma " + Fmt(accel_sigma, 2))
            : "sigma " + Fmt(accel_sigma, 2) + " walk " + Fmt(bias_walk, 2);
    if (relative_sigma > 0.0) n += " relative " + Fmt(relative_sigma, 2);
    return adapt_tau > 0.0 ? n + " adaptive " + Fmt(adapt_tau, 2) + " s" : n;
  }
};

// A candidate in the JSON: its settings (the bank's models are DefaultBankModels).
json ConfigJson(const Config& c) {
  return {{"bank", c.bank},
          {"accel_gate_chi2", c.accel_gate},
          {"accel_sigma", c.accel_sigma},
          {"accel_bias_walk", c.bias_walk},
          {"accel_noise_adaptation_tau_s", c.adapt_tau},
          {"accel_relative_sigma", c.relative_sigma}};
}

// The accelerometer-driven filter's σ × bias walk with a constant noise, the adaptive noise
// (position_kf.hpp) on the neighbourhood of the earlier choice, the paper's filter with it, and
// the bank with four accelerometer gates (estimation::kBankAccelGateChi2 is the choice).
std::vector<Config> Grid() {
  std::vector<Config> g;
  for (double w : {0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 1.0})
    for (double s : {0.01, 0.03, 0.1, 0.3, 1.0, 3.0}) g.push_back({s, w});
  for (double tau : {0.1, 0.3})
    for (double rel : {0.0, 0.1}) {
      for (double w : {0.03, 0.1, 0.3})
        for (double s : {0.03, 0.1, 0.3, 1.0}) g.push_back({s, w, tau, rel});
      for (double s : {0.3, 1.0}) g.push_back({s, 0.0, tau, rel});
    }
  // The bank, ungated and with the accelerometer's χ² gate at the 0.99, 0.999 and 0.9999 quantiles
  // of χ²(3) (a tap is one sample far beyond what the motion can have; PositionKfSettings).
  for (double gate : {0.0, 11.34, 16.27, 21.11}) {
    Config bank;
    bank.bank = true;
    bank.accel_gate = gate;
    g.push_back(bank);
  }
  return g;
}

// The filter of c; `frame` sets what the case fixes (frames, σ, lever arm) on its settings.
estimation::PositionKfBank FilterFor(
    const Config& c, const std::function<void(estimation::PositionKfSettings*)>& frame) {
  if (c.bank) {
    estimation::PositionKfSettings base;
    frame(&base);
    estimation::PositionKfBankSettings bs;
    bs.models = estimation::DefaultBankModels(base);
    for (estimation::PositionKfSettings& m : bs.models) m.accel_gate_chi2 = c.accel_gate;
    return estimation::PositionKfBank(bs);
  }
  estimation::PositionKfSettings s;
  if (c.bias_walk > 0.0) {
    s = estimation::AccelerometerDrivenSettings();
    s.accel_bias_walk = c.bias_walk;
  }
  s.accel_sigma = c.accel_sigma;
  s.accel_noise_adaptation_tau = c.adapt_tau;
  s.accel_relative_sigma = c.relative_sigma;
  frame(&s);
  return estimation::PositionKfBank(s);
}

// RMS of the summed squares (moving or every row; at the samples) and the mean NEES, per filter.
std::vector<Score> Scores(const std::vector<double>& ss_m, int n_m, const std::vector<double>& ss_s,
                          int n_s, const std::vector<double>& nees, int n) {
  std::vector<Score> out;
  for (size_t i = 0; i < ss_m.size(); ++i)
    out.push_back({std::sqrt(ss_m[i] / std::max(n_m, 1)), std::sqrt(ss_s[i] / std::max(n_s, 1)),
                   nees[i] / std::max(n, 1)});
  return out;
}

// A BROAD trial: its IMU rows through the orientation KF, a 1 mm tracker simulated from the optical
// truth at 20 Hz, every filter estimating the lever arm; scored at every row after 5 s.
std::vector<Score> RunBroad(const Case& k, const std::vector<Config>& configs) {
  const auto table = io::CsvTable::Load(k.cell);
  estimation::OrientationKfSettings os;
  os.earth = estimation::EarthFrame::kEnu;
  estimation::OrientationKf okf(os);
  std::vector<estimation::PositionKfBank> kfs;
  for (const Config& c : configs)
    kfs.push_back(FilterFor(c, [&](estimation::PositionKfSettings* ps) {
      ps->earth = os.earth;
      ps->estimate_lever_arm = true;
    }));
  std::mt19937_64 rng(k.seed);
  std::normal_distribution<double> N(0.0, 1e-3);
  std::vector<double> ss(configs.size()), ss_s(configs.size()), nees(configs.size());
  int n = 0, n_s = 0;
  double next_t = -INFINITY;
  for (int r = 0; r < table.rows(); ++r) {
    auto c = [&](const char* name) { return table.At(r, name); };
    const double t = c("t_s");
    const Eigen::Vector3d g(c("gyr_x"), c("gyr_y"), c("gyr_z")),
        f(c("acc_x"), c("acc_y"), c("acc_z")), m(c("mag_x"), c("mag_y"), c("mag_z"));
    if (!okf.Update(t, g, f, 1e-6 * m) || !okf.initialized()) continue;
    const Eigen::Vector3d p(c("pos_x"), c("pos_y"), c("pos_z"));
    const bool sample = p.allFinite() && t >= next_t - 1e-9;
    Eigen::Vector3d z = p;
    if (sample) {
      next_t = (std::isfinite(next_t) ? next_t : t) + 0.05;
      z += Eigen::Vector3d(N(rng), N(rng), N(rng));
    }
    const bool scored = t >= 5.0 && p.allFinite();
    for (size_t i = 0; i < kfs.size(); ++i) {
      (void)kfs[i].UpdateAccel(t, f, okf.R_EB(), g - okf.bias_B());
      if (sample) (void)kfs[i].UpdatePosition(t, z);
      if (!scored || !kfs[i].initialized()) continue;
      const Eigen::Vector3d e = kfs[i].p_WM_W() - p;
      ss[i] += e.squaredNorm();
      if (sample) ss_s[i] += e.squaredNorm();
      nees[i] += e.dot(kfs[i].position_covariance().ldlt().solve(e));
    }
    if (scored && kfs.front().initialized()) {
      ++n;
      n_s += sample;
    }
  }
  return Scores(ss, n, ss_s, n_s, nees, n);
}

// Runs every configuration on one case (one simulated stream, one orientation KF).
std::vector<Score> RunCase(const Case& k, const std::vector<Config>& configs) {
  if (k.imu == "BROAD") return RunBroad(k, configs);
  const std::string base = ResolvePath("config/cells/" + k.cell);
  const io::BuiltCell built = io::LoadCell(base + ".yaml");
  if (!built.spec.imu) throw std::runtime_error("--cell " + k.cell + ": the cell has no IMU");
  cell::CellSimSpec spec = cell::LoadCellSimSpec(base + ".sim.yaml");
  if (k.lever) spec.imu_to_marker_I = Eigen::Vector3d(0.1, -0.05, 0.08);
  const cell::SimProgramme prog = cell::MakeSimProgramme(built, spec, k.seed, 16, 0);
  sim::SensorSimSettings ss = cell::SimSensorSettings(built, spec);
  ss.position.rate_hz = k.rate_hz;
  estimation::OrientationKfSettings os;
  os.earth = built.spec.imu->earth;
  os.gravity = built.spec.imu->gravity;
  if (k.imu == "consumer-grade") {
    ss.imu.gyro_noise_density *= 10;
    ss.imu.accel_noise_density *= 5;
    ss.imu.constant_bias = true;
    ss.imu.gyro_bias = Eigen::Vector3d(0.004, -0.003, 0.005);
    ss.imu.accel_bias = Eigen::Vector3d(0.05, -0.03, 0.04);
    ss.imu.bias_random_walk = true;
    os.gyro_noise_density = ss.imu.gyro_noise_density;
  }
  sim::SensorSim sensors(prog.truth, ss, k.seed);
  // --taps (sim::ImuTaps' defaults), on a stream of their own: the sensors' draws stay those of
  // the untapped twin, so the two cases differ by the taps alone.
  sim::ImuTaps taps(0x7a95'0000ULL + k.seed);
  estimation::OrientationKf okf(os);
  const Eigen::Matrix3d R_IS = built.spec.imu->R_IS;
  std::vector<estimation::PositionKfBank> kfs;
  for (const Config& c : configs) {
    kfs.push_back(FilterFor(c, [&](estimation::PositionKfSettings* ps) {
      ps->earth = os.earth;
      ps->gravity = os.gravity;
      ps->position_sigma = built.spec.position.sigma.maxCoeff();
      if (k.lever) ps->lever_arm_B = prog.truth.imu_to_marker_I();
    }));
    (void)kfs.back().SetWorldFromEarth(prog.truth.R_EW().transpose());
  }
  std::vector<double> ss_m(configs.size()), ss_s(configs.size()), nees(configs.size());
  int n_m = 0, n_s = 0, n = 0;
  while (auto f = sensors.Next()) {
    const Eigen::Vector3d g = R_IS * f->imu.gyro_S, m = R_IS * f->imu.mag_S * 1e-6;
    Eigen::Vector3d a = R_IS * f->imu.accel_S;
    if (k.taps) a += taps.At(f->t);
    (void)okf.Update(f->t, g, a, m);
    if (!okf.initialized()) continue;
    const bool moving = f->truth.v_WM_W.norm() > 0.05;
    const bool scored = f->t >= 5.0;
    for (size_t i = 0; i < kfs.size(); ++i) {
      estimation::PositionKfBank& kf = kfs[i];
      (void)kf.UpdateAccel(f->t, a, okf.R_EB(), g - okf.bias_B());
      if (f->position) (void)kf.UpdatePosition(f->t, f->position->p_M);
      if (!scored || !kf.initialized()) continue;
      const Eigen::Vector3d e = kf.p_WM_W() - f->truth.p_WM_W;
      if (moving) ss_m[i] += e.squaredNorm();
      if (f->position) ss_s[i] += e.squaredNorm();
      nees[i] += e.dot(kf.position_covariance().ldlt().solve(e));
    }
    if (scored && kfs.front().initialized()) {
      n_m += moving;
      n_s += f->position.has_value();
      ++n;
    }
  }
  return Scores(ss_m, n_m, ss_s, n_s, nees, n);
}

using numeric::Median;

int Run(const Options& o) {
  // Untapped, and with --taps tapped too: the simulated cases' and the table's groups.
  const std::vector<bool> tapping =
      o.taps ? std::vector<bool>{false, true} : std::vector<bool>{false};
  std::vector<Case> cases;
  for (const char* imu : {"navigation-grade", "consumer-grade"})
    for (const std::string& cell : o.cells)
      for (double rate : o.rates)
        for (bool lever : {false, true})
          for (bool taps : tapping)
            for (int s = 1; s <= o.seeds; ++s)
              cases.push_back({imu, cell, rate, lever, static_cast<unsigned>(s), taps});
  if (o.broad || !o.broad_trials.empty()) {
    std::vector<std::string> trials;
    for (const std::string& t : o.broad_trials) trials.push_back(ResolvePath(t));
    if (trials.empty())
      for (const auto& e : std::filesystem::directory_iterator(ResolvePath("../shared/data/broad")))
        if (e.path().extension() == ".csv") trials.push_back(e.path().string());
    std::sort(trials.begin(), trials.end());
    for (const std::string& trial : trials)
      for (int s = 1; s <= o.seeds; ++s)
        cases.push_back({"BROAD", trial, 20.0, true, static_cast<unsigned>(s)});
  }
  std::vector<Config> configs = {Config{}};  // the paper's first
  for (const Config& c : Grid())
    if (c.bank || !o.banks_only) configs.push_back(c);
  std::vector<std::vector<Score>> scores;  // [case][config]
  for (size_t k = 0; k < cases.size(); ++k) {
    scores.push_back(RunCase(cases[k], configs));
    std::fprintf(stderr, "\r  case %zu / %zu", k + 1, cases.size());
  }
  std::fprintf(stderr, "\n");
  // ratio[case][config] of the RMSE in motion to the paper's.
  auto ratio = [&](size_t k, size_t c) { return scores[k][c].moving / scores[k][0].moving; };
  auto worst = [&](size_t c, const std::vector<size_t>& ks) {
    double w = 0;
    for (size_t k : ks) w = std::max(w, ratio(k, c));
    return w;
  };
  // The geometric mean of the ratios: what breaks a tie of the worst ratio (candidates that differ
  // only where they are not the worst, e.g. the accelerometer gate, which leaves every sample it
  // does not refuse unchanged).
  auto geomean = [&](size_t c, const std::vector<size_t>& ks) {
    double s = 0;
    for (size_t k : ks) s += std::log(ratio(k, c));
    return ks.empty() ? 1.0 : std::exp(s / static_cast<double>(ks.size()));
  };
  // The minimax of the ratio to the paper's, ties broken by the geometric mean, among the
  // candidates `among` takes. The paper's filter is a candidate too (its ratio is 1 on every case).
  auto choose_among = [&](const std::vector<size_t>& ks, const std::function<bool(size_t)>& among) {
    std::optional<size_t> best;
    for (size_t c = 0; c < configs.size(); ++c) {
      if (!among(c)) continue;
      if (!best) {
        best = c;
        continue;
      }
      const double w = worst(c, ks), wb = worst(*best, ks);
      if (w < wb || (w == wb && geomean(c, ks) < geomean(*best, ks))) best = c;
    }
    return best.value_or(0);
  };
  auto choose = [&](const std::vector<size_t>& ks) {
    return choose_among(ks, [](size_t) { return true; });
  };
  std::vector<size_t> all(cases.size());
  for (size_t k = 0; k < all.size(); ++k) all[k] = k;
  const size_t chosen = choose(all);
  std::vector<size_t> simulated;
  for (size_t k = 0; k < cases.size(); ++k)
    if (cases[k].imu != "BROAD") simulated.push_back(k);
  const size_t chosen_sim = simulated.empty() ? 0 : choose(simulated);
  std::printf("chosen (minimax over %zu cases): %s, worst ratio to the paper's %s\n", all.size(),
              configs[chosen].Name().c_str(), Fmt(worst(chosen, all), 3).c_str());
  // The accelerometer-driven filter's own settings (AccelerometerDrivenSettings, position_kf
  // --motion-model accelerometer-driven): the same minimax among its candidates alone, with the
  // median ratio on the real and on the simulated cases beside it.
  const size_t chosen_driven =
      choose_among(all, [&](size_t c) { return configs[c].bias_walk > 0.0; });
  auto median_ratio = [&](size_t c, bool real) {
    std::vector<double> r;
    for (size_t k = 0; k < cases.size(); ++k)
      if ((cases[k].imu == "BROAD") == real) r.push_back(ratio(k, c));
    return r.empty() ? 1.0 : Median(r);
  };
  // (With --banks-only it has no candidates of its own: nothing to say.)
  if (!o.banks_only)
    std::printf(
        "the accelerometer-driven filter's (minimax among its candidates): %s, worst ratio %s, "
        "median %s on the simulated cases and %s on the real ones\n",
        configs[chosen_driven].Name().c_str(), Fmt(worst(chosen_driven, all), 3).c_str(),
        Fmt(median_ratio(chosen_driven, false), 3).c_str(),
        Fmt(median_ratio(chosen_driven, true), 3).c_str());
  // The bank of the two models (position_kf --motion-model bank), ungated and gated: each, and the
  // choice among them (its accelerometer gate: estimation::kBankAccelGateChi2).
  // With --taps, each bank's figures on the tapped cases alone too: the gate is for them.
  std::vector<size_t> tapped;
  for (size_t k = 0; k < cases.size(); ++k)
    if (cases[k].taps) tapped.push_back(k);
  json banks = json::array();
  for (size_t c = 1; c < configs.size(); ++c) {
    if (!configs[c].bank) continue;
    std::printf(
        "%s: worst ratio %s, geometric mean %s, median %s on the simulated cases and %s on the "
        "real ones",
        configs[c].Name().c_str(), Fmt(worst(c, all), 3).c_str(), Fmt(geomean(c, all), 4).c_str(),
        Fmt(median_ratio(c, false), 3).c_str(), Fmt(median_ratio(c, true), 3).c_str());
    json b = ConfigJson(configs[c]);
    b["worst_ratio"] = worst(c, all);
    b["geometric_mean_ratio"] = geomean(c, all);
    if (!tapped.empty()) {
      std::printf("; on the tapped cases worst %s, geometric mean %s",
                  Fmt(worst(c, tapped), 3).c_str(), Fmt(geomean(c, tapped), 4).c_str());
      b["tapped_worst_ratio"] = worst(c, tapped);
      b["tapped_geometric_mean_ratio"] = geomean(c, tapped);
    }
    std::printf("\n");
    banks.push_back(b);
  }
  const auto is_bank = [&](size_t c) { return configs[c].bank; };
  const size_t bank = choose_among(all, is_bank);
  std::printf("the bank's choice: %s\n", configs[bank].Name().c_str());
  // Seed by seed, the same choice on that seed's cases alone: how often each bank wins says
  // whether the choice is more than one draw of the noise.
  std::map<std::string, int> seed_wins;
  for (int s = 1; s <= o.seeds; ++s) {
    std::vector<size_t> ks;
    for (size_t k = 0; k < cases.size(); ++k)
      if (cases[k].seed == static_cast<unsigned>(s)) ks.push_back(k);
    ++seed_wins[configs[choose_among(ks, is_bank)].Name()];
  }
  json bank_seed_wins = json::object();
  std::printf("the bank's choice seed by seed (%d seeds):", o.seeds);
  for (const auto& [name, n] : seed_wins) {
    std::printf(" %s %d;", name.c_str(), n);
    bank_seed_wins[name] = n;
  }
  std::printf("\n\n");

  // The table: medians over seeds and lever arms.
  std::vector<std::vector<std::string>> table;
  json groups = json::array();
  for (bool taps : tapping)
    for (const char* imu : {"navigation-grade", "consumer-grade"})
      for (const std::string& cell : o.cells)
        for (double rate : o.rates) {
          std::vector<double> pm, ps, cm, cs, ne;
          for (size_t k = 0; k < cases.size(); ++k) {
            if (cases[k].imu != imu || cases[k].cell != cell || cases[k].rate_hz != rate ||
                cases[k].taps != taps)
              continue;
            pm.push_back(scores[k][0].moving * 1e3);
            ps.push_back(scores[k][0].at_samples * 1e3);
            cm.push_back(scores[k][chosen].moving * 1e3);
            cs.push_back(scores[k][chosen].at_samples * 1e3);
            ne.push_back(scores[k][chosen].nees);
          }
          table.push_back({imu, cell + (taps ? ", tapped" : ""), Fmt(rate, 0) + " Hz",
                           Fmt(Median(pm)) + " / " + Fmt(Median(ps)),
                           Fmt(Median(cm)) + " / " + Fmt(Median(cs)), Fmt(Median(ne), 2)});
          groups.push_back({{"imu", imu},
                            {"cell", cell},
                            {"taps", taps},
                            {"tracker_rate_hz", rate},
                            {"paper_moving_rmse_m", Median(pm) * 1e-3},
                            {"paper_at_samples_rmse_m", Median(ps) * 1e-3},
                            {"chosen_moving_rmse_m", Median(cm) * 1e-3},
                            {"chosen_at_samples_rmse_m", Median(cs) * 1e-3},
                            {"chosen_nees", Median(ne)}});
        }
  if (simulated.size() < cases.size()) {
    // BROAD: every row scored (its truth has no "in motion" of the simulator's kind); the paper's,
    // the choice over everything, and the choice over the simulated cases alone.
    std::vector<double> pm, cm, sm;
    for (size_t k = 0; k < cases.size(); ++k) {
      if (cases[k].imu != "BROAD") continue;
      pm.push_back(scores[k][0].moving * 1e3);
      cm.push_back(scores[k][chosen].moving * 1e3);
      sm.push_back(scores[k][chosen_sim].moving * 1e3);
    }
    const double sm_worst = *std::max_element(sm.begin(), sm.end());
    table.push_back({"BROAD (real)", std::to_string(pm.size()) + " trial runs", "20 Hz",
                     Fmt(Median(pm)) + " (every row)",
                     Fmt(Median(cm)) + " (every row); the simulated cases' choice " +
                         Fmt(Median(sm)) + ", worst " + Fmt(sm_worst),
                     "–"});
    groups.push_back({{"imu", "BROAD"},
                      {"paper_moving_rmse_m", Median(pm) * 1e-3},
                      {"chosen_moving_rmse_m", Median(cm) * 1e-3},
                      {"simulated_choice_moving_rmse_m", Median(sm) * 1e-3},
                      {"simulated_choice_worst_rmse_m", sm_worst * 1e-3}});
  }
  std::printf("%s\n",
              MdTable({"IMU", "cell", "tracker rate", "the paper's: in motion / at samples [mm]",
                       "chosen: in motion / at samples [mm]", "NEES"},
                      table)
                  .c_str());

  // Leave one group out.
  std::vector<std::vector<std::string>> folds_table;
  json folds = json::array();
  const std::vector<std::pair<std::string, std::function<std::string(const Case&)>>> keys = {
      {"imu", [](const Case& c) { return c.imu; }},
      {"data", [](const Case& c) { return std::string(c.imu == "BROAD" ? "BROAD" : "simulated"); }},
      {"cell",
       [](const Case& c) {
         return c.imu == "BROAD" ? std::filesystem::path(c.cell).filename().string() : c.cell;
       }},
      {"rate", [](const Case& c) { return Fmt(c.rate_hz, 0) + " Hz"; }},
      {"taps", [](const Case& c) { return std::string(c.taps ? "tapped" : "untapped"); }}};
  for (const auto& [key, of] : keys) {
    std::map<std::string, int> values;
    for (const Case& c : cases) values[of(c)] = 1;
    for (const auto& [held, unused] : values) {
      std::vector<size_t> train, test;
      for (size_t k = 0; k < cases.size(); ++k) (of(cases[k]) == held ? test : train).push_back(k);
      if (train.empty()) continue;  // one value only: nothing to choose on
      const size_t c = choose(train);
      folds_table.push_back(
          {key + " = " + held, configs[c].Name(), Fmt(worst(c, train), 3), Fmt(worst(c, test), 3)});
      json fold = ConfigJson(configs[c]);
      fold["left_out"] = key + " = " + held;
      fold["train_worst_ratio"] = worst(c, train);
      fold["held_out_worst_ratio"] = worst(c, test);
      folds.push_back(fold);
    }
  }
  std::printf("%s", MdTable({"left out", "chosen on the rest", "worst ratio to the paper's, rest",
                             "worst ratio, left out"},
                            folds_table)
                        .c_str());
  json chosen_simulated = ConfigJson(configs[chosen_sim]);
  chosen_simulated["worst_ratio"] = simulated.empty() ? 1.0 : worst(chosen_sim, simulated);
  json chosen_all = ConfigJson(configs[chosen]);
  chosen_all["worst_ratio"] = worst(chosen, all);
  json driven = nullptr;  // null with --banks-only
  if (!o.banks_only) {
    driven = ConfigJson(configs[chosen_driven]);
    driven["worst_ratio"] = worst(chosen_driven, all);
    driven["median_ratio_simulated"] = median_ratio(chosen_driven, false);
    driven["median_ratio_real"] = median_ratio(chosen_driven, true);
  }
  // The bank's choice among its gates: its worst and median ratios, as the driven filter's.
  json bank_json = ConfigJson(configs[bank]);
  bank_json["worst_ratio"] = worst(bank, all);
  bank_json["median_ratio_simulated"] = median_ratio(bank, false);
  bank_json["median_ratio_real"] = median_ratio(bank, true);
  bank_json["geometric_mean_ratio"] = geomean(bank, all);
  // Every case's RMSE in motion [m]: the paper's, the choice's and each bank's.
  json case_scores = json::array();
  for (size_t k = 0; k < cases.size(); ++k) {
    json banks_k = json::object();
    for (size_t c = 1; c < configs.size(); ++c)
      if (configs[c].bank) banks_k[Fmt(configs[c].accel_gate, 2)] = scores[k][c].moving;
    case_scores.push_back({{"imu", cases[k].imu},
                           {"cell", cases[k].cell},
                           {"tracker_rate_hz", cases[k].rate_hz},
                           {"lever_arm", cases[k].lever},
                           {"taps", cases[k].taps},
                           {"seed", cases[k].seed},
                           {"paper_moving_rmse_m", scores[k][0].moving},
                           {"chosen_moving_rmse_m", scores[k][chosen].moving},
                           {"bank_moving_rmse_m_by_gate", banks_k}});
  }
  const json j = {{"seeds", o.seeds},
                  {"cases", cases.size()},
                  {"chosen_simulated", chosen_simulated},
                  {"chosen", chosen_all},
                  {"chosen_accelerometer_driven", driven},
                  {"bank", bank_json},
                  {"banks", banks},
                  {"bank_seed_wins", bank_seed_wins},
                  {"groups", groups},
                  {"folds", folds},
                  {"case_scores", case_scores}};
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  return 0;
}

const RegisterCommand kPositionKfSweep(
    "position-kf-sweep",
    "The position KF's motion models (accelerometer-driven σ, bias walk, adaptive noise; the "
    "bank of two) against the paper's filter: "
    "simulated cells and BROAD, minimax and leave-one-group-out",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--seeds", o->seeds, "seeds per case")
          ->check(cli::Range(1, 100))
          ->capture_default_str();
      sub.add_flag(
          "--broad", o->broad,
          "add the BROAD trials of ../shared/data/broad (real IMU streams, optical truth)");
      sub.add_flag("--taps", o->taps,
                   "add a tapped copy of every simulated case (shocks of 30–70 m/s², one sample or "
                   "ringing for 80 ms, every 2 s on average)");
      sub.add_option("--rate", o->rates, "the simulated tracker's rates [Hz]")
          ->check(cli::Range(1.0, 1000.0))
          ->capture_default_str();
      sub.add_option("--cell", o->cells, "simulated cells (config/cells/NAME.yaml and .sim.yaml)")
          ->capture_default_str();
      sub.add_option("--broad-trial", o->broad_trials,
                     "these BROAD trial files only (implies --broad)");
      sub.add_flag("--banks-only", o->banks_only,
                   "the paper's filter and the bank's four accelerometer gates only (to settle "
                   "the gate on more seeds)");
      sub.add_option("--json", o->json_path, "write the figures here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
