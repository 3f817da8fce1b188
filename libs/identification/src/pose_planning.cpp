#include "rcal/identification/pose_planning.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace rcal::identification {
namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();

// The errors x with world ← base set to identity: the base ETs' value is nominal + x, so x =
// −nominal there (a model without base parameters keeps its world frame).
Eigen::VectorXd BaseFrameAtIdentity(const kinematics::KinematicModel& model,
                                    const Eigen::VectorXd& x) {
  Eigen::VectorXd xb = x;
  const auto& P = model.parameters();
  for (int i = 0; i < model.num_params(); ++i)
    if (P[i].group == "base") xb(i) = -P[i].nominal;
  return xb;
}

// Rows of one stop's measurement, weighted by the noise: 3 (position) or 6 (full pose).
int RowsPerStop(kinematics::MeasurementKind kind) {
  return kind == kinematics::MeasurementKind::kFullPose ? 6 : 3;
}

// The weighted Jacobian of one stop on the columns `cols`, rows × cols.size().
Eigen::MatrixXd WeightedJacobian(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                 const Eigen::VectorXd& q, const std::vector<int>& cols,
                                 const PlanningSettings& s, Eigen::MatrixXd& J6) {
  model.IdentificationJacobian(q, x, J6);
  const int rows = RowsPerStop(s.kind);
  Eigen::MatrixXd W(rows, cols.size());
  for (size_t c = 0; c < cols.size(); ++c) {
    W.col(c).head<3>() = J6.col(cols[c]).head<3>() / s.position_sigma_m;
    if (rows == 6) W.col(c).tail<3>() = J6.col(cols[c]).tail<3>() / s.orientation_sigma_rad;
  }
  return W;
}

// Mean of J_pᵀ J_p over the task configurations on the columns `cols` [m² per unit²].
Eigen::MatrixXd TaskWeight(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                           const std::vector<Eigen::VectorXd>& task, const std::vector<int>& cols) {
  const int n = static_cast<int>(cols.size());
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(n, n);
  if (task.empty()) return G;
  Eigen::MatrixXd J6(6, model.num_params()), Jp(3, n);
  for (const auto& q : task) {
    model.IdentificationJacobian(q, x, J6);
    for (int c = 0; c < n; ++c) Jp.col(c) = J6.col(cols[c]).head<3>();
    G.noalias() += Jp.transpose() * Jp;
  }
  return G / static_cast<double>(task.size());
}

void CheckJoints(const kinematics::KinematicModel& model, const std::vector<Eigen::VectorXd>& qs,
                 const char* what) {
  for (size_t i = 0; i < qs.size(); ++i) {
    if (qs[i].size() != model.num_joints())
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) +
                                  "]: " + std::to_string(qs[i].size()) + " joints, the model has " +
                                  std::to_string(model.num_joints()));
    if (!qs[i].allFinite())
      throw std::invalid_argument(std::string(what) + "[" + std::to_string(i) + "]: not finite");
  }
}

}  // namespace

Eigen::Vector3d MarkerInBase(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const Eigen::VectorXd& q) {
  return model.Forward(q, BaseFrameAtIdentity(model, x)).p_WM_W;
}

bool SatisfiesConstraints(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                          const Eigen::VectorXd& q, const PoseConstraints& c) {
  if (q.size() != model.num_joints() || !q.allFinite() || !model.WithinLimits(q)) return false;
  if (c.home.size() == q.size() && ((q - c.home).array().abs() > c.home_tolerance.array()).any())
    return false;
  if (!c.tool_box && c.min_base_distance <= 0) return true;
  const Eigen::Vector3d p = MarkerInBase(model, x, q);
  if (c.tool_box && !c.tool_box->Contains(p)) return false;
  return p.norm() >= c.min_base_distance;
}

