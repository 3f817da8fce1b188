// rcal fuse TRIAL.csv: FQA, orientation KF and position KF on a BROAD trial (real IMU data with
// optical truth, ../shared/data/broad), scored as the BROAD benchmark scores (its README):
//   e = q_est ⊗ q_truth⁻¹ (both IMU → ENU), total = 2 acos|e_w|, heading = 2 atan|e_z/e_w|,
//   inclination = 2 acos √(e_w² + e_z²); RMSE over the samples with movement = 1 and finite truth.
// The position sensor is simulated from the truth position: decimated to --pos-rate Hz with
// --pos-noise m of white noise per axis (seeded), silent over --pos-occlusion's spans. Figures in
// files are SI (rad, m); the Markdown table printed for people is in degrees and millimetres;
// --trace writes every sample's estimates and errors.
#include <spdlog/spdlog.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "accel_lag_json.hpp"
#include "command.hpp"
#include "fuse_ins.hpp"
#include "fuse_settings.hpp"
#include "rcal/discrepancy/imu_scoring.hpp"
#include "rcal/estimation/accel_lag.hpp"
#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/fqa.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/imu_csv.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::tool {
namespace {

namespace est = rcal::estimation;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

struct FuseOptions {
  std::string trial;
  std::string out_dir;
  std::string json;
  std::string trace;  // per-sample estimates and errors (CSV)
  std::uint64_t seed = 1;
  double pos_rate_hz = 20.0;
  double pos_noise_m = 1e-3;
  // PERIOD, LENGTH [s]: the tracker silent for the first LENGTH of every PERIOD of the trial's
  // time (BroadTracker); empty: never.
  std::vector<double> pos_occlusion;
  std::vector<std::string> overrides;  // NAME=VALUE for the settings below
};

// --trace: per fused sample, the orientation estimate q_EB (IMU → ENU, w x y z), its BROAD errors
// [rad], the bank's marker position in the tracker's frame W (here ENU) [m] and its error [m],
// each bank filter's error alone [m], the accelerometer-driven filter's weight and its λ (the
// adaptive accelerometer-noise factor), and whether the orientation KF used this sample's
// accelerometer and magnetometer.
constexpr const char* kTraceHeader =
    "t_s,movement,q_EB_w,q_EB_x,q_EB_y,q_EB_z,total_error_rad,heading_error_rad,"
    "inclination_error_rad,p_WM_W_x_m,p_WM_W_y_m,p_WM_W_z_m,position_error_m,"
    "paper_model_error_m,accelerometer_driven_error_m,accelerometer_driven_weight,"
    "accelerometer_driven_noise_scale,accel_used,mag_used,ins_q_EB_w,ins_q_EB_x,ins_q_EB_y,"
    "ins_q_EB_z,ins_total_error_rad,ins_heading_error_rad,ins_inclination_error_rad,"
    "ins_p_WM_W_x_m,ins_p_WM_W_y_m,ins_p_WM_W_z_m,ins_position_error_m\n";

// BROAD scoring (discrepancy/imu_scoring.hpp, shared with `rcal analyze` on IMU streams).
using discrepancy::AngleErrors;
using discrepancy::BroadErrors;
using discrepancy::OrientationScore;
using discrepancy::Rms;

nlohmann::json ScoreJson(const OrientationScore& s) {
  return {{"total_rmse_rad", s.total.value()},
          {"heading_rmse_rad", s.heading.value()},
          {"inclination_rmse_rad", s.inclination.value()},
          {"samples", s.total.n}};
}

std::string Fixed(double v, int digits) {
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(digits);
  o << v;
  return o.str();
}

int RunFuse(const FuseOptions& opt) {
  // The settings first: a bad --set is refused before a trial is read.
  FuseSettings settings = BroadSettingsWith(opt.overrides, opt.pos_noise_m);
  const bool occluded = opt.pos_occlusion.size() == 2;
  if (occluded && !(opt.pos_occlusion[1] < opt.pos_occlusion[0]))
    throw std::runtime_error("fuse: --pos-occlusion: LENGTH " + Fixed(opt.pos_occlusion[1], 3) +
                             " s must be shorter than PERIOD " + Fixed(opt.pos_occlusion[0], 3) +
                             " s (the tracker would never see the marker)");
  const est::OrientationKfSettings& okf_settings = settings.orientation;
  const est::PositionKfSettings& pkf_settings = settings.position;
  const io::ImuCsvSettings& imu_settings = settings.imu;
  const std::string path = ResolvePath(opt.trial);
  // Every sample checked against the sensor ranges, time order and NaN before any is fused.
  const io::ImuCsv trial = io::LoadImuCsv(path, imu_settings);
  const int n = static_cast<int>(trial.t.size());
  if (n < 2) throw std::runtime_error("fuse: " + path + " has fewer than two rows");
  for (const auto& [has, what] : {std::pair{trial.has_truth, "truth quaternion q_w..q_z"},
                                  std::pair{trial.has_position, "truth position pos_x..pos_z"},
                                  std::pair{trial.has_movement, "movement"}})
    if (!has) throw std::runtime_error("fuse: " + path + ": missing the " + what + " columns");
  // A slow IMU's steps are not silences (fuse_settings.hpp): the filters' longest step from the
  // stream's own rate.
  const double imu_rate_hz = io::SampleRate(trial);
  SetMaxStepForRate(settings, imu_rate_hz);

  est::OrientationKf okf(okf_settings);
  // The position estimate: a bank (position_kf_bank.hpp) of the paper's motion model (these
  // settings) and position_kf's accelerometer-driven one (--motion-model accelerometer-driven: the
  // accelerometer drives the acceleration, a bias state, the adaptive noise), weighted by how well
  // each predicts the position sensor. Each is scored alone too.
  // The accelerometer-driven model with these settings' frame, gravity, position σ and lever arm.
  // The accelerometer gate is these settings' (pos.accel_gate_chi2: the bank's by default).
  est::PositionKfSettings driven_settings = est::DefaultBankModels(pkf_settings)[1];
  driven_settings.accel_gate_chi2 = pkf_settings.accel_gate_chi2;
  est::PositionKfBankSettings bank_settings;
  bank_settings.models = {pkf_settings, driven_settings};
  est::PositionKfBank bank(bank_settings);
  const est::PositionKf& pkf = bank.filters()[0];
  const est::PositionKf& driven = bank.filters()[1];
  // The tracker-aided INS (aided_ins.hpp): the IMU integrated and corrected by the same position
  // samples; its heading from the field the orientation KF accepted (fuse_ins.hpp).
  est::AidedIns ins(settings.ins);
  est::FqaSettings fqa_settings;
  fqa_settings.earth = est::EarthFrame::kEnu;
  fqa_settings.m_ref_E = est::MagneticNorth(est::EarthFrame::kEnu);

  BroadTracker tracker(opt.pos_rate_hz, opt.pos_noise_m, opt.seed,
                       occluded ? opt.pos_occlusion[0] : 0.0,
                       occluded ? opt.pos_occlusion[1] : 0.0);

  // What the accelerometer's lag is measured from (accel_lag.hpp): the IMU stream with the
  // filter's attitude and the position sensor's samples, never the truth.
  est::AccelLagData lag_data;
  OrientationScore kf_score, fqa_score, ins_score;
  Rms ins_pos_moving;  // the INS's marker position against the truth, movement samples
  Rms pos_all, pos_moving, paper_all, paper_moving, driven_all, driven_moving;
  double driven_weight = 0.0;  // Σ μ_driven over the scored rows
  long refused = 0, fqa_failed = 0, pos_samples = 0, non_finite = 0;
  std::vector<double> plot_t, e_tot, e_head, e_incl, e_fqa, plot_pt, e_pos;
  // The trace: one row per fused sample; empty cells where there is no estimate or no truth.
  std::ostringstream trace;
  trace.precision(9);
  trace << kTraceHeader;
  const auto cell = [&trace](double v) {
    trace << ',';
    if (std::isfinite(v)) trace << v;
  };
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d &gyro = trial.gyro[k], &f_B = trial.accel[k], &m_B = trial.mag_uT[k];
    const double t_k = trial.t[k];
    const auto status = okf.Update(t_k, gyro, f_B, m_B);
    if (!status) {
      if (refused++ < 5) spdlog::warn("sample {}: {}", k, status.error());
      continue;
    }
    // A filter that has gone non-finite has failed: scored, its NaN would read as an error of 0.
    if (!okf.q_EB().allFinite()) {
      if (non_finite++ == 0)
        spdlog::error("fuse: row {} (t = {} s): the orientation KF's estimate is not finite", k + 1,
                      t_k);
      continue;
    }
    const auto q_fqa = est::Fqa(f_B, m_B, fqa_settings);
    if (!q_fqa) ++fqa_failed;
    // Position KF: accelerometer every sample, the simulated position sensor at pos_rate_hz.
    (void)bank.UpdateAccel(t_k, f_B, okf.R_EB(), okf.omega_B());
    lag_data.t_imu.push_back(t_k);
    lag_data.f_B.push_back(f_B);
    lag_data.R_EB.push_back(okf.R_EB());
    lag_data.omega_B.push_back(okf.omega_B());
    const Eigen::Vector3d& p_truth = trial.p_truth[k];
    const std::optional<Eigen::Vector3d> p_sensor = tracker.Sample(t_k, p_truth);
    if (p_sensor) {
      (void)bank.UpdatePosition(t_k, *p_sensor);
      lag_data.t_position.push_back(t_k);
      lag_data.p_WM_W.push_back(*p_sensor);
      ++pos_samples;
    }
    StepAidedIns(ins, okf, t_k, gyro, f_B, settings.ins_heading_from_kf != 0, p_sensor);
    // This sample's errors against the truth, once for the scores, the plots and the trace (NaN
    // where there is no truth or no estimate).
    constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
    const Eigen::Vector4d& q_truth = trial.q_truth[k];
    const bool moving = trial.movement[k] == 1, has_q = q_truth.allFinite();
    const AngleErrors e = has_q ? BroadErrors(okf.q_EB(), q_truth) : AngleErrors{kNan, kNan, kNan};
    const AngleErrors e_ins = has_q && ins.initialized() ? BroadErrors(ins.q_EB(), q_truth)
                                                         : AngleErrors{kNan, kNan, kNan};
    if (has_q) {
      const std::optional<AngleErrors> e_fqa_k =
          q_fqa ? std::optional(BroadErrors(*q_fqa, q_truth)) : std::nullopt;
      if (moving) {
        kf_score.Add(e);
        if (e_fqa_k) fqa_score.Add(*e_fqa_k);
        // The INS is scored once it has started (the first position sample); never non-finite
        // (it resets instead, aided_ins.hpp).
        if (ins.initialized()) ins_score.Add(e_ins);
      }
      plot_t.push_back(t_k);
      e_tot.push_back(e.total * kRadToDeg);
      e_head.push_back(e.heading * kRadToDeg);
      e_incl.push_back(e.inclination * kRadToDeg);
      e_fqa.push_back(e_fqa_k ? e_fqa_k->total * kRadToDeg : kNan);
    }
    const auto error_of = [&](const auto& f) {
      return f.initialized() && p_truth.allFinite() ? (f.p_WM_W() - p_truth).norm() : kNan;
    };
    const double filter_err[2] = {error_of(pkf), error_of(driven)};
    for (auto [err, all, mov] : {std::tuple{filter_err[0], &paper_all, &paper_moving},
                                 std::tuple{filter_err[1], &driven_all, &driven_moving}}) {
      if (!std::isfinite(err)) continue;  // the bank's own estimate is checked below
      all->Add(err);
      if (moving) mov->Add(err);
    }
    const double ins_pos_err =
        ins.initialized() && p_truth.allFinite() ? (ins.p_WM_W() - p_truth).norm() : kNan;
    if (moving && std::isfinite(ins_pos_err)) ins_pos_moving.Add(ins_pos_err);
    const double bank_err = error_of(bank);
    if (bank.initialized() && p_truth.allFinite()) {
      driven_weight += bank.probabilities()[1];
      if (!std::isfinite(bank_err)) {
        if (non_finite++ == 0)
          spdlog::error("fuse: row {} (t = {} s): the position KF's estimate is not finite", k + 1,
                        t_k);
        continue;
      }
      pos_all.Add(bank_err);
      if (moving) pos_moving.Add(bank_err);
      plot_pt.push_back(t_k);
      e_pos.push_back(bank_err * 1e3);
    }
    if (opt.trace.empty()) continue;
    trace << t_k << ',' << trial.movement[k];
    for (int i = 0; i < 4; ++i) cell(okf.q_EB()(i));
    for (double v : {e.total, e.heading, e.inclination}) cell(v);
    const Eigen::Vector3d p = bank.initialized() ? bank.p_WM_W() : Eigen::Vector3d::Constant(kNan);
    for (int i = 0; i < 3; ++i) cell(p(i));
    for (double v : {bank_err, filter_err[0], filter_err[1]}) cell(v);
    cell(bank.initialized() ? bank.probabilities()[1] : kNan);
    cell(driven.initialized() ? driven.accel_noise_scale() : kNan);
    trace << ',' << okf.last_accel_used() << ',' << okf.last_mag_used();
    for (int i = 0; i < 4; ++i) cell(ins.initialized() ? ins.q_EB()(i) : kNan);
    for (double v : {e_ins.total, e_ins.heading, e_ins.inclination}) cell(v);
    for (int i = 0; i < 3; ++i) cell(ins.initialized() ? ins.p_WM_W()(i) : kNan);
    cell(ins_pos_err);
    trace << '\n';
  }

