#include "rcal/identification/setup_guess.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::identification {
namespace {

using kinematics::KinematicModel;
using kinematics::PoseMeasurement;

// Rotation nearest to M = U Σ Vᵀ with det +1 (the reflection guard of Kabsch): U D Vᵀ.
Eigen::Matrix3d ProperRotation(const Eigen::Matrix3d& U, const Eigen::Matrix3d& V) {
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (U * V.transpose()).determinant() < 0 ? -1.0 : 1.0;
  return U * D * V.transpose();
}

// p_FM of marker `slot` at errors x [m].
Eigen::Vector3d MarkerOffset(const KinematicModel& model, int slot, const Eigen::VectorXd& x) {
  if (model.markers().empty()) return Eigen::Vector3d::Zero();
  const kinematics::Marker& m = model.markers()[slot];
  Eigen::Vector3d p = m.nominal;
  for (int a = 0; a < 3; ++a)
    if (m.param[a] >= 0) p(a) += x(m.param[a]);
  return p;
}

// The world ← base frame: the chain's first six ETs (ModelBuilder::BaseFrame) at errors x.
Eigen::Isometry3d BaseTransform(const KinematicModel& model, const Eigen::VectorXd& x) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const auto& ets = model.ets(kinematics::Segment::kChain);
  for (int k = 0; k < 6 && k < static_cast<int>(ets.size()); ++k)
    T = T * kinematics::EtTransform(ets[k],
                                    ets[k].nominal + (ets[k].param >= 0 ? x(ets[k].param) : 0.0));
  return T;
}

// The position problem: per pose the drawing's flange in the base frame and the measured point.
struct Points {
  std::vector<Eigen::Isometry3d> T_BF;
  std::vector<int> slot;
  std::vector<Eigen::Vector3d> b;  // measured p_WM_W
};

struct Registration {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // R_WB
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // t_WB
  std::vector<Eigen::Vector3d> p;                   // p_FM per slot
  int iterations = 0;

  Eigen::Vector3d Predict(const Points& pts, int i) const {
    return R * (pts.T_BF[i] * p[pts.slot[i]]) + t;
  }
  double Residual(const Points& pts, int i) const { return (Predict(pts, i) - pts.b[i]).norm(); }
};

// Alternating Kabsch / linear least squares over the poses `use` (file comment), from `start`.
// `solve_base`: the model has a world ← base frame; `free[k]`: marker k's offset is identified.
Registration Register(const Points& pts, const std::vector<int>& use, Registration reg,
                      bool solve_base, const std::vector<bool>& free,
                      const std::vector<Eigen::Vector3d>& nominal, const SetupGuessSettings& s) {
  const int slots = static_cast<int>(reg.p.size());
  std::vector<int> column(slots, -1);  // first unknown of each free slot
  int n = solve_base ? 3 : 0;
  for (int k = 0; k < slots; ++k)
    if (free[k]) {
      column[k] = n;
      n += 3;
    }
  for (reg.iterations = 0; reg.iterations < s.max_iterations; ++reg.iterations) {
    const Registration before = reg;
    if (solve_base) {
      std::vector<Eigen::Vector3d> a, b;
      for (int i : use) {
        a.push_back(pts.T_BF[i] * reg.p[pts.slot[i]]);
        b.push_back(pts.b[i]);
      }
      try {
        const Eigen::Isometry3d T = FitRigidTransform(a, b);
        reg.R = T.linear();
        reg.t = T.translation();
      } catch (const std::invalid_argument&) {
        // Collinear points: the rotation is not fixed by them; keep the last one.
      }
    }
    if (n == 0) break;
    Eigen::MatrixXd AtA = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd Aty = Eigen::VectorXd::Zero(n);
    for (int i : use) {
      const int k = pts.slot[i];
      Eigen::Vector3d y = pts.b[i] - reg.R * pts.T_BF[i].translation();
      Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3, n);
      if (solve_base)
        A.leftCols<3>().setIdentity();
      else
        y -= reg.t;
      const Eigen::Matrix3d RR = reg.R * pts.T_BF[i].linear();
      if (free[k]) {
        A.middleCols<3>(column[k]) = RR;
        y -= RR * nominal[k];  // unknowns: the offset's departure from its nominal
      } else {
        y -= RR * reg.p[k];
      }
      AtA += A.transpose() * A;
      Aty += A.transpose() * y;
    }
    // Minimum-norm solution: an offset the poses do not see (the flange hardly turns) stays at
    // its nominal instead of running off.
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(AtA);
    cod.setThreshold(s.rank_threshold);
    const Eigen::VectorXd u = cod.solve(Aty);
    if (solve_base) reg.t = u.head<3>();
    for (int k = 0; k < slots; ++k)
      if (free[k]) reg.p[k] = nominal[k] + u.segment<3>(column[k]);
    double change = (reg.t - before.t).norm();
    change = std::max(change, geometry::Log(reg.R * before.R.transpose()).norm());
    for (int k = 0; k < slots; ++k) change = std::max(change, (reg.p[k] - before.p[k]).norm());
    if (change < s.tolerance) break;
  }
  return reg;
}

