// Batch identification, rcal vs Ceres (automatic derivatives), on the same problem and to the
// same cost: the GRB3016 of the paper (Table 1, standard D–H) with its 4-parameter D–H tool,
// Table 3 as the true errors, 50 simulated full-pose measurements with the default sensor noise
// (0.05 mm, 0.1°), and the identifiable (base) parameter set of that pose set (25 of 28).
//
//   minimise  Σₖ |Lₖ⁻¹ rₖ(x)|²,   rₖ = [ p_meas − p(qₖ, x) ;  Log(R_meas · R(qₖ, x)ᵀ) ]
//
// (Lₖ the Cholesky factor of the measurement covariance; residual convention of
// rcal/kinematics/measurement.hpp). rcal: identification::BatchLm (analytic Jacobian). Ceres: one
// AutoDiffCostFunction<6, 25> per pose over a templated, ET-by-ET forward model written here,
// Levenberg–Marquardt with dense normal Cholesky, one thread. Both start from the nominal model.
// The setup checks that both reach the same cost (relative 1e-8) and aborts otherwise.
//
// Default run: 5 repetitions, medians, then a table (ms per solve, ratio Ceres / rcal).
#include <benchmark/benchmark.h>
#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/checkpoint_json.hpp"

namespace {

using rcal::kinematics::ElementaryTransform;
using rcal::kinematics::KinematicModel;
using rcal::kinematics::PoseMeasurement;
constexpr double kPi = std::numbers::pi;
constexpr int kIdentified = 25;  // base parameters of this pose set (checked in the setup)
constexpr int kPoses = 50;

[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "bench_identification setup check failed: %s\n", what.c_str());
  std::abort();
}

template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;

/// R_u(v) for a unit axis u: I + sin v [u]× + (1 − cos v) [u]×².
template <typename T>
Mat3<T> AxisRotation(const Eigen::Vector3d& u, const T& v) {
  using std::cos;
  using std::sin;
  Eigen::Matrix3d K;
  K << 0.0, -u.z(), u.y(), u.z(), 0.0, -u.x(), -u.y(), u.x(), 0.0;
  const Eigen::Matrix3d K2 = K * K;
  const T s = sin(v), c = cos(v);
  Mat3<T> R;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      R(i, j) = T(i == j ? 1.0 : 0.0) + s * K(i, j) + (T(1.0) - c) * K2(i, j);
  return R;
}

/// One pose's whitened residual, templated for Ceres' automatic derivatives.
struct PoseResidual {
  const KinematicModel* model;
  const PoseMeasurement* m;
  std::vector<int> slot;  // model parameter index → position in the identified block, or −1
  Eigen::Matrix<double, 6, 6> L_inv;

  template <typename T>
  T Value(const ElementaryTransform& et, const T* dx) const {
    T v(et.nominal);
    if (et.param >= 0 && slot[et.param] >= 0) v += dx[slot[et.param]];
    if (et.joint >= 0) v += T(m->q(et.joint));
    return v;
  }

  template <typename T>
  Mat3<T> Rotations(rcal::kinematics::Segment s, const T* dx) const {
    Mat3<T> R = Mat3<T>::Identity();
    for (const auto& et : model->ets(s)) R = R * AxisRotation(et.axis, Value(et, dx));
    return R;
  }

  template <typename T>
  bool operator()(const T* const dx, T* residual) const {
    using Seg = rcal::kinematics::Segment;
    Mat3<T> R = Mat3<T>::Identity();
    Vec3<T> p = Vec3<T>::Zero();
    for (const auto& et : model->ets(Seg::kChain)) {
      const T v = Value(et, dx);
      if (et.kind == ElementaryTransform::Kind::kTranslation) {
        p += R * (et.axis.cast<T>() * v);
      } else {
        R = R * AxisRotation(et.axis, v);
      }
    }
    Eigen::Matrix<T, 6, 1> r;
    r.template head<3>() = m->p_WM_W.cast<T>() - p;
    const Mat3<T> R_EI = Rotations<T>(Seg::kEarth, dx) * R * Rotations<T>(Seg::kImu, dx);
    const Mat3<T> E = m->R_EI.cast<T>() * R_EI.transpose();  // column-major, as Ceres wants
    T aa[3];
    ceres::RotationMatrixToAngleAxis(E.data(), aa);
    r(3) = aa[0];
    r(4) = aa[1];
    r(5) = aa[2];
    const Eigen::Matrix<T, 6, 1> r_w = L_inv.cast<T>() * r;
    for (int i = 0; i < 6; ++i) residual[i] = r_w(i);
    return true;
  }
};