  const auto& oc = okf.counters();
  const auto& pc = pkf.counters();
  const std::string name = std::filesystem::path(path).stem().string();
  std::ostringstream md;
  md << "## rcal fuse " << name << "\n\n"
     << "| estimator | total RMSE [°] | heading RMSE [°] | inclination RMSE [°] |\n"
     << "| --- | --- | --- | --- |\n";
  auto row = [&](const char* label, const OrientationScore& s) {
    md << "| " << label << " | " << Fixed(s.total.value() * kRadToDeg, 2) << " | "
       << Fixed(s.heading.value() * kRadToDeg, 2) << " | "
       << Fixed(s.inclination.value() * kRadToDeg, 2) << " |\n";
  };
  row("orientation KF", kf_score);
  row("FQA alone", fqa_score);
  row("tracker-aided INS", ins_score);
  md << "\nMovement samples scored: " << kf_score.total.n << ". Position RMSE (position KF vs "
     << "truth): " << Fixed(pos_moving.value() * 1e3, 2) << " mm during movement, "
     << Fixed(pos_all.value() * 1e3, 2) << " mm overall (sensor: " << opt.pos_rate_hz << " Hz, "
     << opt.pos_noise_m * 1e3 << " mm noise, seed " << opt.seed << "); the bank's filters alone "
     << "during movement: the paper's motion model " << Fixed(paper_moving.value() * 1e3, 2)
     << " mm, accelerometer-driven " << Fixed(driven_moving.value() * 1e3, 2) << " mm (weight "
     << Fixed(pos_all.n > 0 ? driven_weight / static_cast<double>(pos_all.n) : 0.0, 2) << ").\n"
     << "Rejected: accelerometer " << oc.accel_rejected << " (χ² gate " << oc.accel_gated
     << "), magnetometer " << oc.mag_rejected << " (χ² gate " << oc.mag_gated << "), position "
     << pc.position_rejected << " of " << pos_samples << " (the position KF's accelerometer gate "
     << pc.accel_rejected << ", χ² " << pkf_settings.accel_gate_chi2 << "), refused input "
     << refused << "; zero-rate updates " << oc.zero_rate_updates << " of " << oc.samples
     << " samples.\n"
     << "IMU: " << Fixed(imu_rate_hz, 1) << " Hz (median step); attitude started again after a "
     << "step beyond " << Fixed(okf_settings.max_step, 3) << " s: orientation KF "
     << oc.reinitialised << ", INS " << ins.counters().reinitialised << ".\n";
  if (okf_settings.estimate_hard_iron) {
    // A magnet fixed to the IMU, found from the field's norm (mag_hard_iron.hpp).
    const auto& hc = okf.hard_iron().counters();
    md << "Hard iron: offset taken off " << hc.applied << " magnetometer samples ("
       << Fixed(100.0 * static_cast<double>(hc.applied) / std::max<double>(1.0, hc.samples), 1)
       << " %); fit started again " << hc.restarts
       << " times; last fit b_B = " << Fixed(okf.hard_iron().b_B().norm(), 2) << " µT, field "
       << Fixed(okf.hard_iron().r(), 2) << " µT.\n";
  }
  {
    const auto& ic = ins.counters();
    md << "Tracker-aided INS: marker " << Fixed(ins_pos_moving.value() * 1e3, 2)
       << " mm during movement; positions taken " << ic.positions << " (of them " << ic.shocks_taken
       << " as the accelerometer's shock, κ " << settings.ins.accel_shock_sigma
       << "), refused by its χ² gate " << ic.position_rejected << ", re-anchored " << ic.reanchored
       << ".\n";
  }
  // The accelerometer's lag, measured from this recording (reported; pos.accel_delay applies one).
  est::AccelLagSettings lag_settings;
  lag_settings.earth = pkf_settings.earth;
  lag_settings.gravity = pkf_settings.gravity;
  const auto lag = est::EstimateAccelLag(lag_data, lag_settings);
  if (lag)
    md << "Accelerometer lag measured from the position sensor and the filter's attitude: "
       << Fixed(lag->delay * 1e3, 2) << " ± " << Fixed(lag->delay_sigma * 1e3, 2) << " ms ("
       << lag->triplets
       << " position triplets; applied: pos.accel_delay = " << pkf_settings.accel_delay * 1e3
       << " ms).\n";
  else
    md << "Accelerometer lag not measured: " << lag.error() << ".\n";
  if (non_finite > 0)
    md << "\n**FAILED**: " << non_finite
       << " estimates were not finite (left out of the scores above).\n";
  std::cout << md.str();