// R_meas,i = Y · A_i · X over `use` (file comment); `earth`: solve Y too, else Y = Y0.
std::pair<Eigen::Matrix3d, Eigen::Matrix3d> HandEye(const std::vector<Eigen::Matrix3d>& A,
                                                    const std::vector<Eigen::Matrix3d>& M,
                                                    const std::vector<int>& use, bool earth,
                                                    const Eigen::Matrix3d& Y0) {
  Eigen::Matrix3d Y = Y0;
  if (earth && use.size() >= 3) {
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    for (size_t k = 0; k < use.size(); ++k)
      for (size_t l = k + 1; l < use.size(); ++l)
        H += geometry::Log(A[use[k]] * A[use[l]].transpose()) *
             geometry::Log(M[use[k]] * M[use[l]].transpose()).transpose();
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Y = ProperRotation(svd.matrixV(), svd.matrixU());
  }
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (int i : use) sum += A[i].transpose() * Y.transpose() * M[i];
  return {Y, geometry::Orthonormalize(sum)};
}

// Leaves out the worst pose while its residual against the others' fit exceeds `ratio` times
// their median (and a numerical floor): `fit(use)` refits, `residual(i)` judges pose i against
// the last fit. Returns the poses kept.
template <class Fit, class Residual>
std::vector<int> DropOutliers(std::vector<int> use, int max_out, double ratio, double floor,
                              std::vector<int>& outliers, Fit fit, Residual residual) {
  fit(use);
  while (static_cast<int>(outliers.size()) < max_out && use.size() > 3) {
    int worst = use.front();
    for (int i : use)
      if (residual(i) > residual(worst)) worst = i;
    std::vector<int> others;
    for (int i : use)
      if (i != worst) others.push_back(i);
    fit(others);
    std::vector<double> r;
    for (int i : others) r.push_back(residual(i));
    if (residual(worst) > ratio * std::max(numeric::UpperMedian(r), floor)) {
      outliers.push_back(worst);
      use = others;
      continue;
    }
    fit(use);
    break;
  }
  return use;
}

int IndexOf(const KinematicModel& model, const char* name) {
  return model.FindParameter(name);
}

}  // namespace

