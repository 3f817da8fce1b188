#include "rcal/kinematics/identifiability.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace rcal::kinematics {
namespace {

std::string FormatCoefficient(double c) {
  std::ostringstream s;
  s.precision(4);
  s << c;
  return s.str();
}

std::string Explain(const KinematicModel& m, const std::vector<int>& params,
                    const std::vector<double>& dir) {
  const auto& P = m.parameters();
  const std::string& p0 = P[params[0]].name;
  if (params.size() == 1) return p0 + " has no effect on the measured poses";
  if (params.size() == 2 && P[params[0]].is_angle == P[params[1]].is_angle &&
      std::abs(std::abs(dir[1]) - 1.0) < 1e-6) {
    // Δ(p0, p1) ∝ (1, ±1) is invisible, so only p0 ∓ p1 is seen.
    const std::string& p1 = P[params[1]].name;
    return p0 + " and " + p1 + " enter only as " + p0 + (dir[1] < 0 ? " + " : " - ") + p1;
  }
  std::ostringstream s;
  s << p0 << " cannot be separated from ";
  for (size_t i = 1; i < params.size(); ++i) {
    if (i > 1) s << (i + 1 == params.size() ? " and " : ", ");
    s << P[params[i]].name;
  }
  s << ": changing " << p0 << " by 1" << (P[params[0]].is_angle ? " rad" : " m");
  for (size_t i = 1; i < params.size(); ++i)
    s << ", " << P[params[i]].name << " by " << FormatCoefficient(dir[i])
      << (P[params[i]].is_angle ? " rad" : " m");
  s << " moves no measured pose";
  return s.str();
}

}  // namespace

std::vector<Eigen::VectorXd> SampleJointsInLimits(const KinematicModel& model, int count,
                                                  std::mt19937_64& rng, double margin) {
  std::vector<Eigen::VectorXd> qs;
  qs.reserve(std::max(0, count));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int k = 0; k < count; ++k) {
    Eigen::VectorXd q(model.num_joints());
    for (int j = 0; j < model.num_joints(); ++j) {
      const auto& J = model.joints()[j];
      q(j) = J.lower + (J.upper - J.lower) * (margin + (1.0 - 2.0 * margin) * u(rng));
    }
    qs.push_back(q);
  }
  return qs;
}

Eigen::MatrixXd StackedJacobian(const KinematicModel& model, const std::vector<Eigen::VectorXd>& qs,
                                const Eigen::VectorXd& x, MeasurementKind kind) {
  const int rows_per = kind == MeasurementKind::kFullPose ? 6 : 3;
  Eigen::MatrixXd J(rows_per * static_cast<int>(qs.size()), model.num_params());
  Eigen::MatrixXd Ji(6, model.num_params());
  for (size_t k = 0; k < qs.size(); ++k) {
    model.IdentificationJacobian(qs[k], x, Ji);
    J.middleRows(rows_per * k, rows_per) = Ji.topRows(rows_per);
  }
  return J;
}

Eigen::MatrixXd StackedJacobian(const KinematicModel& model, const std::vector<PoseMeasurement>& ms,
                                const Eigen::VectorXd& x) {
  int rows = 0;
  for (const auto& m : ms) rows += m.dimension();
  Eigen::MatrixXd J(rows, model.num_params());
  Eigen::MatrixXd Ji(6, model.num_params());
  int row = 0;
  for (const auto& m : ms) {
    model.ForMarker(m.marker).IdentificationJacobian(m.q, x, Ji);
    J.middleRows(row, m.dimension()) = Ji.topRows(m.dimension());
    row += m.dimension();
  }
  return J;
}

IdentifiabilityReport AnalyzeIdentifiability(const KinematicModel& model,
                                             const std::vector<Eigen::VectorXd>& qs,
                                             const Eigen::VectorXd& x, MeasurementKind kind,
                                             const IdentifiabilitySettings& settings) {
  return AnalyzeJacobian(model, StackedJacobian(model, qs, x, kind), settings);
}

IdentifiabilityReport AnalyzeIdentifiability(const KinematicModel& model,
                                             const std::vector<PoseMeasurement>& ms,
                                             const Eigen::VectorXd& x,
                                             const IdentifiabilitySettings& settings) {
  return AnalyzeJacobian(model, StackedJacobian(model, ms, x), settings);
}