std::vector<Eigen::VectorXd> SampleCandidates(const kinematics::KinematicModel& model,
                                              const Eigen::VectorXd& x, const PoseConstraints& c,
                                              int count, std::mt19937_64& rng, double margin,
                                              int max_draws) {
  const int nj = model.num_joints();
  const bool home = c.home.size() > 0;
  if (home && (c.home.size() != nj || c.home_tolerance.size() != nj))
    throw std::invalid_argument("constraints.home: " + std::to_string(c.home.size()) +
                                " joints and " + std::to_string(c.home_tolerance.size()) +
                                " tolerances, the model has " + std::to_string(nj));
  // Draw inside the limits shrunk by the margin, intersected with the home's band.
  Eigen::VectorXd lo(nj), hi(nj);
  for (int j = 0; j < nj; ++j) {
    const auto& J = model.joints()[j];
    lo(j) = J.lower + margin * (J.upper - J.lower);
    hi(j) = J.upper - margin * (J.upper - J.lower);
    if (home) {
      lo(j) = std::max(lo(j), c.home(j) - c.home_tolerance(j));
      hi(j) = std::min(hi(j), c.home(j) + c.home_tolerance(j));
      if (lo(j) > hi(j))
        throw std::invalid_argument("constraints.home: joint " + model.joints()[j].name +
                                    ": home ± tolerance lies outside the joint limits");
    }
  }
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::VectorXd> out;
  const Eigen::VectorXd xb = BaseFrameAtIdentity(model, x);
  int refused_box = 0, refused_distance = 0;
  for (int draw = 0; draw < max_draws && static_cast<int>(out.size()) < count; ++draw) {
    Eigen::VectorXd q(nj);
    for (int j = 0; j < nj; ++j) q(j) = lo(j) + (hi(j) - lo(j)) * u(rng);
    if (c.tool_box || c.min_base_distance > 0) {
      const Eigen::Vector3d p = model.Forward(q, xb).p_WM_W;
      if (c.tool_box && !c.tool_box->Contains(p)) {
        ++refused_box;
        continue;
      }
      if (p.norm() < c.min_base_distance) {
        ++refused_distance;
        continue;
      }
    }
    out.push_back(std::move(q));
  }
  if (static_cast<int>(out.size()) < count)
    throw std::runtime_error("only " + std::to_string(out.size()) + " of " + std::to_string(count) +
                             " candidate configurations satisfy the constraints after " +
                             std::to_string(max_draws) + " draws; most were refused by " +
                             (refused_box >= refused_distance ? "constraints.tool_box"
                                                              : "constraints.min_base_distance"));
  return out;
}

std::vector<Eigen::VectorXd> InTaskRegion(const kinematics::KinematicModel& model,
                                          const Eigen::VectorXd& x,
                                          const std::vector<Eigen::VectorXd>& candidates,
                                          const PoseConstraints& c) {
  std::vector<Eigen::VectorXd> out;
  if (!c.task_region) return out;
  const Eigen::VectorXd xb = BaseFrameAtIdentity(model, x);
  for (const auto& q : candidates)
    if (c.task_region->Contains(model.Forward(q, xb).p_WM_W)) out.push_back(q);
  return out;
}

