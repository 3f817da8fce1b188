// rcal analyze STREAM.csv (BROAD layout): where the IMU stream disagrees with the simulator's base
// sensor model, the cause, the extended filter and its gain against the truth orientation
// (discrepancy/imu_analysis.hpp). rcal simulate-imu: a simulated stream with hidden effects.
#include "analyze_imu.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include "command.hpp"
#include "pose_log.hpp"
#include "rcal/estimation/pose_pipeline.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/io/imu_csv.hpp"
#include "rcal/io/lcm_log.hpp"
#include "rcal/io/plot.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_schema.hpp"
#include "report.hpp"
#include "significance_json.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
namespace disc = rcal::discrepancy;

using nlohmann::json;

// "z = 3.1", but "z < -8.21" and "p < 1e-300" for bounds.
std::string Is(const std::string& name, const std::string& value) {
  return name + (value[0] == '<' || value[0] == '>' ? " " : " = ") + value;
}

double Relative(double before, double after) {
  return before > 0 ? (before - after) / before : 0.0;
}

double Metric(const disc::OrientationScore& s, const std::string& metric) {
  return metric == "heading" ? s.heading.value() : s.total.value();
}

json ScoreJson(const disc::OrientationScore& s) {
  return {{"total_rmse_rad", s.total.value()},
          {"heading_rmse_rad", s.heading.value()},
          {"inclination_rmse_rad", s.inclination.value()},
          {"samples", s.total.n}};
}

std::string Deg3(const disc::OrientationScore& s) {
  return Fmt(s.total.value() * kDeg, 2) + " / " + Fmt(s.heading.value() * kDeg, 2) + " / " +
         Fmt(s.inclination.value() * kDeg, 2);
}

std::string ValueText(double v, double sigma) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.4g ± %.2g", v, sigma);
  return buf;
}

// Every k-th finite sample of y against t (plots of 10⁴–10⁵ points stay small).
io::Series Decimated(const std::string& title, const std::vector<double>& t,
                     const std::vector<double>& y, double scale, int every) {
  io::Series s{title, {}, {}, "lines"};
  for (size_t k = 0; k < y.size(); k += static_cast<size_t>(every))
    if (std::isfinite(y[k])) {
      s.x.push_back(t[k]);
      s.y.push_back(y[k] * scale);
    }
  return s;
}

}  // namespace

bool IsImuStreamCsv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ','))
      if (cell == "gyr_x" || cell == "gyr_x\r") return true;
    return false;
  }
  return false;
}

