#include "rcal/discrepancy/analysis.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>

#include "rcal/discrepancy/significance.hpp"
#include "rcal/identification/chi_square.hpp"

namespace rcal::discrepancy {
namespace {

using kinematics::Effect;
using kinematics::EffectCause;

constexpr double kInf = std::numeric_limits<double>::infinity();

// Φ⁻¹(p) by bisection on erfc (accurate enough for critical values).
double NormalQuantile(double p) {
  double lo = -40, hi = 40;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double Mean(const std::vector<double>& v) {
  return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
}

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0.0 : std::sqrt(s / v.size());
}

// One-sided paired z of the improvement a − b (positive: b better).
double PairedZ(const std::vector<double>& a, const std::vector<double>& b) {
  const size_t n = a.size();
  if (n < 2) return 0;
  std::vector<double> d(n);
  for (size_t i = 0; i < n; ++i) d[i] = a[i] - b[i];
  const double m = Mean(d);
  double ss = 0;
  for (double x : d) ss += (x - m) * (x - m);
  const double sd = std::sqrt(ss / (n - 1));
  // Zero spread: every pose changed by the same amount, z = ±∞ (written as a bound,
  // significance.hpp; was 1e9, a number that looked measured).
  if (sd <= 0) return m > 0 ? kInf : m < 0 ? -kInf : 0.0;
  return m / (sd / std::sqrt(static_cast<double>(n)));
}

std::string JointName(const kinematics::KinematicModel& model, int j) {
  return model.joints()[j].name;
}

// Every effect that could be tried on this model and data (eligibility by the data's contents).
std::vector<Effect> EligibleEffects(const kinematics::KinematicModel& model, const PoseData& data,
                                    const std::vector<int>& fit, const AnalysisSettings& s,
                                    std::vector<std::string>& skipped) {
  std::vector<Effect> out;
  const int n = model.num_joints();
  const kinematics::ExtendedModel probe(model, {}, s.gravity);
  Eigen::MatrixXd tau(fit.size(), n), q(fit.size(), n);
  std::vector<int> pos(n, 0), neg(n, 0);
  std::vector<double> temp, time;
  for (size_t k = 0; k < fit.size(); ++k) {
    const auto& m = data.measurements[fit[k]];
    const auto& c = data.contexts[fit[k]];
    q.row(k) = m.q.transpose();
    tau.row(k) = probe.GravityTorque(m.q, c.payload_kg).transpose();
    for (int j = 0; j < n && j < c.dq_sign.size(); ++j) {
      pos[j] += c.dq_sign(j) > 0;
      neg[j] += c.dq_sign(j) < 0;
    }
    temp.push_back(c.temperature_c);
    time.push_back(c.time_s);
  }
  const auto spread = [](const Eigen::VectorXd& v) { return v.maxCoeff() - v.minCoeff(); };
  for (int j = 0; j < n; ++j) {
    const std::string name = JointName(model, j);
    const bool rev = model.joints()[j].type == kinematics::JointType::kRevolute;
    if (spread(tau.col(j)) > 1.0)
      out.push_back({EffectCause::kJointCompliance, j});
    else
      skipped.push_back("joint_compliance " + name + ": gravity torque does not vary");
    if (rev) {
      out.push_back({EffectCause::kJointPeriodic, j, 1});
      if (s.second_harmonic) out.push_back({EffectCause::kJointPeriodic, j, 2});
    }
    if (spread(q.col(j)) > 0.05)
      out.push_back({EffectCause::kJointScale, j});
    else
      skipped.push_back("joint_scale " + name + ": joint hardly moves");
    if (pos[j] >= 3 && neg[j] >= 3)
      out.push_back({EffectCause::kBacklash, j});
    else
      skipped.push_back("backlash " + name +
                        ": approach direction (dq) not given or not both ways ≥ 3 times");
  }
  const auto all_finite = [](const std::vector<double>& v) {
    return !v.empty() && std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
  };
  if (all_finite(temp) &&
      *std::max_element(temp.begin(), temp.end()) - *std::min_element(temp.begin(), temp.end()) >=
          s.min_temperature_spread_c) {
    Effect t{EffectCause::kThermal};
    t.reference = Mean(temp);
    out.push_back(t);
  } else {
    skipped.push_back("thermal (temperature): no temperature column, or it hardly varies");
  }
  if (all_finite(time) &&
      *std::max_element(time.begin(), time.end()) > *std::min_element(time.begin(), time.end())) {
    Effect t{EffectCause::kThermal};
    t.thermal_source = Effect::ThermalSource::kTime;
    t.reference = Mean(time);
    out.push_back(t);
  } else {
    skipped.push_back("thermal (time): no time column");
  }
  return out;
}

// The whitened linearised problem around the base fit, over all poses.
struct Linearized {
  kinematics::ExtendedModel ext;  // model + every candidate effect
  std::vector<int> identified;
  int num_geo = 0;
  std::vector<Eigen::VectorXd> r;   // whitened residual per pose
  std::vector<Eigen::MatrixXd> J;   // whitened [J_x(identified) J_e(all)] per pose
  std::vector<Eigen::Vector3d> rp;  // position residual [m]
  std::vector<Eigen::MatrixXd> Jp;  // position rows, unwhitened
  std::vector<int> fit, test;
  std::vector<std::vector<int>> fold_sets;  // per repeat: fold id per fit pose (index in fit)
  std::vector<int> config;                  // configuration id per pose (all poses)
  int groups = 0;                           // configurations among the fit poses
  int folds = 0;

