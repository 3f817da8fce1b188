#include "rcal/sim/effects.hpp"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"

namespace rcal::sim {
namespace {

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(item);
  return out;
}

int JointIndex(const std::string& name, const kinematics::KinematicModel& model,
               const std::string& text, const char* what = "effect") {
  for (int j = 0; j < model.num_joints(); ++j)
    if (model.joints()[j].name == name) return j;
  if (name.size() >= 2 && name[0] == 'j') {
    try {
      size_t used = 0;
      const int k = std::stoi(name.substr(1), &used);
      if (used == name.size() - 1 && k >= 1 && k <= model.num_joints()) return k - 1;
    } catch (const std::exception&) {
    }
  }
  throw std::invalid_argument(std::string(what) + " '" + text + "': no joint '" + name +
                              "' (use j1..j" + std::to_string(model.num_joints()) +
                              " or a joint name)");
}

}  // namespace

TruthEffect ParseEffectSpec(const std::string& text, const kinematics::KinematicModel& model) {
  const size_t eq = text.find('=');
  if (eq == std::string::npos)
    throw std::invalid_argument("effect '" + text + "': expected CAUSE[:JOINT]=VALUE");
  const std::vector<std::string> head = Split(text.substr(0, eq), ':');
  if (head.empty()) throw std::invalid_argument("effect '" + text + "': no cause");
  if (head[0] == "time_offset")
    throw std::invalid_argument("effect '" + text +
                                "': time_offset applies to streamed data only, not to poses");
  const auto cause = kinematics::ParseEffectCause(head[0]);
  if (!cause)
    throw std::invalid_argument("effect '" + text + "': unknown cause '" + head[0] +
                                "' (joint_compliance, joint_periodic, joint_scale, thermal, "
                                "backlash)");
  TruthEffect t;
  t.effect.cause = *cause;
  if (*cause == kinematics::EffectCause::kThermal) {
    if (head.size() > 2 || (head.size() == 2 && head[1] != "time" && head[1] != "temperature"))
      throw std::invalid_argument("effect '" + text + "': thermal[:time|:temperature]=VALUE");
    if (head.size() == 2 && head[1] == "time") {
      t.effect.thermal_source = kinematics::Effect::ThermalSource::kTime;
      t.effect.reference = 0.0;
    }
  } else {
    if (head.size() < 2) throw std::invalid_argument("effect '" + text + "': which joint?");
    t.effect.joint = JointIndex(head[1], model, text);
    if (head.size() == 3 && *cause == kinematics::EffectCause::kJointPeriodic &&
        (head[2] == "h1" || head[2] == "h2"))
      t.effect.harmonic = head[2] == "h2" ? 2 : 1;
    else if (head.size() > 2)
      throw std::invalid_argument("effect '" + text + "': unexpected '" + head[2] + "'");
  }
  const std::vector<std::string> vals = Split(text.substr(eq + 1), ',');
  const int n = t.effect.num_params();
  if (vals.empty() || static_cast<int>(vals.size()) > n)
    throw std::invalid_argument("effect '" + text + "': expected " +
                                (n == 1 ? std::string("one value") : "one or two values"));
  t.values = Eigen::VectorXd::Zero(n);
  for (size_t i = 0; i < vals.size(); ++i) {
    try {
      size_t used = 0;
      t.values(i) = std::stod(vals[i], &used);
      if (used != vals[i].size() || !std::isfinite(t.values(i))) throw std::invalid_argument("");
    } catch (const std::exception&) {
      throw std::invalid_argument("effect '" + text + "': '" + vals[i] + "' is not a number");
    }
  }
  return t;
}

