#include "rcal/identification/ekf_identifier.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/identification/change_detection.hpp"
#include "rcal/identification/chi_square.hpp"
#include "rcal/identification/extended_measurement.hpp"

namespace rcal::identification {

Eigen::VectorXd DefaultEffectPriorSigma(const kinematics::ExtendedModel& model) {
  Eigen::VectorXd s(model.num_effect_params());
  for (size_t k = 0; k < model.effects().size(); ++k) {
    const kinematics::Effect& f = model.effects()[k];
    double v = 1e-3;
    switch (f.cause) {
      case kinematics::EffectCause::kJointCompliance:
        v = 1e-5;
        break;
      case kinematics::EffectCause::kThermal:
        v = f.thermal_source == kinematics::Effect::ThermalSource::kTime ? 1e-7 : 1e-4;
        break;
      default:
        break;
    }
    s.segment(model.effect_offset(k), f.num_params()).setConstant(v);
  }
  return s;
}

const char* TrackingStatusName(TrackingStatus s) {
  switch (s) {
    case TrackingStatus::kConverging:
      return "converging";
    case TrackingStatus::kConverged:
      return "converged";
    case TrackingStatus::kChangeDetected:
      return "change_detected";
    case TrackingStatus::kReconverging:
      return "reconverging";
  }
  return "unknown";
}

namespace {

// The settings' effect σ (or the default), checked.
Eigen::VectorXd EffectSigma(const Eigen::VectorXd& given, const Eigen::VectorXd& fallback,
                            const char* name, bool allow_zero) {
  if (given.size() == 0) return fallback;
  if (given.size() != fallback.size())
    throw std::invalid_argument(std::string(name) + ": " + std::to_string(given.size()) +
                                " values, expected " + std::to_string(fallback.size()) +
                                " (one per effect parameter)");
  for (int i = 0; i < given.size(); ++i)
    if (!std::isfinite(given(i)) || given(i) < 0 || (!allow_zero && given(i) == 0))
      throw std::invalid_argument(
          std::string(name) + ": value " + std::to_string(i) +
          (allow_zero ? " is not finite and ≥ 0" : " is not finite and > 0"));
  return given;
}

}  // namespace

EkfIdentifier::EkfIdentifier(const kinematics::KinematicModel& model, std::vector<int> identified,
                             EkfSettings settings, Eigen::VectorXd x_fixed)
    : EkfIdentifier(kinematics::ExtendedModel(model, {}), std::move(identified),
                    std::move(settings), std::move(x_fixed)) {}

EkfIdentifier::EkfIdentifier(const kinematics::ExtendedModel& model, std::vector<int> identified,
                             EkfSettings settings, Eigen::VectorXd x_fixed)
    : ext_(model),
      identified_(std::move(identified)),
      settings_(std::move(settings)),
      x_fixed_(x_fixed.size() ? std::move(x_fixed) : model.base().Nominal()) {
  const kinematics::KinematicModel& base = ext_.base();
  if (x_fixed_.size() != base.num_params() || !x_fixed_.allFinite())
    throw std::invalid_argument("x_fixed: expected " + std::to_string(base.num_params()) +
                                " finite values");
  for (int i : identified_)
    if (i < 0 || i >= base.num_params())
      throw std::invalid_argument("identified: index " + std::to_string(i) + " out of range");
  const int ng = static_cast<int>(identified_.size()), ne = ext_.num_effect_params();
  prior_sigma_.resize(ng + ne);
  q_diag_.resize(ng + ne);
  for (int i = 0; i < ng; ++i) {
    const bool angle = base.parameters()[identified_[i]].is_angle;
    prior_sigma_(i) = angle ? settings_.prior_sigma_angle : settings_.prior_sigma_length;
    const double s = angle ? settings_.drift_sigma_angle : settings_.drift_sigma_length;
    q_diag_(i) = s * s;
  }
  prior_sigma_.tail(ne) = EffectSigma(settings_.prior_sigma_effects, DefaultEffectPriorSigma(ext_),
                                      "prior_sigma_effects", false);
  q_diag_.tail(ne) = EffectSigma(settings_.drift_sigma_effects, Eigen::VectorXd::Zero(ne),
                                 "drift_sigma_effects", true)
                         .array()
                         .square()
                         .matrix();
  Reset();
}

void EkfIdentifier::Reset() {
  x_ = Eigen::VectorXd::Zero(prior_sigma_.size());
  P_ = Eigen::MatrixXd(prior_sigma_.array().square().matrix().asDiagonal());
  accepted_ = rejected_ = relinearizations_ = 0;
  last_rejection_.clear();
  x0_ = x_;
  P0_ = P_;
  x_lin_ = x_;
  history_.clear();
  contexts_.clear();
  inflations_.clear();
  seqs_.clear();
  recent_.clear();
  second_look_seq_ = -1;
  seq_ = 0;
  status_ = TrackingStatus::kConverging;
  small_steps_ = 0;
  changes_.clear();
  candidate_count_ = 0;
}

void EkfIdentifier::SetState(const Eigen::VectorXd& state, const Eigen::MatrixXd& P) {
  const int n = static_cast<int>(x_.size());
  if (state.size() != n)
    throw std::invalid_argument("x: " + std::to_string(state.size()) + " values, expected " +
                                std::to_string(n));
  if (P.rows() != n || P.cols() != n)
    throw std::invalid_argument("P: wrong size, expected " + std::to_string(n) + "x" +
                                std::to_string(n));
  if (!state.allFinite()) throw std::invalid_argument("x: not finite");
  if (!P.allFinite()) throw std::invalid_argument("P: not finite");
  x_ = state;
  P_ = 0.5 * (P + P.transpose());
  x0_ = x_;
  P0_ = P_;
  x_lin_ = x_;
  history_.clear();
  contexts_.clear();
  inflations_.clear();
  seqs_.clear();
  recent_.clear();
  second_look_seq_ = -1;
  status_ = TrackingStatus::kConverging;
  small_steps_ = 0;
}

EkfCheckpoint EkfIdentifier::Checkpoint() const {
  EkfCheckpoint c;
  c.x0 = x0_;
  c.x = x_;
  c.x_lin = x_lin_;
  c.P0 = P0_;
  c.P = P_;
  c.history = history_;
  c.accepted = accepted_;
  c.rejected = rejected_;
  c.relinearizations = relinearizations_;
  c.x_fixed = x_fixed_;
  if (ext_.num_effect_params() > 0) c.contexts = contexts_;
  if (std::any_of(inflations_.begin(), inflations_.end(),
                  [](const Eigen::MatrixXd& v) { return v.size() > 0; }))
    c.inflations = inflations_;
  c.status = status_;
  c.small_steps = small_steps_;
  if (second_look_seq_ >= 0) {
    const auto at = std::find(seqs_.begin(), seqs_.end(), second_look_seq_);
    if (at != seqs_.end()) {
      c.second_look_onset = static_cast<int>(at - seqs_.begin());
      c.second_look_alternatives = second_look_alternatives_;
    }
  }
  return c;
}

void EkfIdentifier::Restore(const EkfCheckpoint& c) {
  const int n = static_cast<int>(x_.size());
  const auto check_vec = [n](const Eigen::VectorXd& v, const char* name) {
    if (v.size() != n || !v.allFinite())
      throw std::invalid_argument(std::string(name) + ": wrong size or not finite");
  };
  const auto check_mat = [n](const Eigen::MatrixXd& M, const char* name) {
    if (M.rows() != n || M.cols() != n || !M.allFinite())
      throw std::invalid_argument(std::string(name) + ": wrong size or not finite");
  };
  if (c.x_fixed.size() != 0 && (c.x_fixed.size() != model().num_params() || !c.x_fixed.allFinite()))
    throw std::invalid_argument("x_fixed: wrong size or not finite");
  check_vec(c.x0, "x0");
  check_vec(c.x, "x");
  check_vec(c.x_lin, "x_lin");
  check_mat(c.P0, "P0");
  check_mat(c.P, "P");
  for (size_t k = 0; k < c.history.size(); ++k) {
    const std::string why = kinematics::Validate(model(), c.history[k]);
    if (!why.empty()) throw std::invalid_argument("history[" + std::to_string(k) + "]." + why);
  }
  if (!c.contexts.empty() && c.contexts.size() != c.history.size())
    throw std::invalid_argument("contexts: " + std::to_string(c.contexts.size()) +
                                " entries, expected one per history entry (" +
                                std::to_string(c.history.size()) + ") or none");
  for (size_t k = 0; k < c.contexts.size(); ++k) {
    const std::string why = ValidateContext(ext_, c.contexts[k]);
    if (!why.empty()) throw std::invalid_argument("contexts[" + std::to_string(k) + "]." + why);
  }
  if (!c.inflations.empty() && c.inflations.size() != c.history.size())
    throw std::invalid_argument("inflations: " + std::to_string(c.inflations.size()) +
                                " entries, expected one per history entry (" +
                                std::to_string(c.history.size()) + ") or none");
  for (size_t k = 0; k < c.inflations.size(); ++k) {
    const Eigen::MatrixXd& v = c.inflations[k];
    if (v.size() != 0 &&
        (v.rows() != n || v.cols() != n || !v.allFinite() || (v.diagonal().array() < 0).any()))
      throw std::invalid_argument("inflations[" + std::to_string(k) +
                                  "]: wrong size, not finite or negative");
  }
  if (c.second_look_onset != -1 &&
      (c.second_look_onset < 0 || c.second_look_onset >= static_cast<int>(c.inflations.size()) ||
       c.inflations[c.second_look_onset].size() == 0))
    throw std::invalid_argument("second_look_onset: " + std::to_string(c.second_look_onset) +
                                " is not a history entry with a release (or −1)");
  if (c.x_fixed.size() != 0) x_fixed_ = c.x_fixed;
  x0_ = c.x0;
  x_ = c.x;
  x_lin_ = c.x_lin;
  P0_ = c.P0;
  P_ = c.P;
  history_ = c.history;
  contexts_ = c.contexts;
  contexts_.resize(history_.size());  // none given: default contexts
  inflations_ = c.inflations;
  inflations_.resize(history_.size());
  seqs_.resize(history_.size());
  for (size_t k = 0; k < seqs_.size(); ++k) seqs_[k] = static_cast<long>(k);
  seq_ = static_cast<long>(seqs_.size());
  recent_.clear();  // the change test starts afresh (EkfCheckpoint)
  second_look_seq_ = c.second_look_onset >= 0 ? seqs_[c.second_look_onset] : -1;
  second_look_alternatives_ = c.second_look_onset >= 0 && c.second_look_alternatives;
  status_ = c.status;
  small_steps_ = c.small_steps;
  accepted_ = c.accepted;
  rejected_ = c.rejected;
  relinearizations_ = c.relinearizations;
}

void EkfIdentifier::Measure(const kinematics::PoseMeasurement& z,
                            const kinematics::EffectContext& context, const Eigen::VectorXd& state,
                            Eigen::VectorXd& r, Eigen::MatrixXd& H) const {
  const int ng = static_cast<int>(identified_.size());
  Eigen::VectorXd x_full = x_fixed_;
  for (int i = 0; i < ng; ++i) x_full(identified_[i]) = state(i);
  if (ext_.num_effect_params() == 0)
    kinematics::ResidualAndJacobian(ext_.base(), z, x_full, identified_, r, H);
  else
    ExtendedResidualAndJacobian(ext_, z, context, x_full, state.tail(ext_.num_effect_params()),
                                identified_, r, &H);
}

Eigen::MatrixXd EkfIdentifier::JointSignature(const kinematics::PoseMeasurement& z,
                                              const kinematics::EffectContext& context,
                                              const Eigen::VectorXd& state) const {
  const int nq = model().num_joints();
  Eigen::MatrixXd Hq(z.dimension(), nq), H_unused;
  Eigen::VectorXd r_plus, r_minus;
  for (int j = 0; j < nq; ++j) {
    const double h = 1e-6;  // [rad or m]
    kinematics::PoseMeasurement zq = z;
    zq.q(j) += h;
    Measure(zq, context, state, r_plus, H_unused);
    zq.q(j) -= 2 * h;
    Measure(zq, context, state, r_minus, H_unused);
    Hq.col(j) = (r_minus - r_plus) / (2 * h);  // r = z − h
  }
  return Hq;
}

void EkfIdentifier::Reject(EkfUpdateResult& result, std::string reason) {
  result.reason = std::move(reason);
  ++rejected_;
  last_rejection_ = result.reason;
}

int EkfIdentifier::Refine(int max_passes) {
  if (history_.empty()) return 0;
  return Relinearize(max_passes);
}

int EkfIdentifier::Relinearize(int max_passes) {
  const int n = static_cast<int>(x_.size());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  int passes = 0;
  for (int pass = 0; pass < max_passes; ++pass) {
    const Eigen::VectorXd x_ref = x_;
    Eigen::VectorXd x = x0_;
    Eigen::MatrixXd P = P0_;
    for (size_t k = 0; k < history_.size(); ++k) {
      const auto& m = history_[k];
      P += Eigen::MatrixXd(q_diag_.asDiagonal());
      if (inflations_[k].size()) P += inflations_[k];
      Measure(m, contexts_[k], x_ref, r, H);
      const Eigen::MatrixXd S = H * P * H.transpose() + m.covariance;
      const Eigen::MatrixXd K = S.llt().solve(H * P).transpose();
      x += K * (r - H * (x - x_ref));
      const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
      P = IKH * P * IKH.transpose() + K * m.covariance * K.transpose();
    }
    if (!x.allFinite()) break;  // keep the last finite estimate
    x_ = x;
    P_ = 0.5 * (P + P.transpose());
    ++relinearizations_;
    ++passes;
    if ((x_ - x_ref).cwiseAbs().maxCoeff() < settings_.relinearize_threshold) break;
  }
  x_lin_ = x_;
  return passes;
}

double EkfIdentifier::WindowEvidence() const {
  const int n = static_cast<int>(x_.size());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  Eigen::VectorXd x = x0_;
  Eigen::MatrixXd P = P0_;
  double minus_two_ln_l = 0;
  for (size_t k = 0; k < history_.size(); ++k) {
    const auto& m = history_[k];
    P += Eigen::MatrixXd(q_diag_.asDiagonal());
    if (inflations_[k].size()) P += inflations_[k];
    Measure(m, contexts_[k], x_, r, H);
    const Eigen::VectorXd innovation = r - H * (x - x_);  // linearised at the estimate
    const Eigen::MatrixXd S = H * P * H.transpose() + m.covariance;
    const Eigen::LLT<Eigen::MatrixXd> llt(S);
    minus_two_ln_l += innovation.dot(llt.solve(innovation)) +
                      2 * llt.matrixLLT().diagonal().array().log().sum();  // ln det S
    const Eigen::MatrixXd K = llt.solve(H * P).transpose();
    x += K * innovation;
    const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
    P = IKH * P * IKH.transpose() + K * m.covariance * K.transpose();
  }
  return minus_two_ln_l;
}

Eigen::VectorXd EkfIdentifier::x() const {
  Eigen::VectorXd full = x_fixed_;
  for (size_t i = 0; i < identified_.size(); ++i) full(identified_[i]) = x_(i);
  return full;
}

Eigen::VectorXd EkfIdentifier::sigma() const {
  Eigen::VectorXd full = Eigen::VectorXd::Zero(model().num_params());
  for (size_t i = 0; i < identified_.size(); ++i) full(identified_[i]) = std::sqrt(P_(i, i));
  return full;
}

Eigen::VectorXd EkfIdentifier::sigma_e() const {
  const int ne = num_effect_params();
  return P_.diagonal().tail(ne).cwiseSqrt();
}

void EkfIdentifier::FoldOldest() {
  const int n = static_cast<int>(x_.size());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  P0_ += Eigen::MatrixXd(q_diag_.asDiagonal());
  if (inflations_.front().size()) P0_ += inflations_.front();
  const kinematics::PoseMeasurement& m = history_.front();
  Measure(m, contexts_.front(), x_, r, H);
  const Eigen::MatrixXd S = H * P0_ * H.transpose() + m.covariance;
  const Eigen::MatrixXd K = S.llt().solve(H * P0_).transpose();
  const Eigen::VectorXd x0 = x0_ + K * (r - H * (x0_ - x_));
  if (x0.allFinite()) {
    x0_ = x0;
    const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
    P0_ = IKH * P0_ * IKH.transpose() + K * m.covariance * K.transpose();
    P0_ = 0.5 * (P0_ + P0_.transpose());
  }
  history_.erase(history_.begin());
  contexts_.erase(contexts_.begin());
  inflations_.erase(inflations_.begin());
  seqs_.erase(seqs_.begin());
}

int EkfIdentifier::Absorb(const kinematics::PoseMeasurement& z,
                          const kinematics::EffectContext& context,
                          const Eigen::MatrixXd& inflation, bool& ok, const Eigen::VectorXd* r0,
                          const Eigen::MatrixXd* H0) {
  const int n = static_cast<int>(x_.size());
  const Eigen::MatrixXd& R = z.covariance;
  // Eq. (42): random-walk prediction (and a released change's inflation).
  Eigen::MatrixXd P_prior = P_ + Eigen::MatrixXd(q_diag_.asDiagonal());
  if (inflation.size()) P_prior += inflation;
  const Eigen::VectorXd x_prior = x_;
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  Eigen::VectorXd x_i = x_prior;
  Eigen::MatrixXd K;
  int iterations = 0;
  for (int it = 0; it < std::max(1, settings_.max_iterations); ++it) {
    if (it == 0 && r0 && H0) {
      r = *r0;  // already measured at x_prior
      H = *H0;
    } else {
      Measure(z, context, x_i, r, H);
    }
    const Eigen::MatrixXd S = H * P_prior * H.transpose() + R;
    K = S.llt().solve(H * P_prior).transpose();  // P⁻ Hᵀ S⁻¹ (S and P⁻ symmetric)
    const Eigen::VectorXd x_next = x_prior + K * (r - H * (x_prior - x_i));
    const double step = (x_next - x_i).norm();
    x_i = x_next;
    iterations = it + 1;
    if (step < settings_.iteration_tolerance) break;
  }
  ok = x_i.allFinite();
  if (!ok) return iterations;
  const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
  P_ = IKH * P_prior * IKH.transpose() + K * R * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  x_ = x_i;
  ++accepted_;
  history_.push_back(z);
  contexts_.push_back(context);
  inflations_.push_back(inflation);
  seqs_.push_back(seq_);
  return iterations;
}

Eigen::MatrixXd InflationDirections(const Eigen::MatrixXd& inflation) {
  if (inflation.size() == 0) return Eigen::MatrixXd(inflation.rows(), 0);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(inflation);
  const Eigen::VectorXd& lambda = eig.eigenvalues();
  const double top = lambda.maxCoeff();
  std::vector<int> kept;
  for (int c = 0; c < lambda.size(); ++c)
    if (top > 0 && lambda(c) > 1e-9 * top) kept.push_back(c);
  Eigen::MatrixXd U(inflation.rows(), static_cast<Eigen::Index>(kept.size()));
  for (size_t c = 0; c < kept.size(); ++c) U.col(c) = eig.eigenvectors().col(kept[c]);
  return U;
}

namespace {

// Per candidate column (< ng: an identified parameter; ng + j: joint j's offset), the joint whose
// offset it is: joint j for its own column, and for a parameter the joint whose column it agrees
// with over the window's poses (|cos| > 0.99: θ_j on a D–H arm); −1 otherwise. W: the columns'
// inner products over the poses (ng + nq square).
std::vector<int> JointOfColumns(int ng, int nq, const Eigen::MatrixXd& W) {
  std::vector<int> joint(ng + nq, -1);
  for (int j = 0; j < nq; ++j) joint[ng + j] = j;
  for (int a = 0; a < ng; ++a)
    for (int j = 0; j < nq; ++j) {
      const double ab = W(a, ng + j), aa = W(a, a), bb = W(ng + j, ng + j);
      if (aa > 0 && bb > 0 && std::abs(ab) > 0.99 * std::sqrt(aa * bb)) joint[a] = j;
    }
  return joint;
}

// Names each direction of `c` (its candidate column in `columns`) and the joint it is the offset
// of, if any.
void NameDirections(DetectedChange& c, const std::vector<int>& columns,
                    const std::vector<int>& joint_of, int ng, const std::vector<int>& identified) {
  for (int col : columns) {
    c.parameters.push_back(col < ng ? identified[col] : -1);
    c.joints.push_back(joint_of[col]);
  }
}

}  // namespace

std::optional<DetectedChange> EkfIdentifier::TestForChange(bool stuck) {
  if (!settings_.detect_changes || (status_ == TrackingStatus::kConverging && !stuck))
    return std::nullopt;
  const int ng = static_cast<int>(identified_.size()), n = static_cast<int>(x_.size());
  const int nq = model().num_joints();
  // Candidate directions in the state: each identified geometric parameter, and each joint's
  // offset (an encoder swap) as the state change that reproduces it best over the window (the
  // base set may spread one joint's offset over several parameters; for a D–H arm it is θ_j).
  Eigen::MatrixXd AtA = Eigen::MatrixXd::Zero(ng, ng), AtQ = Eigen::MatrixXd::Zero(ng, nq);
  for (const Recent& p : recent_) {
    AtA.noalias() += p.A.leftCols(ng).transpose() * p.A.leftCols(ng);
    AtQ.noalias() += p.A.leftCols(ng).transpose() * p.Aq;
  }
  const Eigen::MatrixXd D_joint =
      AtA.completeOrthogonalDecomposition().solve(AtQ);   // ng × nq, one direction per joint
  Eigen::MatrixXd U = Eigen::MatrixXd::Zero(n, ng + nq);  // state direction of each column
  U.topLeftCorner(ng, ng).setIdentity();
  U.block(0, ng, ng, nq) = D_joint;
  std::vector<Eigen::VectorXd> e;
  std::vector<Eigen::MatrixXd> A;
  for (const Recent& p : recent_) {
    e.push_back(p.e);
    A.push_back(p.A.leftCols(ng) * U.topRows(ng));
  }
  StepTestSettings ts;
  ts.false_alarm = settings_.change_false_alarm;
  ts.min_poses = settings_.change_min_poses;
  ts.max_params = settings_.change_max_params;
  ts.fit_probability = settings_.change_fit_probability;
  ts.naming_probability = settings_.change_naming_probability;
  // A joint's offset and the parameter that is it are one change under two names.
  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(ng + nq, ng + nq);
  for (const Eigen::MatrixXd& Ak : A) W.noalias() += Ak.transpose() * Ak;
  const std::vector<int> joint_of = JointOfColumns(ng, nq, W);
  ts.same_change = joint_of;
  const StepTestResult t = TestForStep(e, A, ts);
  if (!t.detected) {
    candidate_count_ = 0;
    return std::nullopt;
  }
  std::vector<int> sorted = t.columns;
  std::sort(sorted.begin(), sorted.end());
  const long onset_seq = recent_[t.onset].seq;
  if (candidate_count_ > 0 && onset_seq == candidate_onset_ && sorted == candidate_params_) {
    ++candidate_count_;
  } else {
    candidate_onset_ = onset_seq;
    candidate_params_ = sorted;
    candidate_count_ = 1;
  }
  if (candidate_count_ < settings_.change_confirmations) return std::nullopt;
  candidate_count_ = 0;
  DetectedChange c;
  const bool alternatives = !t.alternatives.empty();
  const std::vector<int>& columns = alternatives ? t.alternatives : t.columns;
  c.step = alternatives ? t.alternative_step : t.step;
  c.step_sigma = alternatives ? t.alternative_sigma : t.step_sigma;
  c.probability = t.alternative_probability;
  c.glr = t.glr;
  c.threshold = t.threshold;
  c.onset_poses_ago = static_cast<int>(recent_.size()) - 1 - t.onset;
  c.directions.resize(n, static_cast<int>(columns.size()));
  for (size_t i = 0; i < columns.size(); ++i)
    c.directions.col(static_cast<int>(i)) = U.col(columns[i]);
  NameDirections(c, columns, joint_of, ng, identified_);
  Release(c, static_cast<size_t>(t.onset));
  return c;
}

void EkfIdentifier::Release(const DetectedChange& change, size_t onset) {
  const int n = static_cast<int>(x_.size());
  const long onset_seq = recent_[onset].seq;
  while (!seqs_.empty() && seqs_.back() >= onset_seq) {
    history_.pop_back();
    contexts_.pop_back();
    inflations_.pop_back();
    seqs_.pop_back();
    --accepted_;
  }
  // The jump's prior along each released direction: wide enough that the poses since the onset,
  // not the prior, set its size. Alternatives: each is covered, and the point to relinearise at
  // is their probability-weighted step.
  Eigen::MatrixXd inflation = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < change.directions.cols(); ++i) {
    const Eigen::VectorXd u = change.directions.col(i);
    inflation +=
        (4 * change.step(i) * change.step(i) + 9 * change.step_sigma(i) * change.step_sigma(i)) *
        u * u.transpose();
    const double weight = change.probability.empty() ? 1.0 : change.probability[i];
    x_ += weight * change.step(i) * u;  // a better point to relinearise at
  }
  for (size_t k = onset; k < recent_.size(); ++k) {
    Recent& p = recent_[k];
    history_.push_back(p.z);
    contexts_.push_back(p.context);
    inflations_.push_back(k == onset ? inflation : Eigen::MatrixXd());
    seqs_.push_back(p.seq);
    ++accepted_;
    if (!p.accepted) --rejected_;
    p.accepted = true;
  }
  Relinearize(std::max(settings_.max_relinearize_passes, 1));
  recent_.clear();  // the test restarts on innovations after the release
  candidate_count_ = 0;
  small_steps_ = 0;
  status_ = TrackingStatus::kChangeDetected;
  changes_.push_back(change);
  second_look_seq_ = settings_.change_second_look ? onset_seq : -1;
  second_look_alternatives_ = !change.probability.empty();
}

