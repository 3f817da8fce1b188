// rcal kinematics side by side with Orocos KDL, on the same chain: the GRB3016 of the paper's
// Table 1 (standard D–H) plus its 4-parameter D–H tool, with a fixed set of parameter errors x
// applied (a calibrated model), built for both libraries from one D–H table.
//
//   fk        tool frame T_WT(q):     rcal CompiledChain::ToolFrame  vs KDL
//   ChainFkSolverPos_recursive jacobian  geometric Jacobian:     rcal CompiledChain::JointJacobian
//   vs KDL ChainJntToJacSolver
//             (both: world/base frame, reference point at the tool origin, [v; ω])
//   ik        one pose solve from a seed ±0.3 rad from the generating joints, same tolerance:
//             rcal LevenbergMarquardtIk vs KDL ChainIkSolverPos_LMA
//
// The setup checks that both libraries give the same pose and Jacobian to 1e-12 and that both IK
// solvers reach the tolerance on every benchmarked target, and aborts otherwise. Each benchmark
// cycles through 256 (FK, Jacobian) or 64 (IK) inputs so no single input is measured.
//
// Default run: 5 repetitions, medians reported, then a table of ns per operation and the ratio
// KDL / rcal (higher = rcal faster). Any --benchmark_* flag is passed through.
#include <benchmark/benchmark.h>

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/frames.hpp>
#include <kdl/jacobian.hpp>
#include <kdl/jntarray.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/ik/levenberg_marquardt_ik.hpp"
#include "rcal/kinematics/compiled_chain.hpp"
#include "rcal/kinematics/model.hpp"

namespace {

using rcal::kinematics::KinematicModel;
constexpr double kPi = std::numbers::pi;

struct DhRow {
  double a, alpha, d, theta;  // [m], [rad], [m], [rad]
};

// GRB3016, Table 1 of the paper (as read in ../shared/paper/NOTES.md), then the D–H tool.
constexpr DhRow kLinks[6] = {{0.150, -kPi / 2, 0.250, 0.0}, {0.570, -kPi, 0.0, -kPi / 2},
                             {0.150, kPi / 2, 0.0, 0.0},    {0.0, -kPi / 2, 0.645, 0.0},
                             {0.0, kPi / 2, 0.0, -kPi / 2}, {0.0, 0.0, -0.200, 0.0}};
constexpr DhRow kTool = {0.010, 0.1, 0.050, 0.2};
constexpr int kN = 6;

[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "bench_kinematics setup check failed: %s\n", what.c_str());
  std::abort();
}

struct Setup {
  KinematicModel model;
  Eigen::VectorXd x;  // parameter errors [m | rad]
  rcal::kinematics::CompiledChain chain;
  KDL::Chain kdl_chain;
  std::vector<Eigen::VectorXd> qs;
  std::vector<KDL::JntArray> kdl_qs;
  // IK problems: target (from q_true) and seed, the same for every tolerance.
  std::vector<Eigen::Isometry3d> targets;
  std::vector<KDL::Frame> kdl_targets;
  std::vector<Eigen::VectorXd> seeds;
  std::vector<KDL::JntArray> kdl_seeds;
  struct IkCase {
    double eps = 0;  // |[Δp; Δθ]| tolerance [m, rad]
    double rcal_mean_iterations = 0, kdl_mean_iterations = 0;
    double rcal_worst = 0, kdl_worst = 0;  // worst true |[Δp; Δθ]| at the returned joints
    int kdl_failures = 0;                  // KDL return codes other than E_NOERROR
  };
  std::vector<IkCase> ik_cases;
};

// IK tolerances. KDL's LMA stops when |L·[Δp; Δθ]| < eps with L = 1 (Δθ the rotation vector of
// the pose difference, KDL::diff); rcal's per-part tolerances of eps/√2 imply the same bound, so
// rcal is held to a tolerance at least as strict as KDL's. KDL::Rotation::GetRot returns zero
// for rotations below about 1e-6 rad, so KDL's LMA cannot see orientation errors smaller than
// that: at eps = 1e-6 it is within a few % of the tolerance in truth, at 1e-10 (rcal's default)
// it reports success with orientation errors up to ~1e-6 rad. The table prints both solvers' worst
// true error (from the rcal ET-by-ET model) next to the times, and how often KDL gave up
// (E_INCREMENT_JOINTS_TOO_SMALL: it cannot see the rotation error it is asked to remove).
constexpr double kIkEps[2] = {1e-6, 1e-10};
constexpr int kIkMaxIterations = 500;

std::string Sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3e", v);
  return buf;
}