struct Setup {
  KinematicModel model;
  Eigen::VectorXd x_true;
  std::vector<int> identified;
  std::vector<PoseMeasurement> measurements;
  double rcal_cost = 0, ceres_cost = 0;
  int rcal_iterations = 0, ceres_iterations = 0;
};

ceres::Solver::Options CeresOptions() {
  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  o.num_threads = 1;
  o.max_num_iterations = 100;
  o.function_tolerance = 1e-14;  // as BatchLm's relative_cost_tolerance
  o.parameter_tolerance = 1e-13;
  o.gradient_tolerance = 1e-16;
  o.logging_type = ceres::SILENT;
  o.minimizer_progress_to_stdout = false;
  return o;
}

/// Builds the Ceres problem (part of what is timed, as BatchLm::Solve does its own setup) and
/// solves from the nominal model. Returns the cost in BatchLm's scale (Ceres reports ½Σ|r|²).
double SolveCeres(const Setup& s, std::vector<double>& dx, int* iterations = nullptr) {
  dx.assign(kIdentified, 0.0);
  std::vector<int> slot(s.model.num_params(), -1);
  for (int i = 0; i < kIdentified; ++i) slot[s.identified[i]] = i;
  ceres::Problem problem;
  for (const PoseMeasurement& m : s.measurements) {
    auto* f = new PoseResidual{&s.model, &m, slot, {}};
    f->L_inv = m.covariance.llt().matrixL().solve(Eigen::Matrix<double, 6, 6>::Identity());
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PoseResidual, 6, kIdentified>(f),
                             nullptr, dx.data());
  }
  ceres::Solver::Summary summary;
  ceres::Solve(CeresOptions(), &problem, &summary);
  if (iterations) *iterations = static_cast<int>(summary.iterations.size());
  return 2.0 * summary.final_cost;
}

Setup& S() {
  static Setup s = [] {
    Setup s;
    rcal::kinematics::ModelBuilder b("grb3016");
    const auto j = [](int i) {
      rcal::kinematics::Joint joint;
      joint.name = std::string(1, 'j') + static_cast<char>('0' + i);  // GCC 12 -Wrestrict: no "j"+
      joint.lower = -kPi;
      joint.upper = kPi;
      return joint;
    };
    b.DhLink(0.150, -kPi / 2, 0.250, 0.0, j(1))
        .DhLink(0.570, -kPi, 0.0, -kPi / 2, j(2))
        .DhLink(0.150, kPi / 2, 0.0, 0.0, j(3))
        .DhLink(0.0, -kPi / 2, 0.645, 0.0, j(4))
        .DhLink(0.0, kPi / 2, 0.0, -kPi / 2, j(5))
        .DhLink(0.0, 0.0, -0.200, 0.0, j(6))
        .ToolDh(0.010, 0.1, 0.050, 0.2);
    s.model = b.Build();
    s.x_true = rcal::sim::Table3Errors(s.model);
    rcal::sim::Rng rng(50);
    const auto qs = rcal::sim::SampleJoints(s.model, kPoses, rng);
    s.measurements = rcal::sim::MeasurePoses(s.model, s.x_true, qs, {}, rng);
    s.identified = rcal::kinematics::AnalyzeIdentifiability(
                       s.model, qs, s.model.Nominal(), rcal::kinematics::MeasurementKind::kFullPose)
                       .identifiable;
    if (static_cast<int>(s.identified.size()) != kIdentified)
      Fail("expected 25 identifiable parameters, got " + std::to_string(s.identified.size()));

    const auto lm = rcal::identification::BatchLm(s.model, s.identified)
                        .Solve(s.measurements, s.model.Nominal());
    s.rcal_cost = lm.cost;
    s.rcal_iterations = lm.iterations;
    std::vector<double> dx;
    s.ceres_cost = SolveCeres(s, dx, &s.ceres_iterations);
    const double rel = std::abs(s.ceres_cost - s.rcal_cost) / s.rcal_cost;
    if (!(rel < 1e-8))
      Fail("costs differ: rcal " + std::to_string(s.rcal_cost) + ", Ceres " +
           std::to_string(s.ceres_cost));
    double dmax = 0;
    for (int i = 0; i < kIdentified; ++i)
      dmax = std::max(dmax, std::abs(dx[i] - lm.x(s.identified[i])));
    if (dmax > 1e-7) Fail("solutions differ by " + std::to_string(dmax));
    return s;
  }();
  return s;
}

