#include "rcal/io/effects_json.hpp"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <stdexcept>

namespace rcal::io {
namespace {

using nlohmann::json;

const json& Key(const json& j, const std::string& key, const std::string& where) {
  if (!j.is_object() || !j.contains(key)) throw std::runtime_error(where + key + ": missing");
  return j.at(key);
}

double Number(const json& j, const std::string& key, const std::string& where) {
  const json& v = Key(j, key, where);
  if (!v.is_number() || !std::isfinite(v.get<double>()))
    throw std::runtime_error(where + key + ": not a finite number");
  return v.get<double>();
}

std::string Text(const json& j, const std::string& key, const std::string& where) {
  const json& v = Key(j, key, where);
  if (!v.is_string()) throw std::runtime_error(where + key + ": not a string");
  return v.get<std::string>();
}

}  // namespace

AnalysisEffects ParseAnalysisEffects(const json& analysis,
                                     const kinematics::KinematicModel& model) {
  const json& list = Key(analysis, "effects", "");
  if (!list.is_array()) throw std::runtime_error("effects: not a list");
  AnalysisEffects out;
  std::vector<double> values;
  for (size_t k = 0; k < list.size(); ++k) {
    const std::string at = "effects[" + std::to_string(k) + "].";
    const json& entry = list[k];
    const std::string cause_name = Text(entry, "cause", at);
    const auto cause = kinematics::ParseEffectCause(cause_name);
    if (!cause)
      throw std::runtime_error(at + "cause: '" + cause_name +
                               "' is not a pose-level effect (joint_compliance, joint_periodic, "
                               "joint_scale, backlash, thermal)");
    kinematics::Effect f;
    f.cause = *cause;
    const json& joints = Key(entry, "joints", at);
    if (!joints.is_array()) throw std::runtime_error(at + "joints: not a list");
    if (f.cause == kinematics::EffectCause::kThermal) {
      if (!joints.empty()) throw std::runtime_error(at + "joints: thermal takes no joint");
      const std::string source = Text(entry, "source", at);
      if (source != "temperature" && source != "time")
        throw std::runtime_error(at + "source: '" + source + "', expected temperature or time");
      f.thermal_source = source == "time" ? kinematics::Effect::ThermalSource::kTime
                                          : kinematics::Effect::ThermalSource::kTemperature;
      f.reference = Number(entry, "reference", at);
    } else {
      if (joints.size() != 1 || !joints[0].is_string())
        throw std::runtime_error(at + "joints: expected one joint name");
      const std::string name = joints[0].get<std::string>();
      for (int j = 0; j < model.num_joints(); ++j)
        if (model.joints()[j].name == name) f.joint = j;
      if (f.joint < 0)
        throw std::runtime_error(at + "joints: no joint '" + name + "' in robot " + model.name());
      if (f.cause == kinematics::EffectCause::kJointPeriodic) {
        const double h = Number(entry, "harmonic", at);
        if (h != 1 && h != 2) throw std::runtime_error(at + "harmonic: 1 or 2");
        f.harmonic = static_cast<int>(h);
      }
    }
    for (const auto& g : out.effects)
      if (g.SameAs(f)) throw std::runtime_error(at + "cause: the same effect twice");
    const json& vals = Key(entry, "values", at);
    if (!vals.is_array() || static_cast<int>(vals.size()) != f.num_params())
      throw std::runtime_error(at + "values: expected " + std::to_string(f.num_params()) +
                               " entries");
    for (size_t i = 0; i < vals.size(); ++i)
      values.push_back(Number(vals[i], "value", at + "values[" + std::to_string(i) + "]."));
    out.effects.push_back(f);
  }
  out.values = Eigen::Map<const Eigen::VectorXd>(values.data(), values.size());
  if (analysis.contains("selected_on")) {
    const json& rows = Key(Key(analysis, "selected_on", ""), "row_fingerprints", "selected_on.");
    if (!rows.is_array()) throw std::runtime_error("selected_on.row_fingerprints: not a list");
    for (const json& r : rows) {
      if (!r.is_string()) throw std::runtime_error("selected_on.row_fingerprints: not strings");
      out.selection_rows.insert(r.get<std::string>());
    }
    out.has_selection_rows = true;
  }
  // The analysis' own gain, only to print beside calibrate's: taken when readable, never refused.
  if (analysis.contains("gain") && analysis["gain"].is_object()) {
    const json& g = analysis["gain"];
    if (g.contains("relative_gain") && g["relative_gain"].is_number())
      out.analysis_relative_gain = g["relative_gain"].get<double>();
    if (g.contains("scheme") && g["scheme"].is_string())
      out.analysis_gain_scheme = g["scheme"].get<std::string>();
  }
  if (analysis.contains("link_density_kg_per_m")) {
    out.link_density_kg_per_m = Number(analysis, "link_density_kg_per_m", "");
    if (out.link_density_kg_per_m < 0) throw std::runtime_error("link_density_kg_per_m: negative");
  }
  return out;
}

AnalysisEffects ReadAnalysisEffects(const std::string& path,
                                    const kinematics::KinematicModel& model) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("--effects: cannot read " + path);
  try {
    return ParseAnalysisEffects(json::parse(in), model);
  } catch (const json::exception& e) {
    throw std::runtime_error("--effects " + path + ": not JSON: " + e.what());
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("--effects " + path + ": " + e.what());
  }
}

json EffectsJson(const kinematics::ExtendedModel& model, const Eigen::VectorXd& e,
                 const Eigen::VectorXd& sigma) {
  const auto params = model.EffectParameters();
  json list = json::array();
  for (size_t k = 0; k < model.effects().size(); ++k) {
    const kinematics::Effect& f = model.effects()[k];
    json values = json::array();
    for (int i = model.effect_offset(k); i < model.effect_offset(k) + f.num_params(); ++i)
      values.push_back({{"name", params[i].name},
                        {"unit", params[i].unit},
                        {"value", e(i)},
                        {"sigma", sigma(i)}});
    json entry = {{"cause", kinematics::ToString(f.cause)},
                  {"joints", f.joint >= 0 ? json::array({model.base().joints()[f.joint].name})
                                          : json::array()},
                  {"values", values}};
    if (f.cause == kinematics::EffectCause::kJointPeriodic) entry["harmonic"] = f.harmonic;
    if (f.cause == kinematics::EffectCause::kThermal) {
      entry["source"] =
          f.thermal_source == kinematics::Effect::ThermalSource::kTime ? "time" : "temperature";
      entry["reference"] = f.reference;
    }
    list.push_back(entry);
  }
  return list;
}

std::string PoseFingerprint(const kinematics::PoseMeasurement& m) {
  std::uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a 64
  const auto add = [&h](const double* v, size_t n) {
    const auto* b = reinterpret_cast<const unsigned char*>(v);
    for (size_t i = 0; i < n * sizeof(double); ++i) {
      h ^= b[i];
      h *= 0x100000001b3ull;
    }
  };
  add(m.q.data(), m.q.size());
  add(m.p_WM_W.data(), 3);
  if (m.has_orientation) add(m.R_EI.data(), 9);
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

std::vector<kinematics::EffectContext> ToContexts(const PoseDataset& data) {
  std::vector<kinematics::EffectContext> out(data.samples.size());
  for (size_t i = 0; i < out.size(); ++i) {
    const PoseSample& s = data.samples[i];
    out[i].temperature_c = s.temperature;
    out[i].payload_kg = std::isnan(s.payload) ? 0.0 : s.payload;
    out[i].time_s = s.time;
    out[i].dq_sign = s.dq_sign;
  }
  return out;
}

}  // namespace rcal::io