KDL::JntArray ToKdl(const Eigen::VectorXd& q) {
  KDL::JntArray a(q.size());
  a.data = q;
  return a;
}

Eigen::Isometry3d FromKdl(const KDL::Frame& F) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = F.M(r, c);
    T.translation()(r) = F.p(r);
  }
  return T;
}

rcal::ik::IkSettings RcalIkSettings(double eps) {
  rcal::ik::IkSettings s;
  s.position_tolerance = eps / std::sqrt(2.0);
  s.orientation_tolerance = eps / std::sqrt(2.0);
  s.orientation_weight = 1.0;
  s.max_iterations = kIkMaxIterations;
  s.respect_joint_limits = false;  // KDL's LMA knows no joint limits
  return s;
}

std::unique_ptr<KDL::ChainIkSolverPos_LMA> MakeKdlIk(const KDL::Chain& chain, double eps) {
  Eigen::Matrix<double, 6, 1> L = Eigen::Matrix<double, 6, 1>::Ones();
  return std::make_unique<KDL::ChainIkSolverPos_LMA>(chain, L, eps, kIkMaxIterations, 1e-15);
}

Setup& S() {
  static Setup s = [] {
    Setup s;
    // One parameter error vector, then the D–H table with the errors applied for KDL.
    rcal::kinematics::ModelBuilder b("grb3016");
    for (int i = 0; i < kN; ++i) {
      const DhRow& r = kLinks[i];
      b.DhLink(r.a, r.alpha, r.d, r.theta,
               {"j" + std::to_string(i + 1), rcal::kinematics::JointType::kRevolute, -kPi, kPi});
    }
    b.ToolDh(kTool.a, kTool.alpha, kTool.d, kTool.theta);
    s.model = b.Build();
    std::mt19937 rng(2024);
    std::normal_distribution<double> n(0.0, 1.0);
    s.x.resize(s.model.num_params());
    for (int i = 0; i < s.model.num_params(); ++i)
      s.x(i) = n(rng) * (s.model.parameters()[i].is_angle ? 0.01 : 0.003);
    s.chain = rcal::kinematics::CompiledChain(s.model, s.x);

    auto value = [&](const std::string& name, double nominal) {
      const int p = s.model.FindParameter(name);
      if (p < 0) Fail("no parameter " + name);
      return nominal + s.x(p);
    };
    for (int i = 0; i <= kN; ++i) {
      const bool tool = i == kN;
      const DhRow& r = tool ? kTool : kLinks[i];
      const std::string k = tool ? "tool_" : "", n_ = tool ? "" : std::to_string(i + 1);
      const KDL::Frame F =
          KDL::Frame::DH(value(k + "a" + n_, r.a), value(k + "alpha" + n_, r.alpha),
                         value(k + "d" + n_, r.d), value(k + "theta" + n_, r.theta));
      s.kdl_chain.addSegment(
          KDL::Segment(KDL::Joint(tool ? KDL::Joint::None : KDL::Joint::RotZ), F));
    }

    // FK / Jacobian inputs, checked against each other and against the ET-by-ET model.
    std::uniform_real_distribution<double> u(-kPi, kPi);
    KDL::ChainFkSolverPos_recursive fk(s.kdl_chain);
    KDL::ChainJntToJacSolver jac(s.kdl_chain);
    KDL::Jacobian J_kdl(kN);
    for (int k = 0; k < 256; ++k) {
      Eigen::VectorXd q(kN);
      for (int j = 0; j < kN; ++j) q(j) = u(rng);
      s.qs.push_back(q);
      s.kdl_qs.push_back(ToKdl(q));
      KDL::Frame F;
      if (fk.JntToCart(s.kdl_qs.back(), F) < 0) Fail("KDL FK error");
      const Eigen::Isometry3d T_kdl = FromKdl(F), T_rcal = s.chain.ToolFrame(q),
                              T_model = s.model.ToolFrame(q, s.x);
      const double dT = (T_kdl.matrix() - T_rcal.matrix()).cwiseAbs().maxCoeff();
      const double dM = (T_model.matrix() - T_rcal.matrix()).cwiseAbs().maxCoeff();
      if (dT > 1e-12 || dM > 1e-12)
        Fail("pose mismatch: KDL " + std::to_string(dT) + ", model " + std::to_string(dM));
      if (jac.JntToJac(s.kdl_qs.back(), J_kdl) < 0) Fail("KDL Jacobian error");
      const double dJ = (J_kdl.data - s.chain.JointJacobian(q)).cwiseAbs().maxCoeff();
      if (dJ > 1e-12) Fail("Jacobian mismatch " + std::to_string(dJ));
    }

    // IK problems, away from the wrist singularity (where neither solver is timed fairly).
    std::uniform_real_distribution<double> du(-0.3, 0.3);
    std::uniform_real_distribution<double> uq(-2.5, 2.5);
    while (s.targets.size() < 64) {
      Eigen::VectorXd q_true(kN), seed(kN);
      for (int j = 0; j < kN; ++j) q_true(j) = uq(rng);
      if (std::abs(std::sin(q_true(4) - kPi / 2)) < 0.05) continue;
      for (int j = 0; j < kN; ++j) seed(j) = q_true(j) + du(rng);
      KDL::Frame F;
      fk.JntToCart(ToKdl(q_true), F);
      s.targets.push_back(s.chain.ToolFrame(q_true));
      s.kdl_targets.push_back(F);
      s.seeds.push_back(seed);
      s.kdl_seeds.push_back(ToKdl(seed));
    }
    // Each problem solved by both at each tolerance. rcal must meet it in truth; KDL must report
    // success (its true error is printed: see kIkEps).
    for (const double eps : kIkEps) {
      Setup::IkCase c;
      c.eps = eps;
      rcal::ik::LevenbergMarquardtIk ik(s.model, s.x, RcalIkSettings(eps));
      auto kdl_ik = MakeKdlIk(s.kdl_chain, eps);
      auto true_error = [&](const Eigen::VectorXd& q, const Eigen::Isometry3d& T) {
        const Eigen::Isometry3d T_q = s.model.ToolFrame(q, s.x);
        return std::hypot((T_q.translation() - T.translation()).norm(),
                          rcal::geometry::AngleBetween(T_q.linear(), T.linear()));
      };
      for (size_t k = 0; k < s.targets.size(); ++k) {
        const rcal::ik::IkResult res = ik.Solve(s.targets[k], s.seeds[k]);
        KDL::JntArray q_kdl(kN);
        const int rc = kdl_ik->CartToJnt(s.kdl_seeds[k], s.kdl_targets[k], q_kdl);
        if (!res.converged) Fail("rcal IK did not converge: " + res.reason);
        if (rc != KDL::SolverI::E_NOERROR) ++c.kdl_failures;
        const double e_rcal = true_error(res.q, s.targets[k]);
        const double e_kdl = true_error(q_kdl.data, s.targets[k]);
        if (e_rcal > 1.0001 * eps) Fail("rcal IK missed the tolerance: " + Sci(e_rcal));
        c.rcal_worst = std::max(c.rcal_worst, e_rcal);
        c.kdl_worst = std::max(c.kdl_worst, e_kdl);
        c.rcal_mean_iterations += res.iterations / double(s.targets.size());
        c.kdl_mean_iterations += kdl_ik->lastNrOfIter / double(s.targets.size());
      }
      s.ik_cases.push_back(c);
    }
    return s;
  }();
  return s;
}