  nlohmann::json j;
  j["trial"] = path;
  j["samples"] = n;
  j["orientation_kf"] = ScoreJson(kf_score);
  j["orientation_kf"]["reinitialised"] = oc.reinitialised;
  j["orientation_kf"]["max_step_s"] = okf_settings.max_step;
  j["imu_rate_hz"] = imu_rate_hz;
  j["fqa"] = ScoreJson(fqa_score);
  {
    const est::AidedInsState& x = ins.state();
    const auto& c = ins.counters();
    nlohmann::json a = ScoreJson(ins_score);
    a["lever_arm_BM_B_m"] = {x.r_BM_B.x(), x.r_BM_B.y(), x.r_BM_B.z()};
    a["gyro_bias_B_rad_s"] = {x.b_g_B.x(), x.b_g_B.y(), x.b_g_B.z()};
    a["accel_bias_B_m_s2"] = {x.b_a_B.x(), x.b_a_B.y(), x.b_a_B.z()};
    a["position_rmse_movement_m"] = ins_pos_moving.value();
    a["positions"] = c.positions;
    a["position_rejected"] = c.position_rejected;
    a["reanchored"] = c.reanchored;
    a["shocks_taken"] = c.shocks_taken;
    a["reinitialised"] = c.reinitialised;
    a["max_step_s"] = settings.ins.max_step;
    a["resets"] = c.resets;
    j["aided_ins"] = a;
  }
  j["position_rmse_m"] = pos_all.value();
  j["position_rmse_movement_m"] = pos_moving.value();
  j["position_paper_model"] = {{"rmse_m", paper_all.value()},
                               {"rmse_movement_m", paper_moving.value()},
                               {"rejected", pkf.counters().position_rejected},
                               {"accelerometer_rejected", pkf.counters().accel_rejected},
                               {"accelerometer_rolled_back", pkf.counters().accel_rolled_back},
                               {"accelerometer_reinstated", pkf.counters().accel_reinstated}};
  j["position_accelerometer_driven"] = {
      {"rmse_m", driven_all.value()},
      {"rmse_movement_m", driven_moving.value()},
      {"rejected", driven.counters().position_rejected},
      {"accelerometer_rejected", driven.counters().accel_rejected},
      {"accelerometer_rolled_back", driven.counters().accel_rolled_back},
      {"accelerometer_reinstated", driven.counters().accel_reinstated},
      {"accel_noise_adaptation_tau_s", driven_settings.accel_noise_adaptation_tau},
      {"mean_weight", pos_all.n > 0 ? driven_weight / static_cast<double>(pos_all.n) : 0.0}};
  j["position_bank_evidence_tau_s"] = bank_settings.evidence_tau;
  j["position_sensor"] = {{"rate_hz", opt.pos_rate_hz},
                          {"noise_m", opt.pos_noise_m},
                          {"seed", opt.seed},
                          {"samples", pos_samples}};
  if (occluded)
    j["position_sensor"]["occlusion"] = {{"period_s", opt.pos_occlusion[0]},
                                         {"length_s", opt.pos_occlusion[1]}};
  j["rejected"] = {{"accelerometer", oc.accel_rejected},
                   {"accelerometer_gated", oc.accel_gated},
                   {"magnetometer", oc.mag_rejected},
                   {"magnetometer_gated", oc.mag_gated},
                   {"position", pc.position_rejected},
                   {"input", refused},
                   {"fqa_failed", fqa_failed}};
  j["zero_rate_updates"] = oc.zero_rate_updates;
  j["non_finite_estimates"] = non_finite;
  j["truth_missing"] = trial.truth_missing;
  j["position_truth_missing"] = trial.position_missing;
  j["settings"] = SettingsJson(settings);
  // The sensor ranges the trial was checked against (--set imu.NAME), apart from the filter
  // settings: the magnetometer's is in µT, the unit of the file.
  j["imu_ranges"] = ImuRangesJson(settings);
  j["gyro_bias_final_rad_s"] = {okf.bias_B().x(), okf.bias_B().y(), okf.bias_B().z()};
  j["lever_arm_B_m"] = {pkf.lever_arm_B().x(), pkf.lever_arm_B().y(), pkf.lever_arm_B().z()};
  j["mag_reference"] = {{"norm_uT", okf.mag_ref_norm()}, {"dip_rad", okf.mag_ref_dip()}};
  {
    const est::MagHardIron& hi = okf.hard_iron();
    j["mag_hard_iron"] = {{"applied_samples", hi.counters().applied},
                          {"gated", hi.counters().gated},
                          {"restarts", hi.counters().restarts},
                          {"last_b_B_uT", {hi.b_B().x(), hi.b_B().y(), hi.b_B().z()}},
                          {"last_field_norm_uT", hi.r()},
                          {"last_b_sigma_uT", hi.b_sigma()}};
  }
  if (lag)
    j["accel_lag"] = AccelLagJson(*lag);
  else
    j["accel_lag"] = {{"error", lag.error()}};
  if (!opt.json.empty()) io::AtomicWriteFile(opt.json, j.dump(2) + "\n");
  if (!opt.trace.empty()) io::AtomicWriteFile(opt.trace, trace.str());