JointOffsetStepSpec ParseJointOffsetStep(const std::string& text,
                                         const kinematics::KinematicModel& model) {
  const size_t eq = text.find('='), at = text.rfind('@');
  if (eq == std::string::npos || at == std::string::npos || at < eq)
    throw std::invalid_argument("offset step '" + text + "': expected JOINT=DELTA@STOP");
  JointOffsetStepSpec spec;
  spec.joint = JointIndex(text.substr(0, eq), model, text, "offset step");
  const std::string delta = text.substr(eq + 1, at - eq - 1), stop = text.substr(at + 1);
  try {
    size_t used = 0;
    spec.delta = std::stod(delta, &used);
    if (used != delta.size()) throw std::invalid_argument("");
  } catch (const std::exception&) {
    throw std::invalid_argument("offset step '" + text + "': DELTA '" + delta +
                                "' is not a number [rad | m]");
  }
  // An encoder re-mastered a few mrad off, not a different arm: beyond 0.1 it is a unit mistake.
  if (!std::isfinite(spec.delta) || std::abs(spec.delta) > 0.1)
    throw std::invalid_argument("offset step '" + text + "': DELTA " + delta +
                                " is beyond 0.1 [rad | m] (SI units: 1 mrad is 1e-3)");
  try {
    size_t used = 0;
    spec.stop = std::stoi(stop, &used);
    if (used != stop.size()) throw std::invalid_argument("");
  } catch (const std::exception&) {
    throw std::invalid_argument("offset step '" + text + "': STOP '" + stop +
                                "' is not a stop number");
  }
  if (spec.stop < 1)
    throw std::invalid_argument("offset step '" + text + "': STOP must be 1 or more");
  return spec;
}

EffectTruth MakeEffectTruth(const kinematics::KinematicModel& model,
                            const std::vector<TruthEffect>& effects,
                            const kinematics::GravityModel& gravity) {
  std::vector<kinematics::Effect> fx;
  for (const auto& t : effects) fx.push_back(t.effect);
  EffectTruth out{kinematics::ExtendedModel(model, fx, gravity), {}};
  out.e = out.model.NoEffects();
  for (size_t k = 0; k < effects.size(); ++k) {
    if (effects[k].values.size() != effects[k].effect.num_params())
      throw std::invalid_argument("MakeEffectTruth: wrong number of values");
    out.e.segment(out.model.effect_offset(k), effects[k].values.size()) = effects[k].values;
  }
  return out;
}

double WarmedTo(const SessionSettings& s, double t_s) {
  return s.temperature_start_c +
         s.temperature_rise_c * (1.0 - std::exp(-t_s / s.warmup_time_constant_s));
}

std::vector<kinematics::EffectContext> SampleSession(int num_joints, int count,
                                                     const SessionSettings& s, Rng& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_int_distribution<int> coin(0, 1);
  std::uniform_int_distribution<size_t> pick(0,
                                             s.payloads_kg.empty() ? 0 : s.payloads_kg.size() - 1);
  std::vector<kinematics::EffectContext> out(count);
  for (int i = 0; i < count; ++i) {
    auto& c = out[i];
    c.time_s = count > 1 ? s.session_s * i / (count - 1) : 0.0;
    c.temperature_c = WarmedTo(s, c.time_s) + s.temperature_noise_c * n(rng);
    c.payload_kg = s.payloads_kg.empty() ? 0.0 : s.payloads_kg[pick(rng)];
    c.dq_sign = Eigen::VectorXi::Ones(num_joints);
    if (s.random_approach)
      for (int j = 0; j < num_joints; ++j) c.dq_sign(j) = coin(rng) ? 1 : -1;
  }
  return out;
}

kinematics::EffectContext StopContext(double t_s, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& q_before, const SessionSettings& s,
                                      Rng& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_int_distribution<size_t> pick(0,
                                             s.payloads_kg.empty() ? 0 : s.payloads_kg.size() - 1);
  kinematics::EffectContext c;
  c.time_s = t_s;
  const double noise = n(rng);
  const size_t payload = pick(rng);
  c.temperature_c = WarmedTo(s, t_s) + s.temperature_noise_c * noise;
  c.payload_kg = s.payloads_kg.empty() ? 0.0 : s.payloads_kg[payload];
  c.dq_sign = Eigen::VectorXi::Zero(q.size());
  if (q_before.size() == q.size())
    for (int j = 0; j < q.size(); ++j)
      c.dq_sign(j) = q(j) > q_before(j) ? 1 : (q(j) < q_before(j) ? -1 : 0);
  return c;
}