IdentifiabilityReport AnalyzeJacobian(const KinematicModel& model, const Eigen::MatrixXd& J,
                                      const IdentifiabilitySettings& settings) {
  const int n = model.num_params();
  if (J.cols() != n)
    throw std::invalid_argument("AnalyzeJacobian: J has " + std::to_string(J.cols()) +
                                " columns, model '" + model.name() + "' has " + std::to_string(n) +
                                " parameters");
  IdentifiabilityReport report;
  report.num_params = n;
  report.num_equations = static_cast<int>(J.rows());

  // Column scaling. A column at round-off level is a parameter nothing sees: it stays zero rather
  // than being scaled up into a unit column of noise.
  Eigen::VectorXd d(n);
  double max_norm = 0;
  for (int i = 0; i < n; ++i) max_norm = std::max(max_norm, J.col(i).norm());
  Eigen::MatrixXd Js = J;
  for (int i = 0; i < n; ++i) {
    const double norm = J.col(i).norm();
    const bool seen = norm > 1e-12 * max_norm;
    d(i) = seen ? 1.0 / norm : 1.0;
    Js.col(i) = seen ? Eigen::VectorXd(J.col(i) * d(i)) : Eigen::VectorXd::Zero(J.rows());
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeFullV);
  report.singular_values = svd.singularValues();
  const double smax = report.singular_values.size() ? report.singular_values(0) : 0.0;
  int rank = 0;
  for (int i = 0; i < report.singular_values.size(); ++i)
    if (report.singular_values(i) > settings.rank_tolerance * smax) ++rank;
  report.rank = rank;

  // Null space in unscaled parameter units, reduced to row-echelon form with pivots taken from
  // the last parameter backwards.
  const int k = n - rank;
  Eigen::MatrixXd N = (d.asDiagonal() * svd.matrixV().rightCols(k)).transpose();  // k × n
  // A pivot is judged against the rows not yet reduced: the reduced rows are scaled to a unit
  // pivot and can hold entries far larger than the rest, so a threshold over the whole matrix
  // skipped real pivots (a UR-like 6R arm at a fitted point: 3 pivots for 18 null directions,
  // 42 "identifiable" parameters at rank 27).
  // A parameter is also dropped only when it takes a real part in its direction: its entry, in
  // scaled units (comparable across m and rad), at least `pivot_share` of the largest entry the
  // remaining rows have among the parameters not yet passed. Dropping one with a tiny entry
  // removes the direction in exact arithmetic, but leaves the kept columns nearly dependent (their
  // smallest scaled singular value about that entry): on the UR10 URDF with positions only, chosen
  // at a fitted point, 1e-5–1e-7 where the rank's own is 0.3, and LM crept along that direction
  // for 100 iterations, 30 χ² units above the optimum.
  // Elimination order: the arm's parameters from the last backwards, then the set-up frames'
  // (also from the last). So where a set-up frame and the arm explain the same motion (a marker's
  // offset along the last joint's axis and that joint's placement along it; the base's z and
  // d1), the arm keeps its drawing and the mounting takes the difference: the calibrated robot
  // file then moves no frame of the arm by a marker's offset.
  std::vector<int> order;
  for (int pass = 0; pass < 2; ++pass)
    for (int col = n - 1; col >= 0; --col)
      if (IsSetupGroup(model.parameters()[col].group) == (pass == 1)) order.push_back(col);
  std::vector<int> pivots;
  std::vector<bool> passed(n, false);
  const auto scaled = [&](int r, int c) { return std::abs(N(r, c)) / d(c); };
  int row = 0;
  for (int col : order) {
    if (row >= k) break;
    int best = row;
    for (int r = row + 1; r < k; ++r)
      if (std::abs(N(r, col)) > std::abs(N(best, col))) best = r;
    const double remaining = N.bottomRows(k - row).cwiseAbs().maxCoeff();
    double eligible = 0;
    for (int r = row; r < k; ++r)
      for (int c = 0; c < n; ++c)
        if (!passed[c]) eligible = std::max(eligible, scaled(r, c));
    passed[col] = true;
    if (std::abs(N(best, col)) < settings.coefficient_zero * remaining ||
        scaled(best, col) < settings.pivot_share * eligible)
      continue;
    N.row(row).swap(N.row(best));
    N.row(row) /= N(row, col);
    for (int r = 0; r < k; ++r)
      if (r != row) N.row(r) -= N(r, col) * N.row(row);
    pivots.push_back(col);
    ++row;
  }
  for (int r = 0; r < static_cast<int>(pivots.size()); ++r) {
    UnidentifiableCombination c;
    c.dropped = pivots[r];
    c.params.push_back(pivots[r]);
    c.direction.push_back(1.0);
    for (int col : order) {
      if (col == pivots[r]) continue;
      if (std::abs(N(r, col)) > settings.coefficient_zero) {
        c.params.push_back(col);
        c.direction.push_back(N(r, col));
      }
    }
    c.explanation = Explain(model, c.params, c.direction);
    report.unidentifiable.push_back(std::move(c));
  }
  for (int i = 0; i < n; ++i)
    if (std::find(pivots.begin(), pivots.end(), i) == pivots.end())
      report.identifiable.push_back(i);

  // Condition number of the base parameter columns.
  Eigen::MatrixXd Jb(Js.rows(), report.identifiable.size());
  for (size_t i = 0; i < report.identifiable.size(); ++i)
    Jb.col(i) = Js.col(report.identifiable[i]);
  if (Jb.cols() > 0) {
    const Eigen::VectorXd s = Eigen::JacobiSVD<Eigen::MatrixXd>(Jb).singularValues();
    report.condition_number =
        s(s.size() - 1) > 0 ? s(0) / s(s.size() - 1) : std::numeric_limits<double>::infinity();
  }
  return report;
}

}  // namespace rcal::kinematics