void FkRcal(benchmark::State& state) {
  const Setup& s = S();
  size_t i = 0;
  for (auto _ : state) {
    Eigen::Isometry3d T_WT = s.chain.ToolFrame(s.qs[i++ & 255]);
    benchmark::DoNotOptimize(T_WT);
  }
}

void FkRcalModel(benchmark::State& state) {
  const Setup& s = S();
  size_t i = 0;
  for (auto _ : state) {
    Eigen::Isometry3d T_WT = s.model.ToolFrame(s.qs[i++ & 255], s.x);
    benchmark::DoNotOptimize(T_WT);
  }
}

void FkKdl(benchmark::State& state) {
  const Setup& s = S();
  KDL::ChainFkSolverPos_recursive fk(s.kdl_chain);
  KDL::Frame F;
  size_t i = 0;
  for (auto _ : state) {
    fk.JntToCart(s.kdl_qs[i++ & 255], F);
    benchmark::DoNotOptimize(F);
  }
}

void JacobianRcal(benchmark::State& state) {
  const Setup& s = S();
  rcal::kinematics::CompiledChain::Jacobian J(6, kN);
  size_t i = 0;
  for (auto _ : state) {
    s.chain.JointJacobian(s.qs[i++ & 255], J);
    benchmark::DoNotOptimize(J.data());
    benchmark::ClobberMemory();
  }
}

void JacobianRcalModel(benchmark::State& state) {
  const Setup& s = S();
  size_t i = 0;
  for (auto _ : state) {
    Eigen::MatrixXd J = s.model.JointJacobian(s.qs[i++ & 255], s.x);
    benchmark::DoNotOptimize(J.data());
    benchmark::ClobberMemory();
  }
}