kinematics::PoseMeasurement MeasurePoseWithEffects(const EffectTruth& truth,
                                                   const Eigen::VectorXd& x_true,
                                                   const Eigen::VectorXd& q,
                                                   const kinematics::EffectContext& ctx,
                                                   const PoseNoise& noise, Rng& rng) {
  return MeasureTruePose(truth.model.Forward(q, ctx, x_true, truth.e), q, noise, rng);
}

namespace {
int MarkerSlots(const EffectTruth& truth) {
  return std::max<int>(1, static_cast<int>(truth.model.base().markers().size()));
}
}  // namespace

std::vector<kinematics::PoseMeasurement> MeasurePosesWithEffects(
    const EffectTruth& truth, const Eigen::VectorXd& x_true, const std::vector<Eigen::VectorXd>& qs,
    const std::vector<kinematics::EffectContext>& contexts, const PoseNoise& noise, Rng& rng) {
  if (qs.size() != contexts.size())
    throw std::invalid_argument("MeasurePosesWithEffects: one context per pose");
  std::vector<kinematics::PoseMeasurement> out;
  for (size_t i = 0; i < qs.size(); ++i)
    for (int k = 0; k < MarkerSlots(truth); ++k) {
      out.push_back(
          MeasureTruePose(truth.model.ForMarker(k).Forward(qs[i], contexts[i], x_true, truth.e),
                          qs[i], noise, rng));
      out.back().marker = k;
    }
  return out;
}

}  // namespace rcal::sim

namespace rcal::sim {

TruthEffect EffectOfSize(const kinematics::KinematicModel& model, const kinematics::Effect& effect,
                         const std::vector<Eigen::VectorXd>& qs,
                         const std::vector<kinematics::EffectContext>& contexts,
                         const Eigen::VectorXd& x, double rms_m, Rng& rng,
                         const kinematics::GravityModel& gravity, bool beyond_geometry) {
  TruthEffect t{effect, Eigen::VectorXd::Zero(effect.num_params())};
  std::uniform_real_distribution<double> u(0.0, 2.0 * 3.14159265358979323846);
  std::uniform_int_distribution<int> coin(0, 1);
  if (effect.num_params() == 2) {
    const double phase = u(rng);
    t.values << std::cos(phase), std::sin(phase);
  } else {
    t.values(0) = coin(rng) ? 1.0 : -1.0;
  }
  const kinematics::ExtendedModel ext(model, {effect}, gravity);
  const int n = static_cast<int>(qs.size());
  Eigen::VectorXd d(3 * n);
  Eigen::MatrixXd G(3 * n, model.num_params());
  for (int i = 0; i < n; ++i) {
    Eigen::MatrixXd Jx, Je;
    ext.Jacobians(qs[i], contexts[i], x, ext.NoEffects(), &Jx, &Je);
    d.segment<3>(3 * i) = Je.topRows<3>() * t.values;
    G.middleRows<3>(3 * i) = Jx.topRows<3>();
  }
  const double total = n == 0 ? 0.0 : std::sqrt(d.squaredNorm() / n);
  if (beyond_geometry && n > 0) {
    for (int c = 0; c < G.cols(); ++c)
      if (G.col(c).norm() > 0) G.col(c).normalize();
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(G);
    qr.setThreshold(1e-10);
    const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(G.rows(), qr.rank());
    d -= Q * (Q.transpose() * d);
  }
  const double rms = n == 0 ? 0.0 : std::sqrt(d.squaredNorm() / n);
  if (!(rms > 1e-9 * total))
    throw std::invalid_argument(
        "EffectOfSize: the effect does not move the marker beyond what geometry absorbs");
  t.values *= rms_m / rms;
  return t;
}

}  // namespace rcal::sim