PlanningProblem::PlanningProblem(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                 std::vector<Eigen::VectorXd> candidates,
                                 const PlanningSettings& settings,
                                 const std::vector<Eigen::VectorXd>& task)
    : settings_(settings), candidates_(std::move(candidates)) {
  if (candidates_.empty()) throw std::invalid_argument("pose planning: no candidates");
  if (x.size() != model.num_params())
    throw std::invalid_argument("pose planning: x has " + std::to_string(x.size()) +
                                " entries, the model " + std::to_string(model.num_params()));
  CheckJoints(model, candidates_, "candidates");
  CheckJoints(model, task, "task");
  if (settings.criterion == PlanCriterion::kTaskRegion && task.empty())
    throw std::invalid_argument("pose planning: the task-region criterion needs task poses");
  if (!(settings.position_sigma_m > 0) || !(settings.orientation_sigma_rad > 0))
    throw std::invalid_argument("pose planning: noise σ must be positive");
  rows_ = RowsPerStop(settings.kind);

  // The base set at an even spread of the candidates (generic configurations).
  const int n_base = std::min<int>(size(), std::max(1, settings.base_set_candidates));
  std::vector<Eigen::VectorXd> spread;
  for (int i = 0; i < n_base; ++i)
    spread.push_back(candidates_[static_cast<size_t>(i) * size() / n_base]);
  base_ = kinematics::AnalyzeIdentifiability(model, spread, x, settings.kind).identifiable;
  const int p = static_cast<int>(base_.size());
  if (p == 0) throw std::invalid_argument("pose planning: no identifiable parameter");

  Eigen::MatrixXd J6(6, model.num_params());
  Eigen::MatrixXd Wt(p, static_cast<Eigen::Index>(rows_) * size());
  for (int i = 0; i < size(); ++i)
    Wt.middleCols(static_cast<Eigen::Index>(rows_) * i, rows_) =
        WeightedJacobian(model, x, candidates_[i], base_, settings, J6).transpose();
  // Unit RMS columns: lengths and angles compare, and M stays well conditioned.
  scale_.resize(p);
  for (int c = 0; c < p; ++c) {
    const double rms = Wt.row(c).norm() / std::sqrt(static_cast<double>(size()));
    scale_(c) = rms > 0 ? 1.0 / rms : 1.0;
  }
  W_ = scale_.asDiagonal() * Wt;  // stored transposed: p × (rows·N), one column per row
  prior_ = Eigen::MatrixXd::Zero(p, p);
  for (int c = 0; c < p; ++c) {
    const auto& par = model.parameters()[base_[c]];
    const bool setup = kinematics::IsSetupGroup(par.group);
    const double sigma = par.is_angle
                             ? (setup ? settings.setup_sigma_angle : settings.prior_sigma_angle)
                             : (setup ? settings.setup_sigma_length : settings.prior_sigma_length);
    prior_(c, c) = scale_(c) * scale_(c) / (sigma * sigma);
  }
  if (!task.empty())
    G_ = scale_.asDiagonal() * TaskWeight(model, x, task, base_) * scale_.asDiagonal();
}

Eigen::MatrixXd PlanningProblem::Information(const std::vector<int>& chosen,
                                             bool with_prior) const {
  const int p = static_cast<int>(base_.size());
  Eigen::MatrixXd M = with_prior ? prior_ : Eigen::MatrixXd::Zero(p, p);
  for (int i : chosen) {
    const auto Wi = W_.middleCols(static_cast<Eigen::Index>(rows_) * i, rows_);
    M.noalias() += Wi * Wi.transpose();
  }
  return M;
}

double PlanningProblem::TaskMeanSquared(const Eigen::MatrixXd& M) const {
  if (G_.size() == 0) return 0.0;
  return (G_ * M.ldlt().solve(Eigen::MatrixXd::Identity(M.rows(), M.cols()))).trace();
}