void JacobianKdl(benchmark::State& state) {
  const Setup& s = S();
  KDL::ChainJntToJacSolver jac(s.kdl_chain);
  KDL::Jacobian J(kN);
  size_t i = 0;
  for (auto _ : state) {
    jac.JntToJac(s.kdl_qs[i++ & 255], J);
    benchmark::DoNotOptimize(J.data.data());
    benchmark::ClobberMemory();
  }
}

void IkRcal(benchmark::State& state, int which) {
  const Setup& s = S();
  rcal::ik::LevenbergMarquardtIk ik(s.model, s.x, RcalIkSettings(kIkEps[which]));
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ & 63;
    rcal::ik::IkResult res = ik.Solve(s.targets[k], s.seeds[k]);
    benchmark::DoNotOptimize(res);
  }
  state.counters["mean_iterations"] = s.ik_cases[which].rcal_mean_iterations;
}

void IkKdl(benchmark::State& state, int which) {
  const Setup& s = S();
  auto ik = MakeKdlIk(s.kdl_chain, kIkEps[which]);
  KDL::JntArray q(kN);
  size_t i = 0;
  for (auto _ : state) {
    const size_t k = i++ & 63;
    const int rc = ik->CartToJnt(s.kdl_seeds[k], s.kdl_targets[k], q);
    benchmark::DoNotOptimize(rc);
    benchmark::DoNotOptimize(q.data.data());
  }
  state.counters["mean_iterations"] = s.ik_cases[which].kdl_mean_iterations;
}

// Console output as usual, plus the per-benchmark time kept for the summary table: the median
// aggregate when there are repetitions, the single run otherwise.

}  // namespace

int main(int argc, char** argv) {
  if (!rcal::bench::InitializeWithMedians(argc, argv)) return 1;

  S();  // build and check everything before timing
  benchmark::RegisterBenchmark("fk/rcal", FkRcal);
  benchmark::RegisterBenchmark("fk/kdl", FkKdl);
  benchmark::RegisterBenchmark("fk/rcal_et_model", FkRcalModel);
  benchmark::RegisterBenchmark("jacobian/rcal", JacobianRcal);
  benchmark::RegisterBenchmark("jacobian/kdl", JacobianKdl);
  benchmark::RegisterBenchmark("jacobian/rcal_et_model", JacobianRcalModel);
  benchmark::RegisterBenchmark("ik_1e-6/rcal", IkRcal, 0);
  benchmark::RegisterBenchmark("ik_1e-6/kdl", IkKdl, 0);
  benchmark::RegisterBenchmark("ik_1e-10/rcal", IkRcal, 1);
  benchmark::RegisterBenchmark("ik_1e-10/kdl", IkKdl, 1);

  rcal::bench::TableReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();

  std::printf("\nGRB3016 + D–H tool (6R), calibrated parameters; %s real time per operation.\n",
              reporter.has_medians() ? "median" : "single-run");
  std::printf(
      "IK: 64 targets, seeds ±0.3 rad from the generating joints, stop at |[Δp; Δθ]| < "
      "eps [m, rad].\n\n");
  std::printf("| operation | rcal [ns] | KDL [ns] | KDL / rcal |\n");
  std::printf("|---|---:|---:|---:|\n");
  auto row = [&](const std::string& op, const std::string& label) {
    const double r = reporter.Ns(op + "/rcal"), k = reporter.Ns(op + "/kdl");
    if (r > 0 && k > 0) std::printf("| %s | %.1f | %.1f | %.2fx |\n", label.c_str(), r, k, k / r);
  };
  row("fk", "forward kinematics T_WT(q)");
  row("jacobian", "geometric Jacobian 6x6");
  for (size_t c = 0; c < S().ik_cases.size(); ++c) {
    const Setup::IkCase& ic = S().ik_cases[c];
    char label[200];
    std::snprintf(label, sizeof(label),
                  "IK solve, eps %.0e (mean iterations rcal %.1f, KDL %.1f; worst true error "
                  "rcal %.1e, KDL %.1e; KDL failed %d/%zu)",
                  ic.eps, ic.rcal_mean_iterations, ic.kdl_mean_iterations, ic.rcal_worst,
                  ic.kdl_worst, ic.kdl_failures, S().targets.size());
    row(c == 0 ? "ik_1e-6" : "ik_1e-10", label);
  }
  for (const char* op : {"fk", "jacobian"}) {
    const double e = reporter.Ns(std::string(op) + "/rcal_et_model");
    if (e > 0) std::printf("| %s, rcal ET-by-ET KinematicModel (reference) | %.1f | | |\n", op, e);
  }
  return 0;
}