ImuLog LoadImuStreamLog(const std::string& path, const std::string& channel, bool allow_gaps,
                        const std::string& joints_channel) {
  io::LcmLogReader log(path);  // throws naming the file
  ImuLog out;
  disc::ImuStreamData& d = out.data;
  int64_t last = std::numeric_limits<int64_t>::min(), events = 0, skipped = 0;
  std::string first_reason;
  const auto skip = [&](const std::string& why) {
    if (skipped++ == 0) first_reason = "event " + std::to_string(events) + ": " + why;
  };
  // The arm's rest from its joints, as the pose pipeline takes it (StillDetector): still while
  // max_i |Δq_i| / Δt between consecutive readings stays below its joint_rate_threshold. Each
  // IMU sample takes the state of the latest joint reading at or before it (moving before any).
  const double rate_limit = estimation::StillDetectorSettings{}.joint_rate_threshold;
  std::optional<std::pair<int64_t, std::vector<double>>> last_joints;
  bool arm_moving = true;
  std::vector<int> movement;
  while (const auto e = log.Next()) {
    if (!joints_channel.empty() && e->channel == joints_channel) {
      joint_state_t j{};
      if (!transport::DecodeLcm(e->data.data(), e->data.size(), &j).empty()) continue;
      bool finite = true;
      for (double q : j.q) finite &= std::isfinite(q);
      if (!finite || (last_joints &&
                      (j.utime <= last_joints->first || j.q.size() != last_joints->second.size())))
        continue;
      if (last_joints) {
        double rate = 0.0;
        const double dt = static_cast<double>(j.utime - last_joints->first) * 1e-6;
        for (size_t i = 0; i < j.q.size(); ++i)
          rate = std::max(rate, std::abs(j.q[i] - last_joints->second[i]) / dt);
        arm_moving = rate >= rate_limit;
        ++out.joint_readings;
      }
      last_joints = {j.utime, j.q};
      continue;
    }
    if (e->channel != channel) continue;
    ++events;
    imu_sample_t m{};
    // Checked against the schema before the generated decoder runs; a loss of the log's.
    if (const std::string why = transport::DecodeLcm(e->data.data(), e->data.size(), &m);
        !why.empty()) {
      log.Skip(*e, "does not decode as imu_sample_t: " + why);
      skip("does not decode as imu_sample_t: " + why);
      continue;
    }
    const Eigen::Vector3d g = Eigen::Map<const Eigen::Vector3d>(m.gyro),
                          a = Eigen::Map<const Eigen::Vector3d>(m.accel),
                          b = Eigen::Map<const Eigen::Vector3d>(m.mag);
    if (!g.allFinite() || !a.allFinite() || (m.has_mag && !b.allFinite())) {
      skip("imu_sample.gyro/accel/mag: not finite");
      continue;
    }
    if (!m.has_mag) {
      skip("imu_sample.has_mag: false (the analysis needs the field)");
      continue;
    }
    if (m.utime <= last) {
      skip("imu_sample.utime: " + std::to_string(m.utime) + " not after the previous sample");
      continue;
    }
    last = m.utime;
    d.t.push_back(static_cast<double>(m.utime) * 1e-6);
    d.gyro.push_back(g);
    d.accel.push_back(a);
    d.mag_uT.push_back(b * 1e6);  // the message carries tesla
    // The joints logged after this sample (same utime) are not known yet: the state so far.
    movement.push_back(arm_moving ? 1 : 0);
  }
  CheckLogGaps(path, log.stats(), allow_gaps);
  if (skipped > 0)
    spdlog::warn("{}: {} of {} {} events skipped (first: {})", path, skipped, events, channel,
                 first_reason);
  if (d.t.empty())
    throw std::runtime_error(path + ": no usable " + channel +
                             " samples (imu_sample_t) in the log");
  if (out.joint_readings > 0) {
    d.movement = std::move(movement);
    spdlog::info("{}: rests from the {} channel ({} readings, still below {} rad/s)", path,
                 joints_channel, out.joint_readings + 1, rate_limit);
  }
  return out;
}

disc::ImuStreamData LoadImuStreamCsv(const std::string& path) {
  // The same checks as rcal fuse: sensor ranges, time order, NaN, a unit truth quaternion.
  const io::ImuCsv csv = io::LoadImuCsv(path);
  if (csv.t.size() < 10) throw std::runtime_error(path + ": fewer than 10 rows");
  disc::ImuStreamData d;
  d.t = csv.t;
  d.gyro = csv.gyro;
  d.accel = csv.accel;
  d.mag_uT = csv.mag_uT;
  if (csv.has_truth) d.q_truth = csv.q_truth;
  if (csv.has_movement) d.movement = csv.movement;
  if (csv.has_position) d.p_W = csv.p_truth;
  return d;
}

void WriteImuStreamCsv(const fs::path& path, const std::vector<sim::ImuStreamSample>& stream) {
  std::string s =
      "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,q_w,q_x,q_y,q_z,pos_x,pos_y,pos_"
      "z,movement\n";
  char buf[640];
  for (const auto& r : stream) {
    std::snprintf(buf, sizeof buf,
                  "%.6f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,"
                  "%.9g,%d\n",
                  r.t, r.gyro.x(), r.gyro.y(), r.gyro.z(), r.accel.x(), r.accel.y(), r.accel.z(),
                  r.mag_uT.x(), r.mag_uT.y(), r.mag_uT.z(), r.q_WI(0), r.q_WI(1), r.q_WI(2),
                  r.q_WI(3), r.p_W.x(), r.p_W.y(), r.p_W.z(), r.movement);
    s += buf;
  }
  io::AtomicWriteFile(path, s);
}