DesignBound PlanningProblem::TaskMeanSquaredBound(int count, int max_iterations,
                                                  double tolerance) const {
  if (G_.size() == 0)
    throw std::invalid_argument(
        "design bound: no task configurations (the criterion is over them)");
  if (count < 1) throw std::invalid_argument("design bound: count must be at least 1");
  const int p = static_cast<int>(base_.size());
  const int r = rows_;
  const double n = count;
  // f(M) = tr(G M⁻¹) (TaskMeanSquared); the data part D(w) = count Σ wᵢ Aᵢ, M = Λ₀ + D.
  const auto data_part = [&](const Eigen::VectorXd& weights) {
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(p, p);
    for (int i = 0; i < size(); ++i) {
      if (weights(i) == 0) continue;
      const auto Wi = W_.middleCols(static_cast<Eigen::Index>(r) * i, r);
      out.noalias() += (n * weights(i)) * (Wi * Wi.transpose());
    }
    return out;
  };
  Eigen::VectorXd w = Eigen::VectorXd::Constant(size(), 1.0 / size());  // the random design
  Eigen::MatrixXd D = data_part(w);
  DesignBound b;
  b.lower_m2 = 0;
  b.relaxed_m2 = TaskMeanSquared(prior_ + D);
  Eigen::VectorXd g(size());
  for (int it = 0; it < max_iterations; ++it) {
    b.iterations = it + 1;
    const Eigen::MatrixXd M = prior_ + D;
    // ∂f/∂wᵢ = −count tr(Wᵢᵀ M⁻¹ G M⁻¹ Wᵢ).
    const Eigen::LLT<Eigen::MatrixXd> llt(M);
    const Eigen::MatrixXd Z = llt.solve(W_);
    const Eigen::MatrixXd Y = G_ * Z;
    for (int i = 0; i < size(); ++i) {
      const Eigen::Index c0 = static_cast<Eigen::Index>(r) * i;
      g(i) = -n * (Z.middleCols(c0, r).array() * Y.middleCols(c0, r).array()).sum();
    }
    Eigen::Index j = 0;
    const double g_min = g.minCoeff(&j);
    const double value = TaskMeanSquared(M);
    b.relaxed_m2 = std::min(b.relaxed_m2, value);
    b.lower_m2 = std::max(b.lower_m2, value + g_min - g.dot(w));
    if (b.relaxed_m2 - b.lower_m2 <= tolerance * b.relaxed_m2) break;
    // First the multiplicative step of L-optimal design (wᵢ ∝ wᵢ √(−∂ᵢf), Silvey, Titterington &
    // Torsney 1978: every weight moves at once, which Frank–Wolfe's one-vertex steps do slowly);
    // kept when it lowers f (with the prior it need not), else the Frank–Wolfe step below.
    {
      Eigen::VectorXd w_m = w.array() * (-g.array()).max(0.0).sqrt();
      const double sum = w_m.sum();
      if (sum > 0) {
        w_m /= sum;
        const Eigen::MatrixXd D_m = data_part(w_m);
        if (TaskMeanSquared(prior_ + D_m) < value) {
          w = w_m;
          D = D_m;
          continue;
        }
      }
    }
    // Toward vertex j: D(γ) = (1 − γ) D + γ count Aⱼ; f is convex in γ: golden section.
    const auto Wj = W_.middleCols(static_cast<Eigen::Index>(r) * j, r);
    const Eigen::MatrixXd Aj = n * (Wj * Wj.transpose());
    const auto along = [&](double gamma) {
      return TaskMeanSquared(prior_ + (1.0 - gamma) * D + gamma * Aj);
    };
    double lo = 0, hi = 1;
    const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
    double a = hi - phi * (hi - lo), c = lo + phi * (hi - lo), fa = along(a), fc = along(c);
    for (int k = 0; k < 40; ++k) {
      if (fa < fc) {
        hi = c, c = a, fc = fa, a = hi - phi * (hi - lo), fa = along(a);
      } else {
        lo = a, a = c, fa = fc, c = lo + phi * (hi - lo), fc = along(c);
      }
    }
    const double gamma = 0.5 * (lo + hi);
    w *= 1.0 - gamma;
    w(j) += gamma;
    D = (1.0 - gamma) * D + gamma * Aj;
  }
  b.relaxed_m2 = std::min(b.relaxed_m2, TaskMeanSquared(prior_ + D));
  return b;
}