  // Seeded fold assignments over the fit poses (k-fold, repeated; leave-one-out when k ≥ the
  // configurations). The rows of one configuration (several markers measured at one stop, or a
  // stop measured again) go to one fold together: they share its joint readings and whatever
  // the model misses there, and a fold that fitted the others would flatter the one held out.
  void AssignFolds(int k, int repeats, unsigned seed) {
    const int nf = static_cast<int>(fit.size());
    std::vector<int> group(nf), first_of;  // group per fit pose; groups in order of appearance
    for (int i = 0; i < nf; ++i) {
      int g = -1;
      for (size_t j = 0; j < first_of.size() && g < 0; ++j)
        if (config[fit[first_of[j]]] == config[fit[i]]) g = static_cast<int>(j);
      if (g < 0) {
        g = static_cast<int>(first_of.size());
        first_of.push_back(i);
      }
      group[i] = g;
    }
    groups = static_cast<int>(first_of.size());
    folds = std::min(std::max(2, k), groups);
    fold_sets.clear();
    std::mt19937_64 rng(seed);
    for (int rep = 0; rep < std::max(1, repeats); ++rep) {
      std::vector<int> order(groups), fold_of(groups), fold(nf);
      std::iota(order.begin(), order.end(), 0);
      std::shuffle(order.begin(), order.end(), rng);
      for (int i = 0; i < groups; ++i) fold_of[order[i]] = i % folds;
      for (int i = 0; i < nf; ++i) fold[i] = fold_of[group[i]];
      fold_sets.push_back(fold);
      if (folds == groups) break;  // leave-one-out: one assignment is all there is
    }
  }

  std::vector<int> Columns(const std::vector<int>& effects) const {
    std::vector<int> c(num_geo);
    std::iota(c.begin(), c.end(), 0);
    for (int k : effects)
      for (int i = 0; i < ext.effects()[k].num_params(); ++i)
        c.push_back(num_geo + ext.effect_offset(k) + i);
    return c;
  }

