#include "rcal/transport/checkpoint_json.hpp"

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"

namespace rcal::transport {
namespace {

using nlohmann::json;
constexpr const char* kSchema = "rcal.ekf_checkpoint/3";
constexpr const char* kSchemaV2 = "rcal.ekf_checkpoint/2";  // no x_fixed, no marker; still loads
constexpr const char* kSchemaV1 = "rcal.ekf_checkpoint/1";  // no `held` either; still loads

json Vec(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

json Mat(const Eigen::MatrixXd& m) {
  json rows = json::array();
  for (int r = 0; r < m.rows(); ++r) {
    std::vector<double> row(m.cols());
    for (int c = 0; c < m.cols(); ++c) row[c] = m(r, c);
    rows.push_back(row);
  }
  return rows;
}

const json& At(const json& j, const std::string& key, const std::string& path) {
  if (!j.is_object() || !j.contains(key))
    throw std::runtime_error("checkpoint: " + path + key + ": missing");
  return j.at(key);
}

Eigen::VectorXd ToVec(const json& j, const std::string& key) {
  if (!j.is_array()) throw std::runtime_error("checkpoint: " + key + ": not an array");
  Eigen::VectorXd v(j.size());
  for (size_t i = 0; i < j.size(); ++i) {
    if (!j[i].is_number()) throw std::runtime_error("checkpoint: " + key + ": not a number");
    v(i) = j[i].get<double>();
  }
  return v;
}

Eigen::MatrixXd ToMat(const json& j, const std::string& key) {
  if (!j.is_array()) throw std::runtime_error("checkpoint: " + key + ": not an array");
  if (j.empty()) return {};
  Eigen::MatrixXd m(j.size(), j[0].size());
  for (size_t r = 0; r < j.size(); ++r) {
    const Eigen::VectorXd row = ToVec(j[r], key);
    if (row.size() != m.cols()) throw std::runtime_error("checkpoint: " + key + ": ragged rows");
    m.row(r) = row.transpose();
  }
  return m;
}

json MeasurementJson(const kinematics::PoseMeasurement& m) {
  return {{"q", Vec(m.q)},       {"p_WM_W", Vec(m.p_WM_W)},
          {"marker", m.marker},  {"has_orientation", m.has_orientation},
          {"R_EI", Mat(m.R_EI)}, {"covariance", Mat(m.covariance)}};
}

kinematics::PoseMeasurement MeasurementFromJson(const json& h, const std::string& path) {
  kinematics::PoseMeasurement m;
  m.q = ToVec(At(h, "q", path), path + "q");
  const Eigen::VectorXd p = ToVec(At(h, "p_WM_W", path), path + "p_WM_W");
  if (p.size() != 3) throw std::runtime_error("checkpoint: " + path + "p_WM_W: not 3 values");
  m.p_WM_W = p;
  if (h.contains("marker")) m.marker = At(h, "marker", path).get<int>();  // schema 3
  m.has_orientation = At(h, "has_orientation", path).get<bool>();
  const Eigen::MatrixXd R = ToMat(At(h, "R_EI", path), path + "R_EI");
  if (R.rows() != 3 || R.cols() != 3)
    throw std::runtime_error("checkpoint: " + path + "R_EI: not 3×3");
  m.R_EI = R;
  m.covariance = ToMat(At(h, "covariance", path), path + "covariance");
  return m;
}

// A pose's context (kinematics::EffectContext): NaN (unknown) written as null.
json ContextJson(const kinematics::EffectContext& c) {
  const auto maybe = [](double v) { return std::isnan(v) ? json(nullptr) : json(v); };
  return {{"temperature_c", maybe(c.temperature_c)},
          {"payload_kg", maybe(c.payload_kg)},
          {"time_s", maybe(c.time_s)},
          {"dq_sign", std::vector<int>(c.dq_sign.data(), c.dq_sign.data() + c.dq_sign.size())}};
}

kinematics::EffectContext ContextFromJson(const json& j, const std::string& path) {
  const auto maybe = [&](const char* key) {
    const json& v = At(j, key, path);
    if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();
    if (!v.is_number()) throw std::runtime_error("checkpoint: " + path + key + ": not a number");
    return v.get<double>();
  };
  kinematics::EffectContext c;
  c.temperature_c = maybe("temperature_c");
  c.payload_kg = maybe("payload_kg");
  c.time_s = maybe("time_s");
  const json& dq = At(j, "dq_sign", path);
  if (!dq.is_array()) throw std::runtime_error("checkpoint: " + path + "dq_sign: not an array");
  c.dq_sign.resize(static_cast<Eigen::Index>(dq.size()));
  for (size_t i = 0; i < dq.size(); ++i) c.dq_sign(static_cast<Eigen::Index>(i)) = dq[i].get<int>();
  return c;
}

}  // namespace

std::string CheckpointText(const CheckpointFile& f) {
  const auto& c = f.checkpoint;
  json history = json::array();
  for (const auto& m : c.history) history.push_back(MeasurementJson(m));
  json held = json::array();
  for (const auto& h : f.held)
    held.push_back({{"utime", h.utime},
                    {"pose_index", h.pose_index},
                    {"measurement", MeasurementJson(h.z)},
                    {"context", ContextJson(h.context)}});
  json j = {{"schema", kSchema},
            {"model_id", f.model_id},
            {"utime", f.utime},
            {"last_pose_index", f.last_pose_index},
            {"x0", Vec(c.x0)},
            {"x", Vec(c.x)},
            {"x_lin", Vec(c.x_lin)},
            {"P0", Mat(c.P0)},
            {"P", Mat(c.P)},
            {"accepted", c.accepted},
            {"rejected", c.rejected},
            {"relinearizations", c.relinearizations},
            {"history", history},
            {"held", held},
            {"x_fixed", Vec(c.x_fixed)},
            {"status", identification::TrackingStatusName(c.status)},
            {"small_steps", c.small_steps}};
  // The release awaiting its second look (additive key; none: no look pending).
  if (c.second_look_onset >= 0) j["second_look_onset"] = c.second_look_onset;
  // Its directions are alternatives (additive key; none: one step along all of them).
  if (c.second_look_onset >= 0 && c.second_look_alternatives) j["second_look_alternatives"] = true;
  // The effects of the state's model (additive key; none: geometric).
  if (!f.effects_json.empty()) j["effects"] = json::parse(f.effects_json);
  // A released change's covariance before its pose (additive key; none: no change released).
  if (!c.inflations.empty()) {
    json inflations = json::array();
    for (const Eigen::MatrixXd& m : c.inflations) inflations.push_back(Mat(m));
    j["inflations"] = inflations;
  }
  // The contexts of an extended identifier's poses (additive key; none: a geometric one).
  if (!c.contexts.empty()) {
    json contexts = json::array();
    for (const auto& ctx : c.contexts) contexts.push_back(ContextJson(ctx));
    j["contexts"] = contexts;
  }
  return j.dump() + "\n";
}

CheckpointFile ParseCheckpoint(const std::string& text) {
  json j;
  try {
    j = json::parse(text);
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("checkpoint: not JSON: ") + e.what());
  }
  const std::string schema = j.is_object() ? j.value("schema", "") : "";
  if (schema != kSchema && schema != kSchemaV2 && schema != kSchemaV1)
    throw std::runtime_error(std::string("checkpoint: schema: expected ") + kSchema + " (or " +
                             kSchemaV2 + ", " + kSchemaV1 + ")");
  try {
    CheckpointFile f;
    f.model_id = At(j, "model_id", "").get<std::string>();
    f.utime = At(j, "utime", "").get<int64_t>();
    f.last_pose_index = At(j, "last_pose_index", "").get<int64_t>();
    auto& c = f.checkpoint;
    c.x0 = ToVec(At(j, "x0", ""), "x0");
    c.x = ToVec(At(j, "x", ""), "x");
    c.x_lin = ToVec(At(j, "x_lin", ""), "x_lin");
    c.P0 = ToMat(At(j, "P0", ""), "P0");
    c.P = ToMat(At(j, "P", ""), "P");
    c.accepted = At(j, "accepted", "").get<int>();
    c.rejected = At(j, "rejected", "").get<int>();
    c.relinearizations = At(j, "relinearizations", "").get<int>();
    const json& history = At(j, "history", "");
    for (size_t i = 0; i < history.size(); ++i) {
      const std::string path = "history[" + std::to_string(i) + "].";
      c.history.push_back(MeasurementFromJson(history[i], path));
    }
    if (schema == kSchema) c.x_fixed = ToVec(At(j, "x_fixed", ""), "x_fixed");
    // Tracking (additive keys; absent in checkpoints written before change detection).
    if (j.contains("status")) {
      const std::string status = At(j, "status", "").get<std::string>();
      bool known = false;
      for (auto t :
           {identification::TrackingStatus::kConverging, identification::TrackingStatus::kConverged,
            identification::TrackingStatus::kChangeDetected,
            identification::TrackingStatus::kReconverging})
        if (status == identification::TrackingStatusName(t)) c.status = t, known = true;
      if (!known) throw std::runtime_error("checkpoint: status: unknown value '" + status + "'");
    }
    if (j.contains("small_steps")) c.small_steps = At(j, "small_steps", "").get<int>();
    if (j.contains("second_look_onset"))
      c.second_look_onset = At(j, "second_look_onset", "").get<int>();
    if (j.contains("second_look_alternatives")) {
      const json& v = At(j, "second_look_alternatives", "");
      if (!v.is_boolean())
        throw std::runtime_error("checkpoint: second_look_alternatives: not true or false");
      c.second_look_alternatives = v.get<bool>();
    }
    if (j.contains("inflations")) {
      const json& inflations = At(j, "inflations", "");
      if (!inflations.is_array()) throw std::runtime_error("checkpoint: inflations: not an array");
      for (size_t i = 0; i < inflations.size(); ++i)
        c.inflations.push_back(ToMat(inflations[i], "inflations[" + std::to_string(i) + "]"));
    }
    if (j.contains("effects")) {
      const json& effects = At(j, "effects", "");
      if (!effects.is_array()) throw std::runtime_error("checkpoint: effects: not an array");
      f.effects_json = effects.dump();
    }
    if (j.contains("contexts")) {
      const json& contexts = At(j, "contexts", "");
      if (!contexts.is_array()) throw std::runtime_error("checkpoint: contexts: not an array");
      for (size_t i = 0; i < contexts.size(); ++i)
        c.contexts.push_back(ContextFromJson(contexts[i], "contexts[" + std::to_string(i) + "]."));
    }
    if (schema != kSchemaV1) {
      const json& held = At(j, "held", "");
      if (!held.is_array()) throw std::runtime_error("checkpoint: held: not an array");
      for (size_t i = 0; i < held.size(); ++i) {
        const std::string path = "held[" + std::to_string(i) + "].";
        HeldPose h;
        h.utime = At(held[i], "utime", path).get<int64_t>();
        h.pose_index = At(held[i], "pose_index", path).get<int64_t>();
        h.z = MeasurementFromJson(At(held[i], "measurement", path), path + "measurement.");
        if (held[i].contains("context"))  // additive: absent before contexts were carried
          h.context = ContextFromJson(held[i]["context"], path + "context.");
        f.held.push_back(std::move(h));
      }
    }
    return f;
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(std::string("checkpoint: wrong type: ") + e.what());
  }
}

void SaveCheckpoint(const std::filesystem::path& path, const CheckpointFile& c) {
  io::AtomicWriteFile(path, CheckpointText(c));
}

std::string UntrustedCheckpointTime(const CheckpointFile& c, int64_t ceiling_us) {
  const auto beyond = [&](const std::string& key, int64_t utime) {
    return key + ": " + std::to_string(utime) + " is beyond the time ceiling (" +
           std::to_string(ceiling_us) + ")";
  };
  if (c.utime > ceiling_us) return beyond("utime", c.utime);
  for (size_t i = 0; i < c.held.size(); ++i)
    if (c.held[i].utime > ceiling_us)
      return beyond("held[" + std::to_string(i) + "].utime", c.held[i].utime);
  return "";
}

CheckpointFile LoadCheckpoint(const std::filesystem::path& path) {
  try {
    return ParseCheckpoint(io::ReadFile(path));
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(path.string() + ": " + e.what());
  }
}

}  // namespace rcal::transport