void BatchRcal(benchmark::State& state) {
  const Setup& s = S();
  const rcal::identification::BatchLm lm(s.model, s.identified);
  for (auto _ : state) {
    auto res = lm.Solve(s.measurements, s.model.Nominal());
    benchmark::DoNotOptimize(res.cost);
  }
  state.counters["iterations"] = s.rcal_iterations;
}

void BatchCeres(benchmark::State& state) {
  const Setup& s = S();
  std::vector<double> dx;
  for (auto _ : state) {
    const double cost = SolveCeres(s, dx);
    benchmark::DoNotOptimize(cost);
  }
  state.counters["iterations"] = s.ceres_iterations;
}

// One EKF update on a filter that has seen 49 poses (the steady state of an online run: the
// relinearisation passes have stopped firing), and the same update with the plain EKF settings
// (one linearisation, no passes) for scale.
void EkfUpdate(benchmark::State& state, int iterations) {
  const Setup& s = S();
  rcal::identification::EkfSettings settings;
  settings.max_iterations = iterations;
  rcal::identification::EkfIdentifier warm(s.model, s.identified, settings);
  for (int k = 0; k + 1 < kPoses; ++k) warm.Update(s.measurements[k]);
  const auto checkpoint = warm.Checkpoint();
  rcal::identification::EkfIdentifier ekf(s.model, s.identified, settings);
  for (auto _ : state) {
    state.PauseTiming();
    ekf.Restore(checkpoint);
    state.ResumeTiming();
    const auto r = ekf.Update(s.measurements[kPoses - 1]);
    benchmark::DoNotOptimize(r.nis);
  }
  state.counters["relinearization_passes"] = ekf.relinearizations() - checkpoint.relinearizations;
}

// An identifier that has seen `age` poses (default settings: the window of 100 and change
// detection; or the former filter: every pose kept, no detection), then one more pose: the update
// and the checkpoint text the ekf_identifier process writes after it (issue 15: 0.6 ms per pose at
// 30 poses, 28 ms at 2 100 before the window). Counters: the checkpoint's size and poses.
struct Aged {
  rcal::identification::EkfCheckpoint checkpoint;
  PoseMeasurement next;
};
const Aged& AgedFilter(long age, bool former) {
  static std::map<std::pair<long, bool>, Aged> cache;
  auto it = cache.find({age, former});
  if (it != cache.end()) return it->second;
  const Setup& s = S();
  rcal::identification::EkfSettings settings;
  if (former) {
    settings.window_poses = 0;
    settings.detect_changes = false;
  }
  rcal::identification::EkfIdentifier ekf(s.model, s.identified, settings);
  rcal::sim::Rng rng(60);
  for (long k = 0; k < age; ++k)
    ekf.Update(rcal::sim::MeasurePose(s.model, s.x_true,
                                      rcal::sim::SampleJoints(s.model, 1, rng)[0], {}, rng));
  Aged a{ekf.Checkpoint(),
         rcal::sim::MeasurePose(s.model, s.x_true, rcal::sim::SampleJoints(s.model, 1, rng)[0], {},
                                rng)};
  return cache.emplace(std::make_pair(age, former), std::move(a)).first->second;
}