  if (!opt.out_dir.empty()) {
    const std::filesystem::path dir(opt.out_dir);
    io::AtomicWriteFile(dir / (name + "_fuse.md"), md.str());
    io::AtomicWriteFile(dir / (name + "_fuse.json"), j.dump(2) + "\n");
    io::PlotSpec ori;
    ori.title = "Orientation error, " + name + " (orientation KF)";
    ori.xlabel = "time [s]";
    ori.ylabel = "error [deg]";
    ori.series = {{"total", plot_t, e_tot, "lines"},
                  {"heading", plot_t, e_head, "lines"},
                  {"inclination", plot_t, e_incl, "lines"}};
    io::PlotPng(ori, dir / (name + "_orientation_error.png"));
    io::PlotSpec fq = ori;
    fq.title = "Orientation error, " + name + " (FQA alone vs KF)";
    fq.logy = true;
    fq.series = {{"FQA total", plot_t, e_fqa, "lines"}, {"KF total", plot_t, e_tot, "lines"}};
    io::PlotPng(fq, dir / (name + "_fqa_error.png"));
    io::PlotSpec pos;
    pos.title = "Position error, " + name + " (position KF)";
    pos.xlabel = "time [s]";
    pos.ylabel = "|p - p_truth| [mm]";
    pos.series = {{"position KF", plot_pt, e_pos, "lines"}};
    io::PlotPng(pos, dir / (name + "_position_error.png"));
  }
  if (non_finite > 0) {
    spdlog::error("fuse: {}: {} estimates were not finite: the filters failed on this trial", path,
                  non_finite);
    return 3;
  }
  return 0;
}