SetupGuess GuessSetup(const KinematicModel& model, const std::vector<PoseMeasurement>& ms,
                      const SetupGuessSettings& s, const Eigen::VectorXd& x0) {
  SetupGuess out;
  out.x = x0.size() == model.num_params() ? x0 : model.Nominal();
  if (x0.size() != 0 && x0.size() != model.num_params())
    throw std::invalid_argument("GuessSetup: x0 has " + std::to_string(x0.size()) +
                                " values, model '" + model.name() + "' has " +
                                std::to_string(model.num_params()));
  const int n = static_cast<int>(ms.size());
  const int max_out = s.max_outliers >= 0 ? s.max_outliers : n / 4;
  std::vector<int> all(n);
  for (int i = 0; i < n; ++i) all[i] = i;

  // --- Positions: world ← base and the marker offsets.
  const char* base_names[6] = {"base_x", "base_y", "base_z", "base_rz", "base_ry", "base_rx"};
  int base[6];
  bool has_base = true;
  for (int k = 0; k < 6; ++k) has_base &= (base[k] = IndexOf(model, base_names[k])) >= 0;
  const int slots = std::max<int>(1, static_cast<int>(model.markers().size()));
  std::vector<bool> free(slots, false);
  std::vector<Eigen::Vector3d> nominal(slots);
  for (int k = 0; k < slots; ++k) {
    nominal[k] = MarkerOffset(model, k, out.x);
    if (!model.markers().empty())
      for (int a = 0; a < 3; ++a) free[k] = free[k] || model.markers()[k].param[a] >= 0;
  }
  // Markers no pose measures stay where they are.
  std::vector<int> seen(slots, 0);
  for (const auto& m : ms) ++seen.at(m.marker);
  for (int k = 0; k < slots; ++k) free[k] = free[k] && seen[k] > 0;
  const bool any_free = std::find(free.begin(), free.end(), true) != free.end();
  std::vector<int> kept = all;
  if (n >= 3 && (has_base || any_free)) {
    Points pts;
    const Eigen::Isometry3d T_WB0 = BaseTransform(model, out.x);
    for (const auto& m : ms) {
      Eigen::Isometry3d T_WM = model.ForMarker(m.marker).ToolFrame(m.q, out.x);
      T_WM.translation() -= T_WM.linear() * MarkerOffset(model, m.marker, out.x);
      pts.T_BF.push_back(has_base ? T_WB0.inverse() * T_WM : T_WM);
      pts.slot.push_back(m.marker);
      pts.b.push_back(m.p_WM_W);
    }
    Registration reg;
    reg.p = nominal;
    if (!has_base) {  // positions are in the chain's first frame already
      reg.R = Eigen::Matrix3d::Identity();
      reg.t = Eigen::Vector3d::Zero();
    }
    Registration start = reg;
    const auto fit = [&](const std::vector<int>& use) {
      reg = Register(pts, use, start, has_base, free, nominal, s);
    };
    kept = DropOutliers(all, max_out, s.outlier_ratio, 1e-9, out.outliers, fit,
                        [&](int i) { return reg.Residual(pts, i); });
    out.iterations = reg.iterations;
    if (has_base) {
      const Eigen::Vector3d rpy = geometry::ToRpy(reg.R);
      const double value[6] = {reg.t.x(), reg.t.y(), reg.t.z(), rpy(2), rpy(1), rpy(0)};
      const auto& ets = model.ets(kinematics::Segment::kChain);
      for (int k = 0; k < 6; ++k) out.x(base[k]) = value[k] - ets[k].nominal;
    }
    for (int k = 0; k < slots; ++k)
      if (free[k])
        for (int a = 0; a < 3; ++a)
          if (const int p = model.markers()[k].param[a]; p >= 0)
            out.x(p) = reg.p[k](a) - model.markers()[k].nominal(a);
  }

  // --- Orientations: flange → IMU and earth ← world.
  const auto find3 = [&](const char* a, const char* b, const char* c, int* idx) {
    idx[0] = IndexOf(model, a);
    idx[1] = IndexOf(model, b);
    idx[2] = IndexOf(model, c);
    return idx[0] >= 0 && idx[1] >= 0 && idx[2] >= 0;
  };
  int imu[3], earth[3];
  const bool has_imu = find3("imu_rz", "imu_ry", "imu_rx", imu);
  const bool has_earth = find3("earth_rz", "earth_ry", "earth_rx", earth);
  std::vector<int> with;
  for (int i : kept)
    if (ms[i].has_orientation) with.push_back(i);
  if (has_imu && !with.empty()) {
    // The Rz·Ry·Rx ETs of a segment hold rpy = nominal + x; a correction is composed on the side
    // where the segment meets the chain.
    const auto nominal_rotation = [&](kinematics::Segment seg) {
      Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
      for (const auto& et : model.ets(seg))
        R = R * kinematics::EtTransform(et, et.nominal).linear();
      return R;
    };
    const auto set_rpy = [&](const int* idx, const Eigen::Matrix3d& R, const Eigen::Matrix3d& R0) {
      const Eigen::Vector3d rpy = geometry::ToRpy(R), rpy0 = geometry::ToRpy(R0);
      out.x(idx[0]) = rpy(2) - rpy0(2);
      out.x(idx[1]) = rpy(1) - rpy0(1);
      out.x(idx[2]) = rpy(0) - rpy0(0);
    };
    const Eigen::Matrix3d R_EW0 = nominal_rotation(kinematics::Segment::kEarth);
    const Eigen::Matrix3d R_FI0 = nominal_rotation(kinematics::Segment::kImu);
    Eigen::VectorXd x_a = out.x;  // the drawing's orientation A_i at the guessed base
    if (has_earth)
      for (int k = 0; k < 3; ++k) x_a(earth[k]) = 0.0;
    for (int k = 0; k < 3; ++k) x_a(imu[k]) = 0.0;
    std::vector<Eigen::Matrix3d> A(n), M(n);
    for (int i : with) {
      A[i] = R_EW0.transpose() * model.Forward(ms[i].q, x_a).R_EI * R_FI0.transpose();
      M[i] = ms[i].R_EI;
    }
    Eigen::Matrix3d Y = R_EW0, X = R_FI0;
    const auto fit = [&](const std::vector<int>& use) {
      std::tie(Y, X) = HandEye(A, M, use, has_earth, R_EW0);
    };
    const auto angle = [&](int i) { return geometry::AngleBetween(M[i], Y * A[i] * X); };
    std::vector<int> dropped;
    const int room = std::max(0, max_out - static_cast<int>(out.outliers.size()));
    const std::vector<int> use =
        DropOutliers(with, room, s.outlier_ratio, 1e-9, dropped, fit, angle);
    for (int i : dropped) {
      out.outliers.push_back(i);
      kept.erase(std::remove(kept.begin(), kept.end(), i), kept.end());
    }
    (void)use;
    if (has_earth && with.size() >= 3) set_rpy(earth, Y, R_EW0);
    set_rpy(imu, X, R_FI0);
  }
  std::sort(out.outliers.begin(), out.outliers.end());

  // --- What the kept poses identify of the set-up, and how well.
  std::vector<PoseMeasurement> kept_ms;
  for (int i : kept) {
    kept_ms.push_back(ms[i]);
    kept_ms.back().covariance = Eigen::MatrixXd::Identity(ms[i].dimension(), ms[i].dimension());
  }
  if (kept_ms.empty()) return out;
  out.setup = IdentifiableSubset(model, kept_ms, out.x, SetupParameters(model));
  double ss_p = 0, ss_o = 0;
  int n_p = 0, n_o = 0, k_p = 0, k_o = 0;
  for (const auto& m : kept_ms) {
    const Eigen::VectorXd r = kinematics::Residual(model, m, out.x);
    ss_p += r.head<3>().squaredNorm();
    n_p += 3;
    if (m.has_orientation) {
      ss_o += r.tail<3>().squaredNorm();
      n_o += 3;
    }
  }
  for (int i : out.setup) {
    const std::string& g = model.parameters()[i].group;
    (g == "imu" || g == "earth" ? k_o : k_p) += 1;
  }
  out.rms_position_m = std::sqrt(ss_p / kept_ms.size());
  const int with_o = n_o / 3;
  out.rms_orientation_rad = with_o > 0 ? std::sqrt(ss_o / with_o) : 0.0;
  // Each block's variance per coordinate from its residuals (a floor for exact data).
  const double var_p = std::max(ss_p / std::max(1, n_p - k_p), 1e-24);
  const double var_o = std::max(ss_o / std::max(1, n_o - k_o), 1e-24);
  const int k = static_cast<int>(out.setup.size());
  Eigen::MatrixXd info = Eigen::MatrixXd::Zero(k, k);
  Eigen::VectorXd r;
  Eigen::MatrixXd H;
  for (const auto& m : kept_ms) {
    kinematics::ResidualAndJacobian(model, m, out.x, out.setup, r, H);
    Eigen::VectorXd w = Eigen::VectorXd::Constant(m.dimension(), 1.0 / var_p);
    if (m.has_orientation) w.tail<3>().setConstant(1.0 / var_o);
    info += H.transpose() * w.asDiagonal() * H;
  }
  out.covariance = info.ldlt().solve(Eigen::MatrixXd::Identity(k, k));
  return out;
}

Eigen::VectorXd GenericSetupPlacement(const KinematicModel& model, const Eigen::VectorXd& x0,
                                      unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd x = x0;
  for (int i : SetupParameters(model))
    x(i) += n(rng) * (model.parameters()[i].group == "marker" ? 0.05 : 1e-3);
  return x;
}

}  // namespace rcal::identification