void EkfAged(benchmark::State& state, long age, bool former) {
  const Setup& s = S();
  const Aged& a = AgedFilter(age, former);
  rcal::identification::EkfSettings settings;
  if (former) {
    settings.window_poses = 0;
    settings.detect_changes = false;
  }
  rcal::identification::EkfIdentifier ekf(s.model, s.identified, settings);
  size_t bytes = 0;
  for (auto _ : state) {
    state.PauseTiming();
    ekf.Restore(a.checkpoint);
    state.ResumeTiming();
    const auto r = ekf.Update(a.next);
    const std::string text =
        rcal::transport::CheckpointText({"bench", 0, 0, ekf.Checkpoint(), {}, {}});
    benchmark::DoNotOptimize(r.nis);
    bytes = text.size();
  }
  const size_t poses = ekf.Checkpoint().history.size();
  state.counters["checkpoint_kB"] = bytes / 1e3;
  state.counters["checkpoint_poses"] = static_cast<double>(poses);
}

}  // namespace

int main(int argc, char** argv) {
  if (!rcal::bench::InitializeWithMedians(argc, argv)) return 1;

  S();
  benchmark::RegisterBenchmark("batch50/rcal", BatchRcal)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("batch50/ceres", BatchCeres)->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("ekf_update/iterated", EkfUpdate, 10)->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("ekf_update/plain", EkfUpdate, 1)->Unit(benchmark::kMicrosecond);
  const long ages[] = {100, 1000, 10000, 100000};
  for (long age : ages)
    benchmark::RegisterBenchmark(("ekf_aged/window/" + std::to_string(age)).c_str(), EkfAged, age,
                                 false)
        ->Unit(benchmark::kMillisecond);
  for (long age : {100L, 1000L, 10000L})
    benchmark::RegisterBenchmark(("ekf_aged/former/" + std::to_string(age)).c_str(), EkfAged, age,
                                 true)
        ->Unit(benchmark::kMillisecond);
  rcal::bench::TableReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();

  const double r = reporter.Ns("batch50/rcal"), c = reporter.Ns("batch50/ceres");
  std::printf("\nGRB3016 + D–H tool, %d full poses, %d base parameters; %s real time per solve.\n",
              kPoses, kIdentified, reporter.has_medians() ? "median" : "single-run");
  std::printf("| operation | rcal [ms] | Ceres [ms] | Ceres / rcal |\n|---|---:|---:|---:|\n");
  if (r > 0 && c > 0)
    std::printf(
        "| batch LM, 50 poses (cost rcal %.6g, Ceres %.6g; iterations rcal %d, Ceres %d) | %.3f | "
        "%.3f | %.2fx |\n",
        S().rcal_cost, S().ceres_cost, S().rcal_iterations, S().ceres_iterations, r * 1e-6,
        c * 1e-6, c / r);
  const double e = reporter.Ns("ekf_update/iterated"), p = reporter.Ns("ekf_update/plain");
  if (e > 0 && p > 0)
    std::printf(
        "| one EKF update, 25 parameters, pose 50 of 50: iterated (default) / plain | %.3f "
        "/ %.3f | – | – |\n",
        e * 1e-6, p * 1e-6);
  std::printf(
      "\n| poses seen | update + checkpoint text, window [ms] | former filter [ms] |\n"
      "|---:|---:|---:|\n");
  for (long age : ages) {
    const double w = reporter.Ns("ekf_aged/window/" + std::to_string(age));
    const double f = reporter.Ns("ekf_aged/former/" + std::to_string(age));
    std::printf("| %ld | %.3f | %s |\n", age, w * 1e-6,
                f > 0 ? std::to_string(f * 1e-6).substr(0, 6).c_str() : "–");
  }
  return 0;
}