  // Least squares on `train` poses over `cols`; returns δ (cols order).
  Eigen::VectorXd Solve(const std::vector<int>& train, const std::vector<int>& cols) const {
    int rows = 0;
    for (int i : train) rows += r[i].size();
    Eigen::MatrixXd A(rows, cols.size());
    Eigen::VectorXd b(rows);
    int row = 0;
    for (int i : train) {
      const int d = r[i].size();
      for (size_t c = 0; c < cols.size(); ++c) A.block(row, c, d, 1) = J[i].col(cols[c]);
      b.segment(row, d) = r[i];
      row += d;
    }
    Eigen::VectorXd scale(cols.size());
    for (size_t c = 0; c < cols.size(); ++c) {
      const double nrm = A.col(c).norm();
      scale(c) = nrm > 0 ? 1.0 / nrm : 1.0;
      A.col(c) *= scale(c);
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    qr.setThreshold(1e-10);
    return (qr.solve(b).array() * scale.array()).matrix();
  }

  // Held-out whitened squared residual and squared position error of pose i after δ.
  std::pair<double, double> Score(int i, const std::vector<int>& cols,
                                  const Eigen::VectorXd& delta) const {
    Eigen::VectorXd ri = r[i];
    Eigen::Vector3d pi = rp[i];
    for (size_t c = 0; c < cols.size(); ++c) {
      ri -= J[i].col(cols[c]) * delta(c);
      pi -= Jp[i].col(cols[c]) * delta(c);
    }
    return {ri.squaredNorm(), pi.squaredNorm()};
  }

  struct Eval {
    std::vector<double> score;     // whitened squared residual per held-out pose
    std::vector<double> position;  // position error per held-out pose [m]
  };

  // k-fold (repeated) over the fit poses.
  Eval CrossValidate(const std::vector<int>& effects) const {
    const std::vector<int> cols = Columns(effects);
    const size_t n = fit.size();
    Eval out{std::vector<double>(n, 0.0), std::vector<double>(n, 0.0)};
    for (const auto& fold : fold_sets) {
      for (int f = 0; f < folds; ++f) {
        std::vector<int> train, held;
        for (size_t k = 0; k < n; ++k) (fold[k] == f ? held : train).push_back(k);
        if (held.empty()) continue;
        std::vector<int> tr;
        for (int k : train) tr.push_back(fit[k]);
        const Eigen::VectorXd delta = Solve(tr, cols);
        for (int k : held) {
          const auto [s, p] = Score(fit[k], cols, delta);
          out.score[k] += s / fold_sets.size();
          out.position[k] += p / fold_sets.size();
        }
      }
    }
    for (double& p : out.position) p = std::sqrt(p);
    return out;
  }

  // Fit on all fit poses, judge on the test poses.
  Eval Split(const std::vector<int>& effects) const {
    const std::vector<int> cols = Columns(effects);
    const Eigen::VectorXd delta = Solve(fit, cols);
    Eval out;
    for (int i : test) {
      const auto [s, p] = Score(i, cols, delta);
      out.score.push_back(s);
      out.position.push_back(std::sqrt(p));
    }
    return out;
  }
};

struct Prepared {
  identification::CalibrationFit base_fit;
  std::vector<kinematics::PoseMeasurement> ms;  // weighted with the noise used
  Linearized lin;
  std::vector<std::string> skipped;
  // Geometry steps (PoseData::steps): indexed into the fit poses, their amplitudes in the
  // piecewise base fit, and the geometry each pose (all poses) is linearised at.
  std::vector<identification::GeometryStep> fit_steps;
  std::vector<Eigen::VectorXd> step_amplitudes;
  std::vector<Eigen::VectorXd> x_pose;
  int num_step_params = 0;
};

// The geometry steps of `data` indexed into its fit poses (`fit`: indices into the poses). Throws
// std::invalid_argument naming the step when it has no fit pose on one side, or does not fit the
// model.
std::vector<identification::GeometryStep> FitSteps(const kinematics::KinematicModel& model,
                                                   const PoseData& data,
                                                   const std::vector<int>& fit) {
  std::vector<identification::GeometryStep> out;
  for (size_t k = 0; k < data.steps.size(); ++k) {
    const auto& st = data.steps[k];
    const std::string name = "discrepancy: steps[" + std::to_string(k) + "]";
    if (st.directions.rows() != model.num_params() || st.directions.cols() < 1 ||
        !st.directions.allFinite())
      throw std::invalid_argument(name + ".directions: " + std::to_string(model.num_params()) +
                                  " finite rows and at least one column expected");
    const int before = static_cast<int>(
        std::count_if(fit.begin(), fit.end(), [&](int i) { return i < st.first_pose; }));
    if (before < 1 || before >= static_cast<int>(fit.size()))
      throw std::invalid_argument(name + ".first_pose " + std::to_string(st.first_pose) +
                                  ": no fit pose " + (before < 1 ? "before" : "from") + " it");
    out.push_back({before, st.directions});
  }
  return out;
}

// The piecewise geometric fit (the file comment's steps): the identified parameters and the
// steps' amplitudes from the base fit, the noise re-estimated from its residuals as Calibrate
// does (variance components, corrected for the parameters). Updates p.base_fit's x and noise,
// p.ms's weights and p.step_amplitudes.
void FitPiecewise(const kinematics::KinematicModel& model, const PoseData& data,
                  const AnalysisSettings& s, Prepared& p) {
  const kinematics::ExtendedModel geometric(model, {}, s.gravity);
  std::vector<kinematics::PoseMeasurement> fit_ms;
  std::vector<kinematics::EffectContext> fit_ctx;
  for (int i : p.lin.fit) {
    fit_ms.push_back(p.ms[i]);
    fit_ctx.push_back(data.contexts[i]);
  }
  const int rounds = s.estimate_noise ? 3 : 1;
  for (int it = 0; it < rounds; ++it) {
    if (s.estimate_noise)
      identification::SetNoise(fit_ms, p.base_fit.position_sigma_m,
                               p.base_fit.orientation_sigma_rad);
    const identification::ExtendedFit f =
        identification::FitExtended(geometric, p.base_fit.identified, fit_ms, fit_ctx, p.base_fit.x,
                                    geometric.NoEffects(), false, p.fit_steps);
    p.base_fit.x = f.x;
    p.step_amplitudes = f.step_amplitudes;
    if (!s.estimate_noise) break;
    // Variance components as Calibrate estimates them, at each pose's own geometry.
    const identification::ResidualSums sums =
        identification::SumResiduals(model, fit_ms, [&](size_t k) {
          return identification::GeometryAt(f.x, p.fit_steps, f.step_amplitudes,
                                            static_cast<int>(k));
        });
    const int n_p = sums.position_values, n_o = sums.orientation_values;
    const double params = static_cast<double>(p.base_fit.identified.size() + p.num_step_params);
    const double redundancy = std::max(0.05, 1.0 - params / (n_p + n_o));
    p.base_fit.position_sigma_m = std::sqrt(sums.position_m2 / (n_p * redundancy));
    if (n_o > 0)
      p.base_fit.orientation_sigma_rad = std::sqrt(sums.orientation_rad2 / (n_o * redundancy));
  }
  if (s.estimate_noise)
    identification::SetNoise(p.ms, p.base_fit.position_sigma_m, p.base_fit.orientation_sigma_rad);
}

Prepared Prepare(const kinematics::KinematicModel& model, const PoseData& data,
                 const AnalysisSettings& s, const std::vector<Effect>* only) {
  const size_t n = data.measurements.size();
  if (data.contexts.size() != n)
    throw std::invalid_argument("discrepancy: one context per measurement");
  if (!data.is_test.empty() && data.is_test.size() != n)
    throw std::invalid_argument("discrepancy: is_test must be empty or one flag per measurement");
  for (size_t i = 0; i < n; ++i) {
    const std::string why = kinematics::Validate(model, data.measurements[i]);
    if (!why.empty())
      throw std::invalid_argument("discrepancy: measurement " + std::to_string(i) + ": " + why);
  }
  Prepared p;
  for (size_t i = 0; i < n; ++i)
    (!data.is_test.empty() && data.is_test[i] ? p.lin.test : p.lin.fit).push_back(i);
  if (p.lin.fit.size() < 6) throw std::invalid_argument("discrepancy: fewer than 6 fit poses");
  std::vector<kinematics::PoseMeasurement> fit_ms;
  for (int i : p.lin.fit) fit_ms.push_back(data.measurements[i]);
  identification::CalibrationSettings cs;
  cs.estimate_noise = s.estimate_noise;
  p.base_fit = identification::Calibrate(model, fit_ms, cs);
  p.ms = data.measurements;
  p.fit_steps = FitSteps(model, data, p.lin.fit);
  for (const auto& st : p.fit_steps) p.num_step_params += st.directions.cols();
  if (s.estimate_noise)
    identification::SetNoise(p.ms, p.base_fit.position_sigma_m, p.base_fit.orientation_sigma_rad);
  if (!p.fit_steps.empty()) FitPiecewise(model, data, s, p);
  for (size_t i = 0; i < n; ++i)
    p.x_pose.push_back(identification::GeometryAt(p.base_fit.x, data.steps, p.step_amplitudes,
                                                  static_cast<int>(i)));

  const std::vector<Effect> effects =
      only ? *only : EligibleEffects(model, data, p.lin.fit, s, p.skipped);
  Linearized& L = p.lin;
  L.ext = kinematics::ExtendedModel(model, effects, s.gravity);
  L.identified = p.base_fit.identified;
  // The geometry's columns: the identified parameters, then each step's directions (zero before
  // the step), so every fit below treats a known step as part of the geometry.
  const int num_identified = static_cast<int>(L.identified.size());
  L.num_geo = num_identified + p.num_step_params;
  const Eigen::VectorXd e0 = L.ext.NoEffects();
  const int cols = L.num_geo + L.ext.num_effect_params();
  for (size_t i = 0; i < n; ++i) {
    const auto& m = p.ms[i];
    Eigen::MatrixXd Jx, Je;
    L.ext.ForMarker(m.marker).Jacobians(m.q, data.contexts[i], p.x_pose[i], e0, &Jx, &Je);
    const int d = m.dimension();
    Eigen::MatrixXd Jfull = Eigen::MatrixXd::Zero(d, cols);
    for (int c = 0; c < num_identified; ++c) Jfull.col(c) = Jx.col(L.identified[c]).head(d);
    for (size_t k = 0, c = num_identified; k < data.steps.size(); ++k) {
      const auto& D = data.steps[k].directions;
      if (data.steps[k].first_pose <= static_cast<int>(i))
        Jfull.middleCols(c, D.cols()) = (Jx * D).topRows(d);
      c += D.cols();
    }
    if (Je.cols() > 0) Jfull.rightCols(Je.cols()) = Je.topRows(d);
    const Eigen::VectorXd r = kinematics::Residual(model, m, p.x_pose[i]);
    const Eigen::LLT<Eigen::MatrixXd> llt(m.covariance);
    L.r.push_back(llt.matrixL().solve(r));
    L.J.push_back(llt.matrixL().solve(Jfull));
    L.rp.push_back(r.head<3>());
    L.Jp.push_back(Jfull.topRows(3));
  }
  L.config = identification::ConfigurationGroups(data.measurements);
  L.AssignFolds(s.folds, s.repeats, s.seed);
  return p;
}

// Effects (indices into lin.ext.effects()) whose columns the geometry nearly explains.
std::vector<bool> Identifiable(const Linearized& L, double min_novelty,
                               std::vector<std::string>& skipped,
                               const kinematics::KinematicModel& model) {
  int rows = 0;
  for (int i : L.fit) rows += L.r[i].size();
  const int cols = L.num_geo + L.ext.num_effect_params();
  Eigen::MatrixXd A(rows, cols);
  int row = 0;
  for (int i : L.fit) {
    A.middleRows(row, L.r[i].size()) = L.J[i];
    row += L.r[i].size();
  }
  Eigen::MatrixXd G = A.leftCols(L.num_geo);
  for (int c = 0; c < G.cols(); ++c)
    if (G.col(c).norm() > 0) G.col(c).normalize();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(G);
  qr.setThreshold(1e-10);
  const int rank = qr.rank();
  // Thin Q: the first `rank` columns only (rows × rank, not rows × rows).
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(G.rows(), rank);
  std::vector<bool> ok(L.ext.effects().size(), true);
  for (size_t k = 0; k < L.ext.effects().size(); ++k) {
    for (int i = 0; i < L.ext.effects()[k].num_params(); ++i) {
      const Eigen::VectorXd c = A.col(L.num_geo + L.ext.effect_offset(k) + i);
      const double nc = c.norm();
      const double novelty = nc > 0 ? (c - Q * (Q.transpose() * c)).norm() / nc : 0.0;
      if (novelty < min_novelty) ok[k] = false;
    }
    if (!ok[k])
      skipped.push_back(Describe(model, L.ext.effects()[k]) +
                        ": not separable from the geometric parameters at these poses");
  }
  return ok;
}

// Greedy forward selection among `pool` (indices into L.ext.effects()) on L's k-fold held-out
// residuals: each round adds the candidate with the lowest mean held-out whitened squared
// residual if its paired z against the current model exceeds Φ⁻¹(1 − α/m).
struct Selection {
  std::vector<int> selected;
  std::vector<double> z;
  Linearized::Eval eval;  // k-fold evaluation of the selected model
};
Selection SelectGreedy(const Linearized& L, const std::vector<int>& pool, const AnalysisSettings& s,
                       std::vector<SelectionRound>* rounds) {
  const auto& effects = L.ext.effects();
  Selection out;
  std::vector<int>& selected = out.selected;
  Linearized::Eval& current = out.eval;
  current = L.CrossValidate({});
  while (static_cast<int>(selected.size()) < s.max_effects) {
    SelectionRound round;
    round.heldout_rms_current_m = Rms(current.position);
    std::vector<Linearized::Eval> evals;
    std::vector<int> ids;
    for (int k : pool) {
      if (std::find(selected.begin(), selected.end(), k) != selected.end()) continue;
      std::vector<int> trial = selected;
      trial.push_back(k);
      evals.push_back(L.CrossValidate(trial));
      ids.push_back(k);
      round.tried.push_back(effects[k]);
      round.z.push_back(PairedZ(current.score, evals.back().score));
    }
    if (ids.empty()) break;
    int best = 0;
    for (size_t c = 1; c < ids.size(); ++c)
      if (Mean(evals[c].score) < Mean(evals[best].score)) best = c;
    round.best = best;
    round.z_critical = NormalQuantile(1.0 - s.alpha / ids.size());
    round.heldout_rms_best_m = Rms(evals[best].position);
    round.accepted = round.z[best] > round.z_critical;
    if (rounds) rounds->push_back(round);
    if (!round.accepted) break;
    selected.push_back(ids[best]);
    out.z.push_back(round.z[best]);
    current = evals[best];
  }
  return out;
}

// Nested cross-validation of "geometry" against "geometry + what selection picks": outer k-fold
// over the fit poses (the first assignment); in each outer fold the whole greedy selection runs
// again on the outer training poses alone (their own inner k-fold), and both models are fitted
// there and judged on the outer held-out poses. So the gain is not flattered by having chosen
// the effects on the poses it is measured on. `without[j]`: the same with effect
// `judge[j]` (indices into L.ext.effects()) left out of every outer fold's choice, so that each
// effect of the full selection is judged by what it adds where outer folds chose it (an effect no
// outer fold chose adds nothing).
struct Nested {
  Linearized::Eval before, after;
  std::vector<Linearized::Eval> without;
  std::vector<std::vector<int>> chosen;  // per outer fold
};
Nested NestedCrossValidate(const Linearized& L, const std::vector<int>& pool,
                           const AnalysisSettings& s, const std::vector<int>& judge) {
  const size_t n = L.fit.size();
  Nested out;
  out.before = {std::vector<double>(n), std::vector<double>(n)};
  out.after = out.before;
  out.without.assign(judge.size(), out.before);
  const std::vector<int>& outer = L.fold_sets.front();
  const auto store = [&](Linearized::Eval& e, const std::vector<int>& train,
                         const std::vector<int>& held, const std::vector<int>& effects) {
    const std::vector<int> cols = L.Columns(effects);
    const Eigen::VectorXd d = L.Solve(train, cols);
    for (int k : held) {
      const auto [sc, p] = L.Score(L.fit[k], cols, d);
      e.score[k] = sc;
      e.position[k] = std::sqrt(p);
    }
  };
  for (int f = 0; f < L.folds; ++f) {
    std::vector<int> train, held;  // indices into L.fit
    for (size_t k = 0; k < n; ++k) (outer[k] == f ? held : train).push_back(k);
    if (held.empty()) continue;
    Linearized inner = L;
    inner.fit.clear();
    for (int k : train) inner.fit.push_back(L.fit[k]);
    inner.AssignFolds(s.folds, s.repeats, s.seed + 7919u * (f + 1));
    const std::vector<int> chosen = SelectGreedy(inner, pool, s, nullptr).selected;
    out.chosen.push_back(chosen);
    store(out.before, inner.fit, held, {});
    store(out.after, inner.fit, held, chosen);
    for (size_t j = 0; j < judge.size(); ++j) {
      std::vector<int> less;
      for (int k : chosen)
        if (k != judge[j]) less.push_back(k);
      store(out.without[j], inner.fit, held, less);
    }
  }
  return out;
}

// ln of the two-sided p of a correlation r over n poses (Fisher z). Kept as a log and not
// clamped: |r| → 1 gives p far below what a double holds (significance.hpp).
double LogFisherP(double r, int n) {
  if (n < 4) return 0.0;
  const double z = std::atanh(std::abs(r)) * std::sqrt(n - 3.0);
  return std::min(0.0, std::log(2.0) + LogNormalUpper(z));
}

double Correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double ma = Mean(a), mb = Mean(b);
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

}  // namespace

std::string Describe(const kinematics::KinematicModel& model, const Effect& f) {
  std::string s = kinematics::ToString(f.cause);
  if (f.cause == EffectCause::kThermal)
    return s + (f.thermal_source == Effect::ThermalSource::kTime ? " (time)" : " (temperature)");
  s += " " + model.joints()[f.joint].name;
  if (f.cause == EffectCause::kJointPeriodic) s += " h" + std::to_string(f.harmonic);
  return s;
}

double HeldOutRms(const kinematics::KinematicModel& model, const PoseData& data,
                  const std::vector<Effect>& effects, const AnalysisSettings& settings) {
  return Rms(HeldOutPositionErrors(model, data, effects, settings));
}

std::vector<double> HeldOutPositionErrors(const kinematics::KinematicModel& model,
                                          const PoseData& data, const std::vector<Effect>& effects,
                                          const AnalysisSettings& settings) {
  std::vector<Effect> fx = effects;
  for (Effect& f : fx)  // thermal references at the data's mean, as Analyze chooses them
    if (f.cause == EffectCause::kThermal) {
      std::vector<double> v;
      for (const auto& c : data.contexts) v.push_back(kinematics::ThermalRegressor(f, c));
      f.reference = Mean(v);
    }
  const Prepared p = Prepare(model, data, settings, &fx);
  std::vector<int> all(fx.size());
  std::iota(all.begin(), all.end(), 0);
  return (p.lin.test.empty() ? p.lin.CrossValidate(all) : p.lin.Split(all)).position;
}

Analysis Analyze(const kinematics::KinematicModel& model, const PoseData& data,
                 const AnalysisSettings& s) {
  Prepared p = Prepare(model, data, s, nullptr);
  const Linearized& L = p.lin;
  Analysis a;
  a.base_fit = p.base_fit;
  a.skipped = p.skipped;
  a.num_fit_poses = L.fit.size();
  a.num_test_poses = L.test.size();
  const auto& effects = L.ext.effects();

  // --- Noise tests: the base fit's residuals against the stated noise and repeated poses.
  {
    double ssp = 0, sso = 0;
    int np = 0, no = 0;
    for (int i : L.fit) {
      const Eigen::VectorXd r = kinematics::Residual(model, p.ms[i], p.x_pose[i]);
      ssp += r.head<3>().squaredNorm();
      np += 3;
      if (r.size() == 6) {
        sso += r.tail<3>().squaredNorm();
        no += 3;
      }
    }
    const double dof =
        np + no - static_cast<double>(p.base_fit.identified.size() + p.num_step_params);
    const auto test = [&](const std::string& against, double sp, double so) {
      NoiseTest t;
      t.against = against;
      t.position_sigma_m = sp;
      t.orientation_sigma_rad = so;
      t.chi2 = ssp / (sp * sp) + (no > 0 && so > 0 ? sso / (so * so) : 0.0);
      t.dof = no > 0 && so > 0 ? dof : dof - no;
      t.log_p = identification::ChiSquareLogUpper(t.chi2, t.dof);
      t.p_value = std::exp(t.log_p);
      a.noise_tests.push_back(t);
    };
    if (s.stated_position_sigma_m > 0)
      test("stated noise", s.stated_position_sigma_m, s.stated_orientation_sigma_rad);
    // Repeated poses: the same joints measured again (pooled within-group variance), within one
    // geometry (the poses either side of a step are not repeats of each other).
    std::vector<std::vector<int>> groups;
    for (int i : L.fit) {
      bool placed = false;
      for (auto& g : groups)
        if ((data.measurements[g[0]].q - data.measurements[i].q).lpNorm<Eigen::Infinity>() < 1e-6 &&
            p.x_pose[g[0]] == p.x_pose[i]) {
          g.push_back(i);
          placed = true;
          break;
        }
      if (!placed) groups.push_back({i});
    }
    double ssr = 0;
    int dofr = 0;
    for (const auto& g : groups) {
      if (g.size() < 2) continue;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int i : g) mean += data.measurements[i].p_WM_W;
      mean /= g.size();
      for (int i : g) ssr += (data.measurements[i].p_WM_W - mean).squaredNorm();
      dofr += 3 * (g.size() - 1);
    }
    if (dofr >= 3) test("repeated poses", std::sqrt(ssr / dofr), 0.0);
  }