int RunAnalyzeImu(const AnalyzeImuOptions& o) {
  const std::string path = ResolvePath(o.data);
  spdlog::info("rcal analyze: the IMU stream of {}; no robot needed", path);
  const bool is_log = IsLcmLog(path);
  const ImuLog log = is_log ? LoadImuStreamLog(path, o.channel, o.allow_gaps, o.joints_channel)
                            : ImuLog{LoadImuStreamCsv(path), 0};
  const disc::ImuStreamData& data = log.data;
  disc::ImuAnalysisSettings settings;
  settings.alpha = o.alpha;
  // Rests from the joints mark the arm's stops exactly: cut only the pose pipeline's settle time
  // from each end, not the 0.5 s that a movement column's coarse transitions need.
  if (log.joint_readings > 0) settings.rest_trim_s = estimation::PosePipelineSettings{}.settle_time;
  const std::string rest_source = log.joint_readings > 0   ? "the joints (" + o.joints_channel + ")"
                                  : !data.movement.empty() ? "movement column"
                                                           : "detected still";
  const disc::ImuAnalysis a = disc::AnalyzeImuStream(data, settings);
  const fs::path out(o.out);
  fs::create_directories(out);

  // --- JSON (SI) ---
  auto cand_json = [&](const disc::ImuCandidate& c) {
    json values = json::object();
    for (const auto& v : c.values) values[v.name] = {{"value", v.value}, {"sigma", v.sigma}};
    json j = {{"cause", c.cause},
              {"axes", c.axes},
              {"values", values},
              {"critical_z", c.critical},
              {"significant", c.significant},
              {"loses_to_truth", c.loses_to_truth},
              {"named", c.named()},
              {"tested", c.tested},
              {"note", c.note}};
    PutZ(j, "statistic_z", c.statistic);  // an infinite z as a bound (significance.hpp)
    if (!std::isnan(c.log_p)) PutP(j, "", c.log_p);
    if (a.has_truth) {
      j["before"] = ScoreJson(c.before);
      j["after"] = ScoreJson(c.after);
    }
    if (c.gain_metric() == "position") {  // accel_lag: the position KF, cross-fitted
      j["position_rmse_before_m"] = c.position_before_m;  // NaN (not measured) is written null
      j["position_rmse_after_m"] = c.position_after_m;
    }
    return j;
  };
  json jeffects = json::array(), jcands = json::array();
  for (const auto& c : a.candidates) {
    jcands.push_back(cand_json(c));
    if (c.named()) {
      json values = json::object();
      for (const auto& v : c.values) values[v.name] = {{"value", v.value}, {"sigma", v.sigma}};
      jeffects.push_back({{"cause", c.cause}, {"axes", c.axes}, {"values", values}});
    }
  }
  json gain;
  if (a.has_truth) {
    const double b = Metric(a.base_score, a.gain_metric),
                 e = Metric(a.extended_score, a.gain_metric);
    gain = {{"metric", a.gain_metric + "_rmse"},
            {"heldout_rms_before_rad", b},
            {"heldout_rms_after_rad", e},
            {"relative_gain", Relative(b, e)},
            {"base", ScoreJson(a.base_score)},
            {"extended", ScoreJson(a.extended_score)},
            {"time_offset_applied_s", a.time_offset_s},
            {"measured", true}};
  } else {
    gain = {{"metric", a.gain_metric + "_rmse"},
            {"heldout_rms_before_rad", nullptr},
            {"heldout_rms_after_rad", nullptr},
            {"relative_gain", nullptr},
            {"measured", false},
            {"reason", "no truth orientation in the stream: the gain cannot be measured"}};
  }
  json jallan = {{"tau_s", a.allan.tau_s},
                 {"rel_sigma", a.allan.rel_sigma},
                 {"adev_x_rad_s", a.allan.adev_rad_s[0]},
                 {"adev_y_rad_s", a.allan.adev_rad_s[1]},
                 {"adev_z_rad_s", a.allan.adev_rad_s[2]},
                 {"white_level_rad_s_sqrt_hz", a.allan.white_level}};
  json jrests = json::array();
  for (auto [b, e] : a.rests) jrests.push_back({data.t[b], data.t[e - 1]});
  const json j = {{"kind", "imu_stream"},
                  {"data", o.data},
                  {"samples", a.samples},
                  {"rate_hz", a.rate_hz},
                  {"has_truth", a.has_truth},
                  {"has_movement", a.has_movement},
                  {"rest_segments_s", jrests},
                  {"rests",
                   {{"source", rest_source},
                    {"short", a.short_rests},
                    {"trim_s", settings.rest_trim_s},
                    {"reference_rests", a.reference_rests},
                    {"reference_s", a.reference_s},
                    {"note", a.rest_note}}},
                  {"reference",
                   {{"mag_norm_uT", a.mag_ref_norm_uT},
                    {"mag_dip_rad", a.mag_ref_dip_rad},
                    {"gravity_m_s2", a.gravity_ref},
                    {"sigma_mag_norm_uT", a.sigma_mag_norm_uT},
                    {"sigma_dip_rad", a.sigma_dip_rad},
                    {"sigma_accel_norm_m_s2", a.sigma_accel_norm}}},
                  {"effects", jeffects},
                  {"candidates", jcands},
                  {"gain", gain},
                  {"allan", jallan},
                  {"alpha", o.alpha}};
  io::AtomicWriteFile(out / "analysis.json", j.dump(2) + "\n");
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2) + "\n");

  // --- Plots ---
  spdlog::info("rcal analyze: plots");
  const int every = std::max(1, a.samples / 4000);
  {
    io::PlotSpec p{"Gyro Allan deviation over the rests, with the white-noise line",
                   "tau [s]",
                   "Allan deviation [deg/s]",
                   {},
                   true,
                   true};
    for (int i = 0; i < 3; ++i) {
      io::Series s{std::string("gyro ") + "xyz"[i], a.allan.tau_s, {}, "linespoints"};
      for (double v : a.allan.adev_rad_s[i]) s.y.push_back(v * kDeg);
      io::Series w{std::string("white line ") + "xyz"[i], a.allan.tau_s, {}, "lines"};
      for (double t : a.allan.tau_s) w.y.push_back(a.allan.white_level[i] / std::sqrt(t) * kDeg);
      p.series.push_back(s);
      p.series.push_back(w);
    }
    io::Series stated{"stated density (simulator)", a.allan.tau_s, {}, "lines"};
    for (double t : a.allan.tau_s)
      stated.y.push_back(settings.gyro_noise_density / std::sqrt(t) * kDeg);
    p.series.push_back(stated);
    io::PlotPng(p, out / "allan.png");
  }
  {
    io::PlotSpec p{
        "Magnetic field norm with the reference and the gate band", "time [s]", "|m| [uT]", {}};
    p.series.push_back(Decimated("|m|", data.t, a.mag_norm_uT, 1.0, every));
    const double gate = a.mag_gate_norm_uT;
    for (double off : {-gate, 0.0, gate})
      p.series.push_back({off == 0 ? "reference" : (off > 0 ? "gate +" : "gate -"),
                          {data.t.front(), data.t.back()},
                          {a.mag_ref_norm_uT + off, a.mag_ref_norm_uT + off},
                          "lines"});
    io::PlotPng(p, out / "mag_norm.png");
    io::PlotSpec q{"Magnetic dip (base filter attitude) with the reference and the gate band",
                   "time [s]",
                   "dip [deg]",
                   {}};
    q.series.push_back(Decimated("dip", data.t, a.mag_dip_rad, kDeg, every));
    const double gd = a.mag_gate_dip_rad;
    for (double off : {-gd, 0.0, gd})
      q.series.push_back({off == 0 ? "reference" : (off > 0 ? "gate +" : "gate -"),
                          {data.t.front(), data.t.back()},
                          {(a.mag_ref_dip_rad + off) * kDeg, (a.mag_ref_dip_rad + off) * kDeg},
                          "lines"});
    io::PlotPng(q, out / "mag_dip.png");
  }
  if (!a.position_err_base_m.empty()) {
    io::PlotSpec p{
        "Position KF error between the tracker's samples, without and with the "
        "accelerometer's lag (cross-fitted)",
        "time [s]",
        "position error [mm]",
        {}};
    p.series.push_back(Decimated("as stamped", data.t, a.position_err_base_m, 1e3, every));
    p.series.push_back(
        Decimated("lag taken out (the other half's)", data.t, a.position_err_ext_m, 1e3, every));
    io::PlotPng(p, out / "position_error.png");
  }
  if (a.has_truth) {
    io::PlotSpec p{"Heading error against the truth: base vs extended model",
                   "time [s]",
                   "heading error [deg]",
                   {}};
    p.series.push_back(Decimated("base model", data.t, a.heading_err_base_rad, kDeg, every));
    p.series.push_back(Decimated("extended model", data.t, a.heading_err_ext_rad, kDeg, every));
    io::PlotPng(p, out / "heading_error.png");
    io::PlotSpec q = p;
    q.title = "Total error against the truth: base vs extended model";
    q.ylabel = "total error [deg]";
    q.series = {Decimated("base model", data.t, a.total_err_base_rad, kDeg, every),
                Decimated("extended model", data.t, a.total_err_ext_rad, kDeg, every)};
    io::PlotPng(q, out / "total_error.png");
  }

  // --- report.md ---
  std::ostringstream md;
  md << "# rcal analyze (IMU stream)\n\n- Data: `" << o.data << "`, " << a.samples << " samples at "
     << Fmt(a.rate_hz, 1) << " Hz, " << a.rests.size() << " rest segments (" << rest_source
     << "), truth orientation " << (a.has_truth ? "present" : "absent")
     << (a.short_rests ? "\n- **Short rests**: " + a.rest_note : std::string()) << "\n- Reference ("
     << (a.reference_rests > 1 ? "first " + std::to_string(a.reference_rests) + " rests, " +
                                     Fmt(a.reference_s, 2) + " s"
                               : std::string("first rest"))
     << "): |m| = " << Fmt(a.mag_ref_norm_uT, 2) << " µT (σ " << Fmt(a.sigma_mag_norm_uT, 2)
     << "), dip " << Fmt(a.mag_ref_dip_rad * kDeg, 2) << "° (σ " << Fmt(a.sigma_dip_rad * kDeg, 2)
     << "°), |f| = " << Fmt(a.gravity_ref, 3) << " m/s² (σ " << Fmt(a.sigma_accel_norm, 3)
     << ")\n- Base model: white noise at the stated densities, constant gyro bias, constant "
        "field, accelerometer = gravity; base filter trusts every sample.\n\n## Finding\n\n";
  const auto effects = a.effects();
  if (effects.empty()) {
    md << "**No significant effect beyond the base sensor model** (α = " << o.alpha
       << ", Bonferroni over the " << (a.has_positions ? "five" : "four")
       << " candidates the stream can test and within each).\n\n";
  } else {
    std::vector<std::vector<std::string>> rows;
    for (const auto* c : effects) {
      std::string axes;
      for (const auto& x : c->axes) axes += (axes.empty() ? "" : ",") + x;
      rows.push_back({c->cause, axes, disc::ZText(c->statistic, 1), Fmt(c->critical, 1),
                      std::isnan(c->log_p) ? "" : disc::PText(c->log_p)});
    }
    md << MdTable({"cause", "axes", "z", "z critical", "p"}, rows) << "\n";
  }
  md << "## Candidates\n\n";
  for (const auto& c : a.candidates) {
    md << "### " << c.cause << " — "
       << (!c.tested                           ? "not tested"
           : c.named()                         ? "**found**"
           : c.loses_to_truth && c.significant ? "significant, not named: its extension loses "
                                                 "against the truth"
                                               : "not significant")
       << "\n\nTest statistic " << Is("z", disc::ZText(c.statistic, 2))
       << (std::isnan(c.log_p) ? "" : ", " + Is("p", disc::PText(c.log_p))) << " (critical "
       << Fmt(c.critical, 2) << ")." << (c.note.empty() ? "" : " " + c.note + ".") << "\n\n";
    std::vector<std::vector<std::string>> rows;
    for (const auto& v : c.values) rows.push_back({v.name, ValueText(v.value, v.sigma)});
    md << MdTable({"figure [SI, unit in the name]", "value ± σ"}, rows) << "\n";
    if (c.gain_metric() == "position") {
      if (std::isfinite(c.position_before_m) && std::isfinite(c.position_after_m))
        md << "Position KF (position_kf's default bank, fusing one position every "
           << Fmt(settings.accel_lag_position_period_s * 1e3, 0)
           << " ms) without vs with the lag fitted on the other half of the stream, RMSE over the "
              "movement samples it did not fuse: "
           << Fmt(c.position_before_m * 1e3, 3) << " mm → " << Fmt(c.position_after_m * 1e3, 3)
           << " mm.\n\n![position error](position_error.png)\n\n";
    } else if (a.has_truth && c.tested) {
      md << "Base filter vs base + this extension, total / heading / inclination RMSE over the "
            "movement samples: "
         << Deg3(c.before) << "° → " << Deg3(c.after) << "°.\n\n";
    }
  }
  md << "![Allan deviation](allan.png)\n\n![field norm](mag_norm.png)\n\n![dip](mag_dip.png)\n\n"
     << "## Gain against the truth\n\n";
  if (a.has_truth) {
    md << MdTable({"model", "total RMSE [°]", "heading RMSE [°]", "inclination RMSE [°]"},
                  {{"base (trusts every sample)", Fmt(a.base_score.total.value() * kDeg, 2),
                    Fmt(a.base_score.heading.value() * kDeg, 2),
                    Fmt(a.base_score.inclination.value() * kDeg, 2)},
                   {"extended (selected effects)", Fmt(a.extended_score.total.value() * kDeg, 2),
                    Fmt(a.extended_score.heading.value() * kDeg, 2),
                    Fmt(a.extended_score.inclination.value() * kDeg, 2)}})
       << "\nThe truth orientation is never used by a fit (the time offset is fitted on one half "
          "of the movement samples and scored on the other). Relative gain in "
       << a.gain_metric << " RMSE: "
       << Fmt(100 * Relative(Metric(a.base_score, a.gain_metric),
                             Metric(a.extended_score, a.gain_metric)),
              1)
       << " %.\n\n![heading error](heading_error.png)\n\n![total error](total_error.png)\n";
  } else {
    md << "No truth orientation in the stream: the gain cannot be measured.\n";
  }
  io::AtomicWriteFile(out / "report.md", md.str());

  std::printf("\nrcal analyze — %s, IMU stream, %d samples, %zu rests (%s)\n", o.data.c_str(),
              a.samples, a.rests.size(), rest_source.c_str());
  if (a.short_rests) std::printf("  short rests: %s\n", a.rest_note.c_str());
  if (effects.empty()) std::printf("  no significant effect beyond the base sensor model\n");
  for (const auto* c : effects)
    std::printf("  %s (z %s%s)\n", c->cause.c_str(), disc::ZText(c->statistic, 1).c_str(),
                std::isnan(c->log_p) ? "" : (", p " + disc::PText(c->log_p)).c_str());
  if (a.has_truth)
    std::printf("  total/heading/inclination RMSE [deg]: base %s -> extended %s\n",
                Deg3(a.base_score).c_str(), Deg3(a.extended_score).c_str());
  else
    std::printf("  no truth: gain not measured\n");
  const disc::ImuCandidate& lag = a.candidates.back();  // accel_lag
  if (lag.tested)
    std::printf(
        "  accelerometer lag %.2f ± %.2f ms; position RMSE [mm] without -> with it "
        "(cross-fitted): %.3f -> %.3f\n",
        lag.values[0].value * 1e3, lag.values[0].sigma * 1e3, lag.position_before_m * 1e3,
        lag.position_after_m * 1e3);
  std::printf("  wrote %s\n", (out / "report.md").c_str());
  return 0;
}

