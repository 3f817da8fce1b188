#include "rcal/identification/ekf_identifier.hpp"

#include <Eigen/Cholesky>
#include <stdexcept>

#include "rcal/identification/chi_square.hpp"

namespace rcal::identification {

EkfIdentifier::EkfIdentifier(const kinematics::KinematicModel& model, std::vector<int> identified,
                             EkfSettings settings, Eigen::VectorXd x_fixed)
    : model_(model),
      identified_(std::move(identified)),
      settings_(settings),
      x_fixed_(x_fixed.size() ? std::move(x_fixed) : model.Nominal()) {
  if (x_fixed_.size() != model_.num_params() || !x_fixed_.allFinite())
    throw std::invalid_argument("x_fixed: expected " + std::to_string(model_.num_params()) +
                                " finite values");
  for (int i : identified_)
    if (i < 0 || i >= model_.num_params())
      throw std::invalid_argument("identified: index " + std::to_string(i) + " out of range");
  q_diag_.resize(identified_.size());
  for (size_t i = 0; i < identified_.size(); ++i) {
    const bool angle = model_.parameters()[identified_[i]].is_angle;
    const double s = angle ? settings_.drift_sigma_angle : settings_.drift_sigma_length;
    q_diag_(i) = s * s;
  }
  Reset();
}

void EkfIdentifier::Reset() {
  const int n = static_cast<int>(identified_.size());
  x_ = Eigen::VectorXd::Zero(n);
  P_ = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    const bool angle = model_.parameters()[identified_[i]].is_angle;
    const double s = angle ? settings_.prior_sigma_angle : settings_.prior_sigma_length;
    P_(i, i) = s * s;
  }
  accepted_ = rejected_ = relinearizations_ = 0;
  last_rejection_.clear();
  x0_ = x_;
  P0_ = P_;
  x_lin_ = x_;
  history_.clear();
}

void EkfIdentifier::SetState(const Eigen::VectorXd& x_identified, const Eigen::MatrixXd& P) {
  const int n = static_cast<int>(identified_.size());
  if (x_identified.size() != n)
    throw std::invalid_argument("x: " + std::to_string(x_identified.size()) + " values, expected " +
                                std::to_string(n));
  if (P.rows() != n || P.cols() != n)
    throw std::invalid_argument("P: wrong size, expected " + std::to_string(n) + "x" +
                                std::to_string(n));
  if (!x_identified.allFinite()) throw std::invalid_argument("x: not finite");
  if (!P.allFinite()) throw std::invalid_argument("P: not finite");
  x_ = x_identified;
  P_ = 0.5 * (P + P.transpose());
  x0_ = x_;
  P0_ = P_;
  x_lin_ = x_;
  history_.clear();
}

EkfCheckpoint EkfIdentifier::Checkpoint() const {
  return {x0_, x_, x_lin_, P0_, P_, history_, accepted_, rejected_, relinearizations_};
}

void EkfIdentifier::Restore(const EkfCheckpoint& c) {
  const int n = static_cast<int>(identified_.size());
  const auto check_vec = [n](const Eigen::VectorXd& v, const char* name) {
    if (v.size() != n || !v.allFinite())
      throw std::invalid_argument(std::string(name) + ": wrong size or not finite");
  };
  const auto check_mat = [n](const Eigen::MatrixXd& M, const char* name) {
    if (M.rows() != n || M.cols() != n || !M.allFinite())
      throw std::invalid_argument(std::string(name) + ": wrong size or not finite");
  };
  check_vec(c.x0, "x0");
  check_vec(c.x, "x");
  check_vec(c.x_lin, "x_lin");
  check_mat(c.P0, "P0");
  check_mat(c.P, "P");
  for (size_t k = 0; k < c.history.size(); ++k) {
    const std::string why = kinematics::Validate(model_, c.history[k]);
    if (!why.empty()) throw std::invalid_argument("history[" + std::to_string(k) + "]." + why);
  }
  x0_ = c.x0;
  x_ = c.x;
  x_lin_ = c.x_lin;
  P0_ = c.P0;
  P_ = c.P;
  history_ = c.history;
  accepted_ = c.accepted;
  rejected_ = c.rejected;
  relinearizations_ = c.relinearizations;
}