  // --- Which candidates the geometry cannot absorb.
  std::vector<bool> ok = Identifiable(L, s.min_relative_novelty, a.skipped, model);
  std::vector<int> pool;
  for (size_t k = 0; k < effects.size(); ++k)
    if (ok[k]) {
      pool.push_back(k);
      a.candidates.push_back(effects[k]);
    }

  // --- Greedy forward selection on k-fold held-out residuals.
  const Selection sel = SelectGreedy(L, pool, s, &a.rounds);
  const std::vector<int>& selected = sel.selected;

  // --- Judged on poses the selection did not fit: the split, else nested cross-validation.
  // With nothing selected both models are the geometry, gain 0.
  const std::string kfold_scheme =
      (L.folds == L.groups
           ? std::string("leave-one-out")
           : std::to_string(L.folds) + "-fold ×" + std::to_string(L.fold_sets.size())) +
      (L.groups < static_cast<int>(L.fit.size()) ? " (by configuration)" : "");
  Linearized::Eval before, after;
  std::vector<Linearized::Eval> without(selected.size());  // selected model less effect j
  std::vector<int> outer_count(selected.size(), -1);       // outer folds choosing effect j
  if (!L.test.empty()) {
    before = L.Split({});
    after = L.Split(selected);
    for (size_t j = 0; j < selected.size(); ++j) {
      std::vector<int> less = selected;
      less.erase(less.begin() + j);
      without[j] = L.Split(less);
    }
    a.gain.scheme = "cal/test split";
  } else if (selected.empty()) {
    before = after = sel.eval;
    a.gain.scheme = kfold_scheme;
  } else {
    Nested nested = NestedCrossValidate(L, pool, s, selected);
    before = std::move(nested.before);
    after = std::move(nested.after);
    without = std::move(nested.without);
    for (size_t j = 0; j < selected.size(); ++j) {
      outer_count[j] = 0;
      for (const auto& c : nested.chosen)
        outer_count[j] += std::find(c.begin(), c.end(), selected[j]) != c.end();
    }
    for (const auto& c : nested.chosen) {
      a.gain.outer_selections.emplace_back();
      for (int k : c) a.gain.outer_selections.back().push_back(effects[k]);
    }
    a.gain.nested = true;
    a.gain.scheme =
        (L.folds == L.groups ? std::string("nested leave-one-out (selection redone per fold)")
                             : "nested " + std::to_string(L.folds) +
                                   "-fold (selection redone in each outer fold)") +
        (L.groups < static_cast<int>(L.fit.size()) ? ", by configuration" : "");
  }