const RegisterCommand kRegisterFuse(
    "fuse", "FQA + orientation KF + position KF on a BROAD trial, scored against its truth",
    [](Args& sub) -> std::function<int()> {
      auto opt = std::make_shared<FuseOptions>();
      sub.add_option("trial", opt->trial, "BROAD trial CSV (../shared/data/broad/*.csv)")
          ->required();
      sub.add_option("--out", opt->out_dir, "directory for the report, JSON and plots");
      sub.add_option("--json", opt->json, "write the figures as JSON (SI units) to this file");
      sub.add_option("--trace", opt->trace,
                     "write the per-sample estimates and errors as CSV (q_EB: IMU → ENU, w x y z; "
                     "p_WM_W [m]; errors [rad] and [m])");
      sub.add_option("--seed", opt->seed, "seed of the simulated position-sensor noise");
      sub.add_option("--pos-rate", opt->pos_rate_hz, "position sensor rate [Hz]");
      sub.add_option("--pos-noise", opt->pos_noise_m, "position sensor noise per axis [m]");
      sub.add_option("--pos-occlusion", opt->pos_occlusion,
                     "PERIOD LENGTH [s]: the position sensor silent for the first LENGTH of every "
                     "PERIOD of the trial's time (an occluded marker); its other samples unchanged")
          ->expected(2)
          ->check(cli::PositiveNumber);
      sub.add_option(
          "--set", opt->overrides,
          "override a filter setting, NAME=VALUE in SI units, NAME as in the JSON "
          "settings with or without its unit (tilt_sigma_rad or tilt_sigma; repeatable)");
      return [opt] { return RunFuse(*opt); };
    });

}  // namespace
}  // namespace rcal::tool
