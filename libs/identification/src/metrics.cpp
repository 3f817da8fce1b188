#include "rcal/identification/metrics.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include "rcal/geometry/so3.hpp"

namespace rcal::identification {
namespace {

void Stats(const std::vector<double>& v, double& mean, double& max, double& rms) {
  if (v.empty()) return;
  mean = std::accumulate(v.begin(), v.end(), 0.0) / v.size();
  max = *std::max_element(v.begin(), v.end());
  double ss = 0;
  for (double e : v) ss += e * e;
  rms = std::sqrt(ss / v.size());
}

}  // namespace

PoseErrorStats Summarize(std::vector<double> position_m, std::vector<double> orientation_rad) {
  PoseErrorStats s;
  s.position_m = std::move(position_m);
  s.orientation_rad = std::move(orientation_rad);
  Stats(s.position_m, s.mean_position_m, s.max_position_m, s.rms_position_m);
  Stats(s.orientation_rad, s.mean_orientation_rad, s.max_orientation_rad, s.rms_orientation_rad);
  return s;
}

PoseErrorStats ErrorsAgainstMeasurements(const kinematics::KinematicModel& model,
                                         const Eigen::VectorXd& x,
                                         const std::vector<kinematics::PoseMeasurement>& ms) {
  std::vector<double> p, o;
  for (const auto& m : ms) {
    const kinematics::ToolPose pose = model.ForMarker(m.marker).Forward(m.q, x);
    p.push_back((m.p_WM_W - pose.p_WM_W).norm());
    if (m.has_orientation) o.push_back(geometry::AngleBetween(m.R_EI, pose.R_EI));
  }
  return Summarize(std::move(p), std::move(o));
}

PoseErrorStats ErrorsAgainstMeasurements(const kinematics::ExtendedModel& model,
                                         const Eigen::VectorXd& x, const Eigen::VectorXd& e,
                                         const std::vector<kinematics::PoseMeasurement>& ms,
                                         const std::vector<kinematics::EffectContext>& contexts) {
  if (!contexts.empty() && contexts.size() != ms.size())
    throw std::invalid_argument("ErrorsAgainstMeasurements: " + std::to_string(ms.size()) +
                                " measurements but " + std::to_string(contexts.size()) +
                                " contexts");
  const kinematics::EffectContext none;
  std::vector<double> p, o;
  for (size_t i = 0; i < ms.size(); ++i) {
    const auto& m = ms[i];
    const kinematics::ToolPose pose =
        model.ForMarker(m.marker).Forward(m.q, contexts.empty() ? none : contexts[i], x, e);
    p.push_back((m.p_WM_W - pose.p_WM_W).norm());
    if (m.has_orientation) o.push_back(geometry::AngleBetween(m.R_EI, pose.R_EI));
  }
  return Summarize(std::move(p), std::move(o));
}

PoseErrorStats ErrorsAgainstTruth(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                  const Eigen::VectorXd& x_true,
                                  const std::vector<Eigen::VectorXd>& qs) {
  return ErrorsAgainstTruth(model, x, x_true, qs, qs);
}

PoseErrorStats ErrorsAgainstTruth(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                  const Eigen::VectorXd& x_true,
                                  const std::vector<Eigen::VectorXd>& qs,
                                  const std::vector<Eigen::VectorXd>& qs_true) {
  if (qs.size() != qs_true.size())
    throw std::invalid_argument("ErrorsAgainstTruth: " + std::to_string(qs.size()) +
                                " readings but " + std::to_string(qs_true.size()) +
                                " true joint vectors");
  std::vector<double> p, o;
  for (size_t i = 0; i < qs.size(); ++i) {
    const kinematics::ToolPose a = model.Forward(qs[i], x), b = model.Forward(qs_true[i], x_true);
    p.push_back((a.p_WM_W - b.p_WM_W).norm());
    o.push_back(geometry::AngleBetween(a.R_EI, b.R_EI));
  }
  return Summarize(std::move(p), std::move(o));
}

std::pair<double, double> PredictedMeanErrors(const kinematics::KinematicModel& model,
                                              const std::vector<int>& identified,
                                              const Eigen::MatrixXd& C, const Eigen::VectorXd& x,
                                              const std::vector<Eigen::VectorXd>& qs, unsigned seed,
                                              int samples) {
  const Eigen::MatrixXd L = C.llt().matrixL();
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd J(6, model.num_params());
  Eigen::MatrixXd Jid(6, identified.size());
  double sum_p = 0, sum_o = 0;
  Eigen::VectorXd z(L.rows());
  for (const auto& q : qs) {
    model.IdentificationJacobian(q, x, J);
    for (size_t i = 0; i < identified.size(); ++i) Jid.col(i) = J.col(identified[i]);
    const Eigen::MatrixXd JL = Jid * L;
    for (int k = 0; k < samples; ++k) {
      for (int i = 0; i < z.size(); ++i) z(i) = n(rng);
      const Eigen::VectorXd d = JL * z;
      sum_p += d.head<3>().norm();
      sum_o += d.tail<3>().norm();
    }
  }
  const double count = static_cast<double>(qs.size()) * samples;
  return {sum_p / count, sum_o / count};
}

double MeanPositionErrorQuantile(const kinematics::KinematicModel& model,
                                 const std::vector<int>& identified, const Eigen::MatrixXd& C,
                                 const Eigen::VectorXd& x, const std::vector<Eigen::VectorXd>& qs,
                                 double p, unsigned seed, int samples) {
  if (!(p > 0.0 && p < 1.0))
    throw std::invalid_argument("MeanPositionErrorQuantile: p not in (0, 1)");
  if (samples < 1) throw std::invalid_argument("MeanPositionErrorQuantile: samples < 1");
  const auto k = static_cast<Eigen::Index>(identified.size());
  if (C.rows() != k || C.cols() != k)
    throw std::invalid_argument("MeanPositionErrorQuantile: C is not of the identified size");
  if (qs.empty()) return 0.0;
  const Eigen::MatrixXd L = C.llt().matrixL();
  // The position rows of every pose, stacked: one draw z gives every pose's δp = Jₚ L z at once.
  Eigen::MatrixXd JL(3 * static_cast<Eigen::Index>(qs.size()), k);
  Eigen::MatrixXd J(6, model.num_params());
  Eigen::MatrixXd Jid(3, k);
  for (size_t i = 0; i < qs.size(); ++i) {
    model.IdentificationJacobian(qs[i], x, J);
    for (Eigen::Index c = 0; c < k; ++c) Jid.col(c) = J.col(identified[c]).head<3>();
    JL.middleRows(3 * static_cast<Eigen::Index>(i), 3) = Jid * L;
  }
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd z(k), d(JL.rows());
  std::vector<double> means(samples);
  for (int s = 0; s < samples; ++s) {
    for (Eigen::Index i = 0; i < k; ++i) z(i) = n(rng);
    d.noalias() = JL * z;
    double sum = 0;
    for (size_t i = 0; i < qs.size(); ++i)
      sum += d.segment<3>(3 * static_cast<Eigen::Index>(i)).norm();
    means[s] = sum / static_cast<double>(qs.size());
  }
  const auto at = static_cast<size_t>(std::min<double>(samples - 1, std::floor(p * samples)));
  std::nth_element(means.begin(), means.begin() + static_cast<std::ptrdiff_t>(at), means.end());
  return means[at];
}

}  // namespace rcal::identification