  // --- Keep what gains there. The selected model must beat geometry on the held-out poses, and
  // each of its effects must beat its absence (for the nested scheme: in the outer folds'
  // own selections). Ties lose: an effect is reported only when it gains on data it did not fit.
  const double rms_before = Rms(before.position), rms_after = Rms(after.position);
  const bool model_gains = rms_after < rms_before;
  std::vector<int> kept;
  std::vector<double> kept_z, kept_without;
  std::vector<int> kept_outer;
  for (size_t j = 0; j < selected.size(); ++j) {
    const double rms_without = Rms(without[j].position);
    const bool earns = rms_after < rms_without;
    if (model_gains && earns) {
      kept.push_back(selected[j]);
      kept_z.push_back(sel.z[j]);
      kept_without.push_back(rms_without);
      kept_outer.push_back(outer_count[j]);
      continue;
    }
    char buf[256];
    if (!model_gains)
      std::snprintf(buf, sizeof buf,
                    "the selected model loses on held-out poses (%s): position RMS %.4f mm with "
                    "geometry alone, %.4f mm with the selected effects",
                    a.gain.scheme.c_str(), rms_before * 1e3, rms_after * 1e3);
    else if (outer_count[j] == 0)
      std::snprintf(buf, sizeof buf,
                    "no outer fold's selection chose it (%s): it gains nothing on held-out poses",
                    a.gain.scheme.c_str());
    else
      std::snprintf(buf, sizeof buf,
                    "does not earn its place on held-out poses (%s): position RMS %.4f mm with "
                    "it, %.4f mm without",
                    a.gain.scheme.c_str(), rms_after * 1e3, rms_without * 1e3);
    RejectedEffect r;
    r.effect = effects[selected[j]];
    r.reason = buf;
    r.z = sel.z[j];
    r.heldout_rms_with_m = rms_after;
    r.heldout_rms_without_m = rms_without;
    r.outer_folds_selecting = outer_count[j];
    a.rejected.push_back(r);
    spdlog::info("discrepancy: {} selected (z {:.2f}) but rejected: {}", Describe(model, r.effect),
                 r.z, r.reason);
  }
  // The gain is that of the selection as made (never recomputed after the rejections above,
  // which looked at these held-out poses). Nothing kept: the model is the geometry, gain 0.
  if (kept.empty() && !selected.empty()) {
    a.gain.nested = false;
    a.gain.outer_selections.clear();
    if (L.test.empty()) {
      before = after = L.CrossValidate({});
      a.gain.scheme = kfold_scheme;
    } else {
      after = before;
    }
  }
  a.gain.heldout_rms_before_m = Rms(before.position);
  a.gain.heldout_rms_after_m = Rms(after.position);
  a.gain.relative_gain = a.gain.heldout_rms_before_m > 0
                             ? 1.0 - a.gain.heldout_rms_after_m / a.gain.heldout_rms_before_m
                             : 0.0;
  a.gain.z = kept.empty() ? 0.0 : PairedZ(before.score, after.score);
  a.gain.position_before_m = before.position;
  a.gain.position_after_m = after.position;
  if (a.gain.nested) {
    // What a fixed list of the kept effects gains on the outer folds (calibrate --effects).
    Linearized one = L;
    one.fold_sets.resize(1);
    a.gain.heldout_rms_after_not_nested_m = Rms(one.CrossValidate(kept).position);
  }

