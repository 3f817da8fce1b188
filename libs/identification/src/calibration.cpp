#include "rcal/identification/calibration.hpp"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include "rcal/geometry/so3.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/extended_lm.hpp"
#include "rcal/identification/extended_measurement.hpp"
#include "rcal/identification/setup_guess.hpp"
#include "rcal/kinematics/identifiability.hpp"

namespace rcal::identification {

Eigen::Isometry3d FitRigidTransform(const std::vector<Eigen::Vector3d>& a,
                                    const std::vector<Eigen::Vector3d>& b) {
  if (a.size() != b.size() || a.size() < 3)
    throw std::invalid_argument("FitRigidTransform: need the same number (≥ 3) of points");
  Eigen::Vector3d ca = Eigen::Vector3d::Zero(), cb = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < a.size(); ++i) {
    ca += a[i];
    cb += b[i];
  }
  ca /= a.size();
  cb /= b.size();
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < a.size(); ++i) H += (a[i] - ca) * (b[i] - cb).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (svd.singularValues()(1) < 1e-12 * std::max(1.0, svd.singularValues()(0)))
    throw std::invalid_argument("FitRigidTransform: points are collinear");
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = svd.matrixV() * D * svd.matrixU().transpose();
  T.translation() = cb - T.linear() * ca;
  return T;
}

std::vector<int> SetupParameters(const kinematics::KinematicModel& model) {
  std::vector<int> out;
  for (int i = 0; i < model.num_params(); ++i)
    if (kinematics::IsSetupGroup(model.parameters()[i].group)) out.push_back(i);
  return out;
}

Eigen::VectorXd InitialSetupGuess(const kinematics::KinematicModel& model,
                                  const std::vector<kinematics::PoseMeasurement>& ms) {
  return GuessSetup(model, ms).x;
}