Eigen::VectorXd PlanningProblem::Gains(const Eigen::MatrixXd& M, PlanCriterion criterion) const {
  // Z = M⁻¹ Wᵀ (columns per row of a stop); stop i adds Wᵢᵀ Wᵢ, so with Bᵢ = I + Wᵢ M⁻¹ Wᵢᵀ:
  //   Δ log det M = log det Bᵢ,   Δ tr(G M⁻¹) = −tr(Bᵢ⁻¹ Wᵢ M⁻¹ G M⁻¹ Wᵢᵀ).
  const Eigen::LLT<Eigen::MatrixXd> llt(M);
  if (llt.info() != Eigen::Success)
    throw std::runtime_error("pose planning: information matrix not positive definite");
  const Eigen::MatrixXd Z = llt.solve(W_);
  Eigen::MatrixXd Y;
  const bool task = criterion == PlanCriterion::kTaskRegion;
  if (task) Y.noalias() = G_ * Z;
  Eigen::VectorXd gains(size());
  const int r = rows_;
  Eigen::MatrixXd B(r, r), C(r, r);
  for (int i = 0; i < size(); ++i) {
    const Eigen::Index c0 = static_cast<Eigen::Index>(r) * i;
    const auto Wi = W_.middleCols(c0, r);
    const auto Zi = Z.middleCols(c0, r);
    B.noalias() = Wi.transpose() * Zi;
    B.diagonal().array() += 1.0;
    const Eigen::LLT<Eigen::MatrixXd> b(B);
    if (!task) {
      gains(i) = 2.0 * b.matrixLLT().diagonal().array().log().sum();
    } else {
      C.noalias() = Zi.transpose() * Y.middleCols(c0, r);
      gains(i) = b.solve(C).trace();
    }
  }
  return gains;
}

PosePlan PlanningProblem::Run(int count, bool exchange, PlanCriterion criterion,
                              const Eigen::MatrixXd& prior, bool with_prior) const {
  if (count < 1) throw std::invalid_argument("pose planning: count must be at least 1");
  if (count > size())
    throw std::invalid_argument("pose planning: " + std::to_string(count) + " stops from only " +
                                std::to_string(size()) + " candidates");
  PosePlan plan;
  plan.identifiable = base_;
  std::vector<char> taken(size(), 0);
  Eigen::MatrixXd M = prior;
  const auto add = [&](Eigen::MatrixXd& m, int i, double sign) {
    const auto Wi = W_.middleCols(static_cast<Eigen::Index>(rows_) * i, rows_);
    m.noalias() += sign * (Wi * Wi.transpose());
  };
  const auto best_free = [&](const Eigen::VectorXd& g) {
    int best = -1;
    double v = kNegInf;
    for (int i = 0; i < size(); ++i)
      if (!taken[i] && g(i) > v) v = g(i), best = i;
    return best;
  };
  for (int k = 0; k < count; ++k) {
    const int i = best_free(Gains(M, criterion));
    plan.chosen.push_back(i);
    taken[i] = 1;
    add(M, i, 1.0);
  }
  // Exchange: each chosen stop in turn against the best free candidate at the information
  // without it; every swap raises the criterion strictly, so the sweeps end.
  for (int sweep = 0; exchange && sweep < settings_.max_exchange_sweeps; ++sweep) {
    ++plan.sweeps;
    bool changed = false;
    for (int pos = 0; pos < count; ++pos) {
      const int j = plan.chosen[pos];
      Eigen::MatrixXd M_minus = M;
      add(M_minus, j, -1.0);
      const Eigen::VectorXd g = Gains(M_minus, criterion);
      const int k = best_free(g);
      if (k < 0 || !(g(k) > g(j) + 1e-9 * std::abs(g(j)) + 1e-300)) continue;
      taken[j] = 0;
      taken[k] = 1;
      plan.chosen[pos] = k;
      M = M_minus;
      add(M, k, 1.0);
      ++plan.exchanges;
      changed = true;
    }
    if (!changed) break;
  }
  const PosePlan e = Evaluate(plan.chosen, with_prior);
  plan.log_det = e.log_det;
  plan.task_mean_squared_m2 = e.task_mean_squared_m2;
  return plan;
}

PosePlan PlanningProblem::Plan(int count, bool exchange) const {
  return Run(count, exchange, settings_.criterion, prior_, true);
}