  // --- Final nonlinear fit of the kept effects on the fit poses.
  std::vector<Effect> chosen;
  for (int k : kept) chosen.push_back(effects[k]);
  const kinematics::ExtendedModel final_model(model, chosen, s.gravity);
  std::vector<kinematics::PoseMeasurement> fit_ms;
  std::vector<kinematics::EffectContext> fit_ctx;
  for (int i : L.fit) {
    fit_ms.push_back(p.ms[i]);
    fit_ctx.push_back(data.contexts[i]);
  }
  Eigen::VectorXd e0 = final_model.NoEffects();
  {
    const std::vector<int> cols = L.Columns(kept);
    const Eigen::VectorXd delta = L.Solve(L.fit, cols);
    e0 = delta.tail(e0.size());
  }
  const identification::ExtendedFit ff = identification::FitExtended(
      final_model, L.identified, fit_ms, fit_ctx, p.base_fit.x, e0, s.estimate_noise, p.fit_steps);
  a.x = ff.x;
  a.e = ff.e;
  a.step_amplitudes = ff.step_amplitudes;
  a.step_sigma = ff.step_sigma;
  a.position_sigma_after_m = ff.position_sigma_m;
  const auto params = final_model.EffectParameters();
  for (size_t k = 0; k < chosen.size(); ++k) {
    FoundEffect fe;
    fe.effect = chosen[k];
    fe.cause = kinematics::ToString(chosen[k].cause);
    if (chosen[k].joint >= 0) fe.joints.push_back(JointName(model, chosen[k].joint));
    const int o = final_model.effect_offset(k), np = chosen[k].num_params();
    fe.parameters.assign(params.begin() + o, params.begin() + o + np);
    fe.values = ff.e.segment(o, np);
    fe.sigma = ff.sigma_e.segment(o, np);
    fe.z = kept_z[k];
    fe.heldout_rms_without_m = kept_without[k];
    fe.outer_folds_selecting = kept_outer[k];
    a.effects.push_back(fe);
  }

