#include "rcal/estimation/mag_hard_iron.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "number_text.hpp"

namespace rcal::estimation {
namespace {

using detail::Num;

// Relinearisations of the iterated update (three: within 1e-6 µT of ten on BROAD's trial 33).
constexpr int kIterations = 3;

}  // namespace

Status CheckMagHardIronSettings(const MagHardIronSettings& s) {
  struct Field {
    const char* name;
    double value;
    bool zero_ok;
  };
  const Field fields[] = {{"noise", s.noise, false},
                          {"random_walk", s.random_walk, true},
                          {"initial_sigma", s.initial_sigma, false},
                          {"norm_sigma", s.norm_sigma, false},
                          {"gate_chi2", s.gate_chi2, false},
                          {"restart_time", s.restart_time, false},
                          {"confident_sigma", s.confident_sigma, false},
                          {"settle_time", s.settle_time, true},
                          {"apply_floor", s.apply_floor, true}};
  for (const Field& f : fields) {
    if (!std::isfinite(f.value) || f.value < 0.0 || (!f.zero_ok && f.value == 0.0))
      return Status::Error(std::string("mag_hard_iron.") + f.name + " = " + Num(f.value) +
                           (f.zero_ok ? ": must be finite and ≥ 0" : ": must be finite and > 0"));
  }
  return Status::Ok();
}

MagHardIron::MagHardIron(const MagHardIronSettings& settings)
    : settings_(settings), settings_status_(CheckMagHardIronSettings(settings)) {}

void MagHardIron::Start(double t, const Eigen::Vector3d& m_B) {
  t_ = t;
  // No offset known: the sample is taken as the earth's field. A restart (the sphere's centre
  // moved: a magnet attached or taken off) keeps r̂ and its variance, the earth's field here,
  // which a magnet on the sensor does not change.
  const bool restart = started_;
  if (!restart) {
    m0_ = m_B.norm();
    r_ = m0_;
  }
  const double P_rr = restart ? P_(3, 3) : std::pow(settings_.norm_sigma * m0_, 2);
  started_ = true;
  b_B_.setZero();
  P_.setZero();
  P_.topLeftCorner<3, 3>().diagonal().setConstant(std::pow(settings_.initial_sigma * m0_, 2));
  P_(3, 3) = P_rr;
  gated_time_ = 0.0;
  known_time_ = 0.0;
  applied_ = false;
}

Status MagHardIron::Update(double t, const Eigen::Vector3d& m_B) {
  if (!settings_status_.ok()) return settings_status_;
  if (!std::isfinite(t)) return Status::Error("mag_hard_iron: t = " + Num(t) + " is not finite");
  if (!m_B.allFinite() || m_B.isZero(0.0))
    return Status::Error("mag_hard_iron: m_B is not finite or is zero");
  if (started_ && t < t_)
    return Status::Error("mag_hard_iron: t = " + Num(t) + " s goes back from " + Num(t_) + " s");
  ++counters_.samples;
  if (!started_) {
    Start(t, m_B);
    return Status::Ok();
  }
  const double dt = t - t_;
  t_ = t;
  P_.topLeftCorner<3, 3>().diagonal().array() += std::pow(settings_.random_walk * m0_, 2) * dt;

  const Eigen::Vector3d v = m_B - b_B_;
  const double n = v.norm();
  if (n <= 0.0) {
    // The sample sits on the offset: no direction to learn from.
    ++counters_.gated;
    return Status::Ok();
  }
  Eigen::Vector4d H;
  H << -v / n, -1.0;
  const double R = std::pow(settings_.noise * m0_, 2);
  const double y = r_ - n;  // innovation of 0 = |m − b| − r
  const double S = H.dot(P_ * H) + R;
  if (y * y / S > settings_.gate_chi2) {
    ++counters_.gated;
    gated_time_ += dt;
    if (gated_time_ > settings_.restart_time) {
      // The sphere moved (a magnet attached, taken off or moved): fit again from here.
      Start(t, m_B);
      ++counters_.restarts;
    }
  } else {
    gated_time_ = 0.0;
    // Iterated EKF: the measurement relinearised about the updated state, as Gauss–Newton on
    // the prior and this sample. Right after a (re)start b̂ may be tens of µT from b, where one
    // linearisation about b̂ = 0 takes a wrong step and a covariance that no longer covers it.
    // The first pass is the gate's linearisation about the prior.
    const Eigen::Vector4d x_prior(b_B_.x(), b_B_.y(), b_B_.z(), r_);
    Eigen::Vector4d K = P_ * H / S;
    Eigen::Vector4d x = x_prior + K * y;
    for (int i = 1; i < kIterations; ++i) {
      const Eigen::Vector3d v_i = m_B - x.head<3>();
      const double n_i = v_i.norm();
      if (n_i <= 0.0) break;
      H << -v_i / n_i, -1.0;
      const double y_i = x(3) - n_i - H.dot(x_prior - x);
      K = P_ * H / (H.dot(P_ * H) + R);
      x = x_prior + K * y_i;
    }
    b_B_ = x.head<3>();
    r_ = x(3);
    // Joseph form with a scalar measurement: (I − K H) P (I − K H)ᵀ + K R Kᵀ.
    const Eigen::Matrix4d IKH = Eigen::Matrix4d::Identity() - K * H.transpose();
    P_ = IKH * P_ * IKH.transpose() + K * K.transpose() * R;
    P_ = 0.5 * (P_ + P_.transpose());
  }
  // Known and large for settle_time in a row: right after a (re)start the covariance shrinks
  // faster than a far b̂ converges (the norm is far from linear there).
  const bool known =
      b_sigma() < settings_.confident_sigma * m0_ && b_B_.norm() > settings_.apply_floor * r_;
  known_time_ = known ? known_time_ + dt : 0.0;
  applied_ = known && known_time_ >= settings_.settle_time;
  if (applied_) ++counters_.applied;
  return Status::Ok();
}

Eigen::Vector3d MagHardIron::offset_B() const {
  return applied_ ? b_B_ : Eigen::Vector3d::Zero();
}

double MagHardIron::b_sigma() const {
  if (!started_) return std::numeric_limits<double>::infinity();
  return std::sqrt(std::max(0.0, P_.topLeftCorner<3, 3>().trace()));
}

}  // namespace rcal::estimation