int EkfIdentifier::Refine(int max_passes) {
  if (history_.empty()) return 0;
  return Relinearize(max_passes);
}

int EkfIdentifier::Relinearize(int max_passes) {
  const int n = static_cast<int>(identified_.size());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  int passes = 0;
  for (int pass = 0; pass < max_passes; ++pass) {
    const Eigen::VectorXd x_ref = x_;
    Eigen::VectorXd x_full = this->x();
    Eigen::VectorXd x = x0_;
    Eigen::MatrixXd P = P0_;
    for (const auto& m : history_) {
      P += Eigen::MatrixXd(q_diag_.asDiagonal());
      kinematics::ResidualAndJacobian(model_, m, x_full, identified_, r, H);
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
  Eigen::VectorXd full = Eigen::VectorXd::Zero(model_.num_params());
  for (size_t i = 0; i < identified_.size(); ++i) full(identified_[i]) = std::sqrt(P_(i, i));
  return full;
}

EkfUpdateResult EkfIdentifier::Update(const kinematics::PoseMeasurement& z) {
  EkfUpdateResult result;
  const std::string invalid = kinematics::Validate(model_, z);
  if (!invalid.empty()) {
    result.reason = invalid;
    ++rejected_;
    last_rejection_ = invalid;
    return result;
  }
  const int n = static_cast<int>(identified_.size());
  const Eigen::MatrixXd& R = z.covariance;

  // Eq. (42): random-walk prediction.
  const Eigen::MatrixXd P_prior = P_ + Eigen::MatrixXd(q_diag_.asDiagonal());
  const Eigen::VectorXd x_prior = x_;

  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  Eigen::VectorXd x_full = x();
  kinematics::ResidualAndJacobian(model_, z, x_full, identified_, r, H);

  Eigen::MatrixXd S = H * P_prior * H.transpose() + R;
  Eigen::LLT<Eigen::MatrixXd> llt(S);
  result.nis = r.dot(llt.solve(r));
  result.gate = settings_.gate_probability < 1.0
                    ? ChiSquareQuantile(settings_.gate_probability, z.dimension())
                    : std::numeric_limits<double>::infinity();
  if (accepted_ >= settings_.gate_after && result.nis > result.gate) {
    result.reason = "innovation " + std::to_string(result.nis) + " beyond the gate " +
                    std::to_string(result.gate);
    ++rejected_;
    last_rejection_ = result.reason;
    return result;
  }

  Eigen::VectorXd x_i = x_prior;
  Eigen::MatrixXd K;
  for (int it = 0; it < std::max(1, settings_.max_iterations); ++it) {
    if (it > 0) {
      for (int k = 0; k < n; ++k) x_full(identified_[k]) = x_i(k);
      kinematics::ResidualAndJacobian(model_, z, x_full, identified_, r, H);
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
    result.reason = "update diverged (non-finite state)";
    ++rejected_;
    last_rejection_ = result.reason;
    return result;
  }
  const Eigen::MatrixXd IKH = Eigen::MatrixXd::Identity(n, n) - K * H;
  P_ = IKH * P_prior * IKH.transpose() + K * R * K.transpose();
  P_ = 0.5 * (P_ + P_.transpose());
  x_ = x_i;
  ++accepted_;
  result.accepted = true;
  history_.push_back(z);
  if (settings_.relinearize_threshold > 0 &&
      (x_ - x_lin_).cwiseAbs().maxCoeff() > settings_.relinearize_threshold)
    Relinearize(settings_.max_relinearize_passes);
  return result;
}

}  // namespace rcal::identification