std::optional<DetectedChange> EkfIdentifier::SecondLook(size_t k0) {
  const int n = static_cast<int>(x_.size()), ng = static_cast<int>(identified_.size());
  const int nq = model().num_joints(), nc = ng + nq;
  const Eigen::MatrixXd released = InflationDirections(inflations_[k0]);
  const int m = static_cast<int>(released.cols());
  if (m == 0) return std::nullopt;
  // The window as one linear problem around the estimate: rows of the poses (whitened by their
  // covariance) and of the window's prior; G the state's columns, C the candidates' (zero before
  // the onset), Cq every pose's joint-offset signature (for the joints' state directions).
  int rows = n;
  for (const auto& z : history_) rows += z.dimension();
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(rows, n), C = Eigen::MatrixXd::Zero(rows, nc),
                  Cq(rows, nq);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(rows);
  Cq.setZero();
  {
    const Eigen::LLT<Eigen::MatrixXd> llt0(P0_);
    if (llt0.info() != Eigen::Success) return std::nullopt;
    G.topRows(n) = llt0.matrixL().solve(Eigen::MatrixXd::Identity(n, n));
    b.head(n) = llt0.matrixL().solve(x0_ - x_);
  }
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  for (size_t k = 0, row = n; k < history_.size(); ++k) {
    const kinematics::PoseMeasurement& z = history_[k];
    const int d = z.dimension();
    Measure(z, contexts_[k], x_, r, H);
    const Eigen::MatrixXd Hq = JointSignature(z, contexts_[k], x_);
    const Eigen::LLT<Eigen::MatrixXd> llt(z.covariance);
    G.middleRows(row, d) = llt.matrixL().solve(H);
    b.segment(row, d) = llt.matrixL().solve(r);
    Cq.middleRows(row, d) = llt.matrixL().solve(Hq);
    if (k >= k0) {
      C.block(row, 0, d, ng) = G.block(row, 0, d, ng);
      C.block(row, ng, d, nq) = Cq.middleRows(row, d);
    }
    row += d;
  }
  // Each joint's offset as a state direction: the state change that reproduces it best over the
  // window (θ_j on a D–H arm).
  const Eigen::MatrixXd D_joint =
      G.bottomRows(rows - n).leftCols(ng).completeOrthogonalDecomposition().solve(
          Cq.bottomRows(rows - n));
  // A step along state directions U from history entry `onset` on, as columns: each pose's
  // Jacobian along them, zero before the onset and in the prior rows.
  const auto step_columns = [&](size_t onset, const Eigen::MatrixXd& U) {
    Eigen::MatrixXd cols = Eigen::MatrixXd::Zero(rows, U.cols());
    for (size_t k = 0, row = n; k < history_.size(); ++k) {
      const int d = history_[k].dimension();
      if (k >= onset) cols.middleRows(row, d) = G.middleRows(row, d) * U;
      row += d;
    }
    return cols;
  };
  // The window's other releases are part of its geometry: a step along their released
  // directions from their onsets on (the range of each inflation).
  Eigen::MatrixXd G_steps = G;
  for (size_t j = 0; j < inflations_.size(); ++j) {
    if (j == k0 || inflations_[j].size() == 0) continue;
    const Eigen::MatrixXd cols = step_columns(j, InflationDirections(inflations_[j]));
    G_steps.conservativeResize(Eigen::NoChange, G_steps.cols() + cols.cols());
    G_steps.rightCols(cols.cols()) = cols;
  }
  // Project the geometry out (the state refitted with every candidate).
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(G_steps);
  qr.setThreshold(1e-10);
  const Eigen::MatrixXd Q = qr.householderQ() * Eigen::MatrixXd::Identity(rows, qr.rank());
  const Eigen::VectorXd b_perp = b - Q * (Q.transpose() * b);
  const Eigen::MatrixXd C_perp = C - Q * (Q.transpose() * C);
  // What a set of columns (beyond the geometry) explains: |projection of b⊥ on their span|².
  const auto explained = [&](const Eigen::MatrixXd& cols) {
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> q(cols);
    q.setThreshold(1e-10);
    if (q.rank() == 0) return 0.0;
    const Eigen::MatrixXd Qc = q.householderQ() * Eigen::MatrixXd::Identity(cols.rows(), q.rank());
    return (Qc.transpose() * b_perp).squaredNorm();
  };
  // The joint each candidate is the offset of, over the window's poses (not the prior rows).
  Eigen::MatrixXd pose_columns(rows - n, nc);
  pose_columns << G.bottomRows(rows - n).leftCols(ng), Cq.bottomRows(rows - n);
  const std::vector<int> joint_of = JointOfColumns(ng, nq, pose_columns.transpose() * pose_columns);
  DetectedChange c;
  c.threshold = changes_.empty() ? 0.0 : changes_.back().threshold;
  c.onset_poses_ago = static_cast<int>(history_.size()) - 1 - static_cast<int>(k0);
  std::vector<int> chosen;
  const auto direction = [&](int col) {  // a candidate's state direction
    Eigen::VectorXd u = Eigen::VectorXd::Zero(n);
    if (col < ng)
      u(col) = 1.0;
    else
      u.head(ng) = D_joint.col(col - ng);
    return u;
  };
  if ((m == 1 || second_look_alternatives_) && settings_.change_naming_probability > 0) {
    // A single-parameter change: the window, with the onset known, says which direction it is
    // along, or which it may be along (change_detection.hpp, StepAlternatives), and the release
    // moves there unless that is what is released already.
    Eigen::VectorXd step, sigma;
    chosen =
        StepAlternatives(C_perp.transpose() * C_perp, C_perp.transpose() * b_perp, joint_of,
                         settings_.change_naming_probability,
                         std::max(settings_.change_max_params, 1), &c.probability, &step, &sigma);
    if (chosen.empty()) return std::nullopt;
    Eigen::MatrixXd U(n, static_cast<Eigen::Index>(chosen.size()));
    for (size_t i = 0; i < chosen.size(); ++i) U.col(static_cast<int>(i)) = direction(chosen[i]);
    // The directions released already: nothing to move. (Not columns merely alike over the
    // window: a KR6's a4_dz for a stepped joint-3 offset, |cos| > 0.99 over its poses, left
    // the error 30 poses after the step at 3.8–5.1× the error before it, against 0.96–1.15×
    // once the release moved.)
    const Eigen::MatrixXd outside = U - released * (released.transpose() * U);
    if (U.cols() == m && outside.norm() <= 1e-6 * U.norm()) return std::nullopt;
    if (chosen.size() == 1) c.probability.clear();  // one step along it
    c.step = step;
    c.step_sigma = sigma;
    c.glr = step(0) * step(0) / (sigma(0) * sigma(0));  // the likeliest's 2 ln Λ
    c.directions = U;
  } else {
    Eigen::MatrixXd chosen_cols(rows, 0);
    const Eigen::MatrixXd released_cols = step_columns(k0, released);
    const double gain_released = explained(released_cols - Q * (Q.transpose() * released_cols));
    // Forward selection of as many directions among the candidates.
    double gain = 0;
    for (int step = 0; step < m; ++step) {
      int best = -1;
      double best_gain = -1;
      for (int col = 0; col < nc; ++col) {
        if (std::find(chosen.begin(), chosen.end(), col) != chosen.end()) continue;
        if (C_perp.col(col).squaredNorm() <= 0) continue;
        Eigen::MatrixXd trial(rows, chosen_cols.cols() + 1);
        trial << chosen_cols, C_perp.col(col);
        const double gc = explained(trial);
        if (gc > best_gain) {
          best_gain = gc;
          best = col;
        }
      }
      if (best < 0) return std::nullopt;
      chosen.push_back(best);
      chosen_cols.conservativeResize(Eigen::NoChange, chosen_cols.cols() + 1);
      chosen_cols.col(chosen_cols.cols() - 1) = C_perp.col(best);
      gain = best_gain;
    }
    // Equal numbers of parameters: the likelihood decides. Ties (the same directions, or columns
    // the window cannot tell apart) keep the release.
    if (!(gain > gain_released * (1 + 1e-9) + 1e-12)) return std::nullopt;
    c.glr = gain;
    c.directions = Eigen::MatrixXd::Zero(n, m);
    for (int i = 0; i < m; ++i) c.directions.col(i) = direction(chosen[i]);
    // The step along the chosen columns with the geometry refitted, and its 1σ (whitened: unit
    // noise).
    const Eigen::MatrixXd N = chosen_cols.transpose() * chosen_cols;
    const Eigen::MatrixXd N_inv = N.completeOrthogonalDecomposition().pseudoInverse();
    c.step = N_inv * (chosen_cols.transpose() * b_perp);
    c.step_sigma = N_inv.diagonal().cwiseMax(0.0).cwiseSqrt();
  }
  NameDirections(c, chosen, joint_of, ng, identified_);
  // Move the release: the onset's inflation along the new directions, sized as Release sizes it.
  Eigen::MatrixXd inflation = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < c.directions.cols(); ++i) {
    const Eigen::VectorXd u = c.directions.col(i);
    inflation +=
        (4 * c.step(i) * c.step(i) + 9 * c.step_sigma(i) * c.step_sigma(i)) * u * u.transpose();
  }
  inflations_[k0] = inflation;
  second_look_alternatives_ = !c.probability.empty();
  Relinearize(std::max(settings_.max_relinearize_passes, 1));
  small_steps_ = 0;
  status_ = TrackingStatus::kReconverging;
  // The release looked at is the latest (a later one replaces the pending look); after a
  // restart the changes before it are not known.
  if (changes_.empty())
    changes_.push_back(c);
  else
    changes_.back() = c;
  return c;
}