std::vector<int> IdentifiableSubset(const kinematics::KinematicModel& model,
                                    const std::vector<kinematics::PoseMeasurement>& ms,
                                    const Eigen::VectorXd& x, const std::vector<int>& candidates) {
  // No candidate (a model whose set-up frames are all fixed) or no pose: nothing identifiable
  // (Eigen's QR of a matrix with no column reads out of bounds).
  if (candidates.empty() || ms.empty()) return {};
  int rows = 0;
  for (const auto& m : ms) rows += m.dimension();
  Eigen::MatrixXd J(rows, candidates.size());
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  int row = 0;
  for (const auto& m : ms) {
    kinematics::ResidualAndJacobian(model, m, x, candidates, r, H);
    J.middleRows(row, m.dimension()) = H;
    row += m.dimension();
  }
  for (int c = 0; c < J.cols(); ++c) {
    const double n = J.col(c).norm();
    if (n > 0) J.col(c) /= n;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(J);
  qr.setThreshold(1e-9);
  std::vector<int> out;
  for (int k = 0; k < qr.rank(); ++k) out.push_back(candidates[qr.colsPermutation().indices()(k)]);
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<int> PreferredBaseSet(const kinematics::KinematicModel& model,
                                  const std::vector<Eigen::VectorXd>& qs, const Eigen::VectorXd& x,
                                  kinematics::MeasurementKind kind) {
  Eigen::MatrixXd J = kinematics::StackedJacobian(model, qs, x, kind);
  for (int k = 0; k < J.cols(); ++k)
    if (J.col(k).norm() > 0) J.col(k).normalize();
  const auto& params = model.parameters();
  std::vector<int> order;
  for (const char* g : {"base", "earth", "imu", "marker"})
    for (int i = 0; i < model.num_params(); ++i)
      if (params[i].group == g) order.push_back(i);
  for (int i = 0; i < model.num_params(); ++i)
    if (std::find(order.begin(), order.end(), i) == order.end() && params[i].group != "tool")
      order.push_back(i);
  for (int i = 0; i < model.num_params(); ++i)
    if (params[i].group == "tool") order.push_back(i);
  std::vector<int> chosen;
  Eigen::Index rank = 0;
  for (int i : order) {
    Eigen::MatrixXd S(J.rows(), chosen.size() + 1);
    for (size_t k = 0; k < chosen.size(); ++k) S.col(k) = J.col(chosen[k]);
    S.col(chosen.size()) = J.col(i);
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(S);
    qr.setThreshold(1e-9);
    if (qr.rank() > rank) {
      chosen.push_back(i);
      rank = qr.rank();
    }
  }
  std::sort(chosen.begin(), chosen.end());
  return chosen;
}

ResidualSums SumResiduals(const kinematics::KinematicModel& model,
                          const std::vector<kinematics::PoseMeasurement>& ms,
                          const std::function<Eigen::VectorXd(size_t)>& x_at) {
  ResidualSums s;
  for (size_t k = 0; k < ms.size(); ++k) {
    const Eigen::VectorXd r = kinematics::Residual(model, ms[k], x_at(k));
    s.position_m2 += r.head<3>().squaredNorm();
    s.position_values += 3;
    if (ms[k].has_orientation) {
      s.orientation_rad2 += r.tail<3>().squaredNorm();
      s.orientation_values += 3;
    }
  }
  return s;
}

void SetNoise(std::vector<kinematics::PoseMeasurement>& ms, double sp, double so) {
  for (auto& m : ms) {
    const int d = m.dimension();
    m.covariance = Eigen::MatrixXd::Zero(d, d);
    m.covariance.topLeftCorner<3, 3>().diagonal().setConstant(sp * sp);
    if (m.has_orientation) m.covariance.bottomRightCorner<3, 3>().diagonal().setConstant(so * so);
  }
}

namespace {

struct Solved {
  Eigen::VectorXd x, sigma;
  double cost = 0;
  int iterations = 0;
};

Solved Solve(const kinematics::KinematicModel& model, const std::vector<int>& identified,
             const std::vector<kinematics::PoseMeasurement>& ms, const Eigen::VectorXd& x0,
             CalibrationSettings::Method method) {
  // The EKF estimates errors relative to its starting point: run it on the model with x0 folded
  // in by starting its state there. Its prior is wide enough that the start barely matters.
  const LmResult lm = BatchLm(model, identified).Solve(ms, x0);
  if (method == CalibrationSettings::Method::kLm) return {lm.x, lm.sigma, lm.cost, lm.iterations};
  // Offline every pose is known good (the dataset was chosen): no gate, and a prior wide enough
  // (10 cm, 10°) that it does not pull set-up frames found far from the drawing.
  EkfSettings es;
  es.gate_probability = 1.0;
  es.prior_sigma_length = 0.1;
  es.prior_sigma_angle = 0.17;
  EkfIdentifier ekf(model, identified, es, x0);
  Eigen::VectorXd start(identified.size());
  for (size_t i = 0; i < identified.size(); ++i) start(i) = x0(identified[i]);
  ekf.SetState(start, ekf.P());
  for (const auto& m : ms) ekf.Update(m);
  ekf.Refine(200);
  Eigen::VectorXd x = x0;
  for (size_t i = 0; i < identified.size(); ++i) x(identified[i]) = ekf.x_identified()(i);
  return {x, ekf.sigma(), BatchLm(model, identified).Cost(ms, x), ekf.accepted()};
}

}  // namespace

CalibrationFit Calibrate(const kinematics::KinematicModel& model,
                         std::vector<kinematics::PoseMeasurement> ms,
                         const CalibrationSettings& settings) {
  if (ms.size() < 3) throw std::invalid_argument("calibration needs at least 3 poses");
  CalibrationFit fit;
  const Eigen::VectorXd x0 = InitialSetupGuess(model, ms);
  fit.setup = IdentifiableSubset(model, ms, x0, SetupParameters(model));
  // Identifiability at the data's own poses (and markers), around the set-up guess.
  fit.identified = kinematics::AnalyzeIdentifiability(model, ms, x0).identifiable;

  fit.position_sigma_m = std::sqrt(ms.front().covariance(0, 0));
  fit.orientation_sigma_rad =
      ms.front().has_orientation ? std::sqrt(ms.front().covariance(3, 3)) : 0;
  const int iterations = settings.estimate_noise ? std::max(1, settings.noise_iterations) : 1;
  for (int it = 0; it < iterations; ++it) {
    SetNoise(ms, fit.position_sigma_m, fit.orientation_sigma_rad);
    const Solved nominal = Solve(model, fit.setup, ms, x0, CalibrationSettings::Method::kLm);
    // Later rounds only rescale the noise: they start from the last estimate.
    Solved full = Solve(model, fit.identified, ms, it == 0 ? nominal.x : fit.x, settings.method);
    // The base set is chosen where the model is linearised. The set-up guess can be a special
    // point the arm is not at: a marker guessed at the flange origin lies on the last joint's
    // axis, where that axis' tilt moves no measured point (2 of the 27 combinations of a 6R arm
    // with positions only are lost there, yet well determined at the truth: scaled singular
    // values 0.13 and 0.11 on the UR10). So choose it again at the estimate, and refit while it
    // grows (at most kRelinearisations times).
    constexpr int kRelinearisations = 3;
    for (int r = 0; r < kRelinearisations; ++r) {
      const std::vector<int> at_estimate =
          kinematics::AnalyzeIdentifiability(model, ms, full.x).identifiable;
      if (at_estimate.size() <= fit.identified.size()) break;
      fit.identified = at_estimate;
      full = Solve(model, fit.identified, ms, full.x, settings.method);
    }
    fit.x_nominal = nominal.x;
    fit.x = full.x;
    fit.sigma = full.sigma;
    fit.cost = full.cost;
    fit.iterations = full.iterations;
    if (!settings.estimate_noise) break;
    // Variance components: each block's mean squared residual, corrected for the parameters.
    const ResidualSums sums = SumResiduals(model, ms, [&](size_t) { return fit.x; });
    const double ss_p = sums.position_m2, ss_o = sums.orientation_rad2;
    const int n_p = sums.position_values, n_o = sums.orientation_values;
    const double redundancy = 1.0 - static_cast<double>(fit.identified.size()) / (n_p + n_o);
    // As many parameters as measured values: the fit passes through every pose and leaves no
    // residual to estimate the noise from (it was 0/0, a NaN covariance, an obscure error).
    if (!(redundancy > 0))
      throw std::invalid_argument(
          "calibration: " + std::to_string(ms.size()) + " poses give " + std::to_string(n_p + n_o) +
          " measured values for " + std::to_string(fit.identified.size()) +
          " identifiable parameters: the fit passes through every pose and leaves nothing to "
          "estimate the noise from; measure more poses (or give the noise and do not estimate "
          "it)");
    fit.position_sigma_m = std::sqrt(ss_p / (n_p * redundancy));
    if (n_o > 0) fit.orientation_sigma_rad = std::sqrt(ss_o / (n_o * redundancy));
  }
  fit.nominal_fit = ErrorsAgainstMeasurements(model, fit.x_nominal, ms);
  fit.calibrated_fit = ErrorsAgainstMeasurements(model, fit.x, ms);
  return fit;
}

std::vector<int> ConfigurationGroups(const std::vector<kinematics::PoseMeasurement>& ms) {
  std::vector<int> group(ms.size());
  std::vector<size_t> first;  // first measurement of each group
  for (size_t i = 0; i < ms.size(); ++i) {
    int g = -1;
    for (size_t k = 0; k < first.size() && g < 0; ++k) {
      const Eigen::VectorXd& q0 = ms[first[k]].q;
      if (q0.size() == ms[i].q.size() && (q0 - ms[i].q).lpNorm<Eigen::Infinity>() <= 1e-9)
        g = static_cast<int>(k);
    }
    if (g < 0) {
      g = static_cast<int>(first.size());
      first.push_back(i);
    }
    group[i] = g;
  }
  return group;
}

HeldOutFolds MakeHeldOutFolds(int n, const std::vector<bool>& is_test,
                              const CalibrationSettings& settings,
                              const std::vector<int>& configuration) {
  if (!configuration.empty() && static_cast<int>(configuration.size()) != n)
    throw std::invalid_argument("MakeHeldOutFolds: one configuration id per pose");
  HeldOutFolds out;
  out.fold.assign(n, -1);
  const bool split = std::any_of(is_test.begin(), is_test.end(), [](bool b) { return b; });
  if (split) {
    for (int i = 0; i < n && i < static_cast<int>(is_test.size()); ++i)
      out.fold[i] = is_test[i] ? 0 : -1;
    out.folds = 1;
    out.scheme = "cal/test split";
    return out;
  }
  // Whole configurations go to one fold: the rows of one configuration (several markers measured
  // there, or the pose measured again) share its joint errors, and a fold that fitted one of them
  // would flatter the others.
  std::vector<int> group = configuration;
  if (group.empty()) {
    group.resize(n);
    std::iota(group.begin(), group.end(), 0);
  }
  const int groups = n == 0 ? 0 : *std::max_element(group.begin(), group.end()) + 1;
  out.folds = std::min(settings.folds, groups);
  std::vector<int> order(groups), fold_of(groups);
  std::iota(order.begin(), order.end(), 0);
  std::mt19937_64 rng(settings.seed);
  std::shuffle(order.begin(), order.end(), rng);
  for (int k = 0; k < groups; ++k) fold_of[order[k]] = k % out.folds;
  for (int i = 0; i < n; ++i) out.fold[i] = fold_of[group[i]];
  const std::string unit = groups == n ? "" : " (by configuration)";
  out.scheme = (out.folds == groups ? "leave-one-out" : std::to_string(out.folds) + "-fold") + unit;
  return out;
}

Eigen::Vector3d MarkerOffsetFromPoint(const kinematics::KinematicModel& model, int slot,
                                      const Eigen::VectorXd& x, const Eigen::VectorXd& q,
                                      const Eigen::Vector3d& p_WM_W) {
  const kinematics::KinematicModel& view = model.ForMarker(slot);
  const kinematics::Marker& marker = model.markers().at(slot);
  // The view's chain ends at this marker: T_WM = T_WF · Trans(p_FM(x)), p_FM(x) = nominal + x.
  Eigen::Vector3d p_FM = marker.nominal;
  for (int i = 0; i < 3; ++i)
    if (marker.param[i] >= 0) p_FM(i) += x(marker.param[i]);
  const Eigen::Isometry3d T_WM = view.ToolFrame(q, x);
  const Eigen::Vector3d p_WF_W = T_WM.translation() - T_WM.linear() * p_FM;
  return T_WM.linear().transpose() * (p_WM_W - p_WF_W);
}

namespace {

// HeldOut and HeldOutExtended: with `ext`, each round also fits the extended model.
ExtendedHeldOutErrors HeldOutRounds(const kinematics::KinematicModel& model,
                                    const std::vector<kinematics::PoseMeasurement>& all,
                                    const std::vector<bool>& is_test, const CalibrationFit& fit,
                                    const CalibrationSettings& settings,
                                    const kinematics::ExtendedModel* ext,
                                    const std::vector<kinematics::EffectContext>* contexts,
                                    const Eigen::VectorXd& e0,
                                    const std::vector<MarkerReference>& references) {
  std::vector<kinematics::PoseMeasurement> ms = all;
  SetNoise(ms, fit.position_sigma_m, fit.orientation_sigma_rad);
  const int n = static_cast<int>(ms.size());
  HeldOutFolds folds = MakeHeldOutFolds(n, is_test, settings, ConfigurationGroups(ms));
  for (const MarkerReference& ref : references) {
    if (ref.measurement < 0 || ref.measurement >= n || ms[ref.measurement].marker != ref.slot)
      throw std::invalid_argument("HeldOut: reference measurement " +
                                  std::to_string(ref.measurement) + " is not one of marker slot " +
                                  std::to_string(ref.slot));
    folds.fold[ref.measurement] = -2;  // neither fitted nor judged
  }
  ExtendedHeldOutErrors out;
  out.scheme = folds.scheme;
  std::vector<double> nom_p, nom_o, cal_p, cal_o, ext_p, ext_o;
  const auto append = [](const PoseErrorStats& s, std::vector<double>& p, std::vector<double>& o) {
    p.insert(p.end(), s.position_m.begin(), s.position_m.end());
    o.insert(o.end(), s.orientation_rad.begin(), s.orientation_rad.end());
  };
  for (int f = 0; f < folds.folds; ++f) {
    std::vector<kinematics::PoseMeasurement> train, held;
    std::vector<kinematics::EffectContext> train_ctx, held_ctx;
    for (int i = 0; i < n; ++i) {
      if (folds.fold[i] == -2) continue;
      (folds.fold[i] == f ? held : train).push_back(ms[i]);
      if (contexts) (folds.fold[i] == f ? held_ctx : train_ctx).push_back((*contexts)[i]);
    }
    if (train.size() < 3 || held.empty()) continue;
    CalibrationSettings s = settings;
    s.estimate_noise = false;  // weights from the full fit; each fold refits its parameters
    CalibrationFit ff = Calibrate(model, train, s);
    // Markers measured at a stated configuration: their offset from that measurement with this
    // round's fit, in both the nominal and the calibrated model.
    for (const MarkerReference& ref : references) {
      const auto& m = ms[ref.measurement];
      const auto& marker = model.markers().at(ref.slot);
      for (Eigen::VectorXd* x : {&ff.x_nominal, &ff.x}) {
        const Eigen::Vector3d p_FM = MarkerOffsetFromPoint(model, ref.slot, *x, m.q, m.p_WM_W);
        for (int i = 0; i < 3; ++i)
          if (marker.param[i] >= 0) (*x)(marker.param[i]) = p_FM(i) - marker.nominal(i);
      }
    }
    append(ErrorsAgainstMeasurements(model, ff.x_nominal, held), nom_p, nom_o);
    append(ErrorsAgainstMeasurements(model, ff.x, held), cal_p, cal_o);
    if (!ext) continue;
    const ExtendedFit ef = FitExtended(*ext, ff.identified, train, train_ctx, ff.x, e0, false);
    Eigen::VectorXd r;
    for (size_t i = 0; i < held.size(); ++i) {
      ExtendedResidualAndJacobian(*ext, held[i], held_ctx[i], ef.x, ef.e, {}, r, nullptr);
      ext_p.push_back(r.head<3>().norm());
      if (r.size() == 6) ext_o.push_back(r.tail<3>().norm());
    }
  }
  out.nominal = Summarize(nom_p, nom_o);
  out.geometric = Summarize(cal_p, cal_o);
  out.extended = Summarize(ext_p, ext_o);
  return out;
}

}  // namespace

HeldOutErrors HeldOut(const kinematics::KinematicModel& model,
                      const std::vector<kinematics::PoseMeasurement>& ms,
                      const std::vector<bool>& is_test, const CalibrationFit& fit,
                      const CalibrationSettings& settings,
                      const std::vector<MarkerReference>& references) {
  const ExtendedHeldOutErrors e =
      HeldOutRounds(model, ms, is_test, fit, settings, nullptr, nullptr, {}, references);
  return {e.scheme, e.nominal, e.geometric};
}

ExtendedHeldOutErrors HeldOutExtended(const kinematics::ExtendedModel& model,
                                      const std::vector<kinematics::PoseMeasurement>& ms,
                                      const std::vector<kinematics::EffectContext>& contexts,
                                      const std::vector<bool>& is_test, const CalibrationFit& fit,
                                      const Eigen::VectorXd& e0,
                                      const CalibrationSettings& settings) {
  if (contexts.size() != ms.size())
    throw std::invalid_argument("HeldOutExtended: one context per measurement");
  if (e0.size() != model.num_effect_params())
    throw std::invalid_argument("HeldOutExtended: e0 has " + std::to_string(e0.size()) +
                                " values, expected " + std::to_string(model.num_effect_params()));
  return HeldOutRounds(model.base(), ms, is_test, fit, settings, &model, &contexts, e0, {});
}

}  // namespace rcal::identification