  // --- Correlations: each candidate's regressor against the residual along its direction.
  for (size_t k = 0; k < effects.size(); ++k) {
    const Effect& f = effects[k];
    for (int c = 0; c < f.num_params(); ++c) {
      RegressorCorrelation rc;
      rc.effect = f;
      rc.column = c;
      const int j = f.joint;
      switch (f.cause) {
        case EffectCause::kJointCompliance:
          rc.regressor = "gravity torque " + JointName(model, j);
          rc.unit = model.joints()[j].type == kinematics::JointType::kRevolute ? "N*m" : "N";
          break;
        case EffectCause::kJointPeriodic:
          rc.regressor = std::string(c == 0 ? "sin(" : "cos(") + (f.harmonic == 2 ? "2 " : "") +
                         "q " + JointName(model, j) + ")";
          rc.unit = "1";
          break;
        case EffectCause::kJointScale:
          rc.regressor = "q " + JointName(model, j);
          rc.unit = "rad";
          break;
        case EffectCause::kBacklash:
          rc.regressor = "approach direction " + JointName(model, j);
          rc.unit = "1";
          break;
        case EffectCause::kThermal:
          rc.regressor = f.thermal_source == Effect::ThermalSource::kTime ? "time" : "temperature";
          rc.unit = f.thermal_source == Effect::ThermalSource::kTime ? "s" : "degC";
          break;
      }
      const int col = L.num_geo + L.ext.effect_offset(k) + c;
      for (int i : L.fit) {
        // Regressor = the effect column per unit parameter along its own direction; direction
        // of the joint's motion (joint effects) or of the arm's growth (thermal).
        const auto& m = data.measurements[i];
        const auto& ctx = data.contexts[i];
        Eigen::Vector3d dir;
        double g = 0;
        if (f.cause == EffectCause::kThermal) {
          kinematics::EffectContext unit_ctx = ctx;
          if (f.thermal_source == Effect::ThermalSource::kTime)
            unit_ctx.time_s = f.reference + 1.0;
          else
            unit_ctx.temperature_c = f.reference + 1.0;
          const kinematics::ExtendedModel one(model, {f}, s.gravity);
          Eigen::MatrixXd Je;
          one.ForMarker(m.marker).Jacobians(m.q, unit_ctx, p.x_pose[i], one.NoEffects(), nullptr,
                                            &Je);
          dir = Je.col(0).head<3>();
          g = kinematics::ThermalRegressor(f, ctx);
        } else {
          dir = model.ForMarker(m.marker).JointJacobian(m.q, p.x_pose[i]).col(j).head<3>();
          const Eigen::Vector3d jc = L.Jp[i].col(col);
          g = dir.squaredNorm() > 0 ? jc.dot(dir) / dir.squaredNorm() : 0.0;
        }
        const double nd = dir.norm();
        const Eigen::Vector3d u = nd > 0 ? Eigen::Vector3d(dir / nd) : Eigen::Vector3d::Zero();
        rc.values.push_back(g);
        rc.residual_before_m.push_back(u.dot(L.rp[i]));
        const Eigen::VectorXd x_after =
            identification::GeometryAt(a.x, data.steps, a.step_amplitudes, static_cast<int>(i));
        rc.residual_after_m.push_back(u.dot(
            m.p_WM_W - final_model.ForMarker(m.marker).Forward(m.q, ctx, x_after, a.e).p_WM_W));
      }
      rc.correlation = Correlation(rc.values, rc.residual_before_m);
      rc.log_p = LogFisherP(rc.correlation, rc.values.size());
      rc.p_value = std::exp(rc.log_p);
      a.correlations.push_back(std::move(rc));
    }
  }
  std::stable_sort(a.correlations.begin(), a.correlations.end(),
                   [](const auto& x, const auto& y) { return x.log_p < y.log_p; });
  return a;
}

}  // namespace rcal::discrepancy