void EkfIdentifier::UpdateStatus(double max_step_sigma) {
  small_steps_ = max_step_sigma < settings_.converged_step_sigma ? small_steps_ + 1 : 0;
  const bool settled = small_steps_ >= settings_.converged_poses;
  switch (status_) {
    case TrackingStatus::kConverging:
      if (settled) {
        status_ = TrackingStatus::kConverged;
        recent_.clear();  // innovations of a converging filter are not the test's
      }
      break;
    case TrackingStatus::kChangeDetected:
    case TrackingStatus::kReconverging:
      status_ = settled ? TrackingStatus::kConverged : TrackingStatus::kReconverging;
      break;
    case TrackingStatus::kConverged:
      break;
  }
}

EkfUpdateResult EkfIdentifier::Update(const kinematics::PoseMeasurement& z,
                                      const kinematics::EffectContext& context) {
  EkfUpdateResult result;
  result.status = status_;
  std::string invalid = kinematics::Validate(model(), z);
  if (invalid.empty()) invalid = ValidateContext(ext_, context);
  if (!invalid.empty()) {
    Reject(result, invalid);
    return result;
  }
  ++seq_;
  const Eigen::VectorXd x_before = x_;

  // The innovation at the prior (Eq. 42–43), whitened for the change test.
  const Eigen::MatrixXd P_prior = P_ + Eigen::MatrixXd(q_diag_.asDiagonal());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  Measure(z, context, x_, r, H);
  const Eigen::MatrixXd S = H * P_prior * H.transpose() + z.covariance;
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  result.nis = r.dot(llt.solve(r));
  result.gate = settings_.gate_probability < 1.0
                    ? ChiSquareQuantile(settings_.gate_probability, z.dimension())
                    : std::numeric_limits<double>::infinity();
  const bool gated = accepted_ >= settings_.gate_after && result.nis > result.gate;
  // While converging the test does not run: a converging filter's innovations carry the
  // linearisation of a state still poorly known. It runs all the same once the gate has refused
  // `change_min_poses` of the poses in the test's window: a consistent filter refuses one pose in
  // 1/(1 − gate_probability), so a converging filter that refuses poses again and again is stuck
  // (the arm changed before the filter settled: the demo's arm stepped at its 25th of 50 stops
  // was refused to the end, with nothing said), and only the test can tell a change from
  // outliers.
  if (settings_.detect_changes && std::isfinite(result.nis)) {
    const Eigen::MatrixXd Hq = JointSignature(z, context, x_);
    // Marked refused only once the gate has counted it (a release retakes it uncounted).
    recent_.push_back({z, context, seq_, true, llt.matrixL().solve(r), llt.matrixL().solve(H),
                       llt.matrixL().solve(Hq)});
    if (static_cast<int>(recent_.size()) > std::max(settings_.change_window, 1))
      recent_.erase(recent_.begin());
    int refused = gated ? 1 : 0;
    for (size_t k = 0; k + 1 < recent_.size(); ++k) refused += recent_[k].accepted ? 0 : 1;
    const bool stuck = refused >= settings_.change_min_poses;
    if (std::optional<DetectedChange> change = TestForChange(stuck)) {
      result.accepted = true;
      result.change = std::move(change);
      result.status = status_;
      return result;
    }
  }
  if (gated) {
    Reject(result, "innovation " + std::to_string(result.nis) + " beyond the gate " +
                       std::to_string(result.gate));
    if (!recent_.empty() && recent_.back().seq == seq_) recent_.back().accepted = false;
    return result;
  }
  bool ok = true;
  result.iterations = Absorb(z, context, Eigen::MatrixXd(), ok, &r, &H);
  if (!ok) {
    Reject(result, "update diverged (non-finite state)");
    if (!recent_.empty() && recent_.back().seq == seq_) recent_.pop_back();
    return result;
  }
  result.accepted = true;
  if (settings_.relinearize_threshold > 0 &&
      (x_ - x_lin_).cwiseAbs().maxCoeff() > settings_.relinearize_threshold)
    Relinearize(settings_.max_relinearize_passes);
  // Bounded cost: the window keeps at least the change test's poses.
  const int keep = std::max(settings_.window_poses, settings_.change_window);
  if (settings_.window_poses > 0)
    while (static_cast<int>(history_.size()) > keep) FoldOldest();
  double max_step = 0;
  for (int i = 0; i < static_cast<int>(identified_.size()); ++i)
    max_step =
        std::max(max_step, std::abs(x_(i) - x_before(i)) / std::sqrt(std::max(P_(i, i), 1e-300)));
  UpdateStatus(max_step);
  if (second_look_seq_ >= 0) {
    const auto at = std::find(seqs_.begin(), seqs_.end(), second_look_seq_);
    if (at == seqs_.end()) {
      second_look_seq_ = -1;  // its onset left the window: nothing to look at
    } else if (static_cast<int>(seqs_.end() - at) >= std::max(settings_.change_window, 1)) {
      second_look_seq_ = -1;
      result.reattributed = SecondLook(static_cast<size_t>(at - seqs_.begin()));
    }
  }
  result.status = status_;
  return result;
}

}  // namespace rcal::identification
