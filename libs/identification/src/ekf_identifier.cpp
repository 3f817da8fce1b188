#include "rcal/identification/ekf_identifier.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <stdexcept>

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
}

EkfCheckpoint EkfIdentifier::Checkpoint() const {
  EkfCheckpoint c{x0_, x_,      x_lin_, P0_, P_, history_, accepted_, rejected_, relinearizations_,
                  {},  x_fixed_};
  if (ext_.num_effect_params() > 0) c.contexts = contexts_;
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
  if (c.x_fixed.size() != 0) x_fixed_ = c.x_fixed;
  x0_ = c.x0;
  x_ = c.x;
  x_lin_ = c.x_lin;
  P0_ = c.P0;
  P_ = c.P;
  history_ = c.history;
  contexts_ = c.contexts;
  contexts_.resize(history_.size());  // none given: default contexts
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

EkfUpdateResult EkfIdentifier::Update(const kinematics::PoseMeasurement& z,
                                      const kinematics::EffectContext& context) {
  EkfUpdateResult result;
  std::string invalid = kinematics::Validate(model(), z);
  if (invalid.empty()) invalid = ValidateContext(ext_, context);
  if (!invalid.empty()) {
    Reject(result, invalid);
    return result;
  }
  const int n = static_cast<int>(x_.size());
  const Eigen::MatrixXd& R = z.covariance;

  // Eq. (42): random-walk prediction.
  const Eigen::MatrixXd P_prior = P_ + Eigen::MatrixXd(q_diag_.asDiagonal());
  const Eigen::VectorXd x_prior = x_;

  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  Measure(z, context, x_prior, r, H);

  Eigen::MatrixXd S = H * P_prior * H.transpose() + R;
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  result.nis = r.dot(llt.solve(r));
  result.gate = settings_.gate_probability < 1.0
                    ? ChiSquareQuantile(settings_.gate_probability, z.dimension())
                    : std::numeric_limits<double>::infinity();
  if (accepted_ >= settings_.gate_after && result.nis > result.gate) {
    Reject(result, "innovation " + std::to_string(result.nis) + " beyond the gate " +
                       std::to_string(result.gate));
    return result;
  }

  Eigen::VectorXd x_i = x_prior;
  Eigen::MatrixXd K;
  for (int it = 0; it < std::max(1, settings_.max_iterations); ++it) {
    if (it > 0) {
      Measure(z, context, x_i, r, H);
      S = H * P_prior * H.transpose() + R;
      llt.compute(S);
    }
    K = llt.solve(H * P_prior).transpose();  // P⁻ Hᵀ S⁻¹ (S and P⁻ symmetric)
    const Eigen::VectorXd x_next = x_prior + K * (r - H * (x_prior - x_i));
    const double step = (x_next - x_i).norm();
    x_i = x_next;
    result.iterations = it + 1;
    if (step < settings_.iteration_tolerance) break;
  }
  if (!x_i.allFinite()) {
    Reject(result, "update diverged (non-finite state)");
    return result;
  }
  const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
  P_ = IKH * P_prior * IKH.transpose() + K * R * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  x_ = x_i;
  ++accepted_;
  result.accepted = true;
  history_.push_back(z);
  contexts_.push_back(context);
  if (settings_.relinearize_threshold > 0 &&
      (x_ - x_lin_).cwiseAbs().maxCoeff() > settings_.relinearize_threshold)
    Relinearize(settings_.max_relinearize_passes);
  return result;
}

}  // namespace rcal::identification