PosePlan PlanningProblem::IrocGreedy(int count) const {
  // A ridge far below one stop's information: it only breaks the ties of the rank-deficient
  // first steps (the greedy then raises the rank first, as a pseudo-determinant would).
  const double mean_diag = W_.squaredNorm() / static_cast<double>(size()) / W_.rows();
  const Eigen::MatrixXd ridge =
      Eigen::MatrixXd::Identity(W_.rows(), W_.rows()) * (1e-8 * mean_diag);
  return Run(count, false, PlanCriterion::kDOptimal, ridge, true);
}

PosePlan PlanningProblem::Evaluate(const std::vector<int>& chosen, bool with_prior) const {
  PosePlan plan;
  plan.chosen = chosen;
  plan.identifiable = base_;
  const Eigen::MatrixXd M = Information(chosen, with_prior);
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
  plan.log_det = ldlt.vectorD().array().abs().log().sum();
  plan.task_mean_squared_m2 = TaskMeanSquared(M);
  return plan;
}

double PredictedTaskMeanSquared(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                const std::vector<int>& identified, const Eigen::MatrixXd& P,
                                const std::vector<Eigen::VectorXd>& task) {
  const auto n = static_cast<Eigen::Index>(identified.size());
  if (P.rows() != n || P.cols() != n)
    throw std::invalid_argument("predicted task error: covariance is " + std::to_string(P.rows()) +
                                "×" + std::to_string(P.cols()) + ", " + std::to_string(n) +
                                " parameters identified");
  CheckJoints(model, task, "task");
  return (TaskWeight(model, x, task, identified) * P).trace();
}

std::vector<NextPose> NextBestPoses(const kinematics::KinematicModel& model,
                                    const Eigen::VectorXd& x, const std::vector<int>& identified,
                                    const Eigen::MatrixXd& P,
                                    const std::vector<Eigen::VectorXd>& candidates,
                                    const std::vector<Eigen::VectorXd>& task,
                                    const Eigen::VectorXd& q_now, int k,
                                    const PlanningSettings& settings, double settle_distance) {
  const int n = static_cast<int>(identified.size());
  if (P.rows() != n || P.cols() != n)
    throw std::invalid_argument("next poses: covariance is " + std::to_string(P.rows()) + "×" +
                                std::to_string(P.cols()) + ", " + std::to_string(n) +
                                " parameters identified");
  if (q_now.size() != model.num_joints() || !q_now.allFinite())
    throw std::invalid_argument("next poses: current joints: wrong size or not finite");
  CheckJoints(model, candidates, "candidates");
  CheckJoints(model, task, "task");
  // The error that matters: over the task region, else over the candidates themselves.
  const Eigen::MatrixXd G = TaskWeight(model, x, task.empty() ? candidates : task, identified);
  const Eigen::MatrixXd PGP = P * G * P;
  Eigen::MatrixXd J6(6, model.num_params());
  std::vector<NextPose> all;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (!model.WithinLimits(candidates[i])) continue;
    // Posterior P⁺ = P − P Hᵀ S⁻¹ H P, S = H P Hᵀ + R (H weighted: R = I), so
    // tr(G P) − tr(G P⁺) = tr(S⁻¹ H P G P Hᵀ).
    const Eigen::MatrixXd H = WeightedJacobian(model, x, candidates[i], identified, settings, J6);
    Eigen::MatrixXd S = H * P * H.transpose();
    S.diagonal().array() += 1.0;
    NextPose np;
    np.candidate = static_cast<int>(i);
    np.gain_m2 = Eigen::LLT<Eigen::MatrixXd>(S).solve(H * PGP * H.transpose()).trace();
    np.distance = (candidates[i] - q_now).norm();
    np.score = np.gain_m2 / (np.distance + settle_distance);
    all.push_back(np);
  }
  const size_t keep = std::min<size_t>(all.size(), static_cast<size_t>(std::max(0, k)));
  std::partial_sort(all.begin(), all.begin() + keep, all.end(),
                    [](const NextPose& a, const NextPose& b) { return a.score > b.score; });
  all.resize(keep);
  return all;
}

}  // namespace rcal::identification