namespace {

struct SimulateImuOptions {
  std::string out;
  std::uint64_t seed = 1;
  sim::ImuStreamSettings settings;
  sim::ImuStreamEffects effects;
  double gyro_bias_rw = 0.0;
  double mag_uT = 0.0;
};

const RegisterCommand kRegisterSimulateImu(
    "simulate-imu", "Simulate an IMU stream in the BROAD layout with hidden effects",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<SimulateImuOptions>();
      sub.add_option("--out", o->out, "CSV file to write")->required();
      sub.add_option("--seed", o->seed, "seed of every draw")->capture_default_str();
      sub.add_option("--segments", o->settings.motion_segments, "motion segments")
          ->capture_default_str();
      sub.add_option("--rest", o->settings.rest_s, "rest length [s]")->capture_default_str();
      sub.add_option("--motion", o->settings.motion_s, "motion length [s]")->capture_default_str();
      sub.add_option("--gyro-bias-rw", o->gyro_bias_rw,
                     "gyro bias random walk, all axes [rad/s/√s]");
      sub.add_option("--mag-disturbance", o->mag_uT, "magnetic disturbance along east [µT]");
      sub.add_option("--mag-start", o->effects.mag_disturbance_start_s, "disturbance start [s]");
      sub.add_option("--mag-end", o->effects.mag_disturbance_end_s, "disturbance end [s]");
      sub.add_option("--linear-accel", o->effects.linear_accel,
                     "linear acceleration during motion [m/s²]");
      sub.add_option("--time-offset", o->effects.time_offset_s, "IMU stamps late by [s]");
      sub.add_option("--accel-delay", o->effects.accel_delay_s,
                     "the accelerometer alone reads late by [s]")
          ->check(cli::Range(-0.05, 0.05));
      return [o] {
        o->effects.gyro_bias_random_walk.setConstant(o->gyro_bias_rw);
        if (o->mag_uT != 0.0) {
          o->effects.mag_disturbance = true;
          o->effects.mag_disturbance_uT = Eigen::Vector3d(o->mag_uT, 0.0, 0.0);
        }
        std::mt19937_64 rng(o->seed);
        const auto stream = sim::SimulateImuStream(o->settings, o->effects, rng);
        WriteImuStreamCsv(o->out, stream);
        std::printf("wrote %s (%zu samples)\n", o->out.c_str(), stream.size());
        return 0;
      };
    });

}  // namespace
}  // namespace rcal::tool
