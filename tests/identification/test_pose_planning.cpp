#include "rcal/identification/pose_planning.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "identification_fixture.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::identification {
namespace {

using kinematics::MeasurementKind;

double LogDet(const Eigen::MatrixXd& M) {
  return 2.0 * M.llt().matrixLLT().diagonal().array().log().sum();
}

struct Fixture {
  kinematics::KinematicModel model = testing::Ur10FromUrdf();
  std::vector<Eigen::VectorXd> candidates, task;
  PlanningSettings settings;
  Fixture(int n = 600, unsigned seed = 3) {
    sim::Rng rng(seed);
    candidates = sim::SampleJoints(model, n, rng);
    task = sim::SampleJoints(model, 40, rng);
    settings.position_sigma_m = 2e-5;
  }
};

// The rank-r update formulas against the criteria computed directly from M and M + AᵢᵀAᵢ.
TEST(PosePlanning, GainsEqualTheCriterionsChangeComputedDirectly) {
  Fixture f(200);
  for (const auto kind : {MeasurementKind::kPositionOnly, MeasurementKind::kFullPose}) {
    f.settings.kind = kind;
    const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings, f.task);
    const std::vector<int> some = {3, 17, 40, 41, 99};
    const Eigen::MatrixXd M = pp.Information(some);
    const Eigen::VectorXd gd = pp.Gains(M, PlanCriterion::kDOptimal);
    const Eigen::VectorXd gt = pp.Gains(M, PlanCriterion::kTaskRegion);
    const double t0 = pp.TaskMeanSquared(M);
    for (int i : {0, 5, 17, 150}) {
      auto with = some;
      with.push_back(i);
      const Eigen::MatrixXd Mi = pp.Information(with);
      EXPECT_NEAR(gd(i), LogDet(Mi) - LogDet(M), 1e-7 * std::abs(LogDet(Mi)));
      EXPECT_NEAR(gt(i), t0 - pp.TaskMeanSquared(Mi), 1e-8 * t0);
      EXPECT_GT(gt(i), 0.0);
    }
  }
}

// tr(G M⁻¹) against the mean squared position change of sampled parameter errors N(0, M⁻¹)
// (unscaled: δx_base = D·δx_scaled) at the task poses, from the model's own Jacobian.
TEST(PosePlanning, TaskMeanSquaredIsThePredictedMeanSquaredPositionError) {
  Fixture f(300);
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings, f.task);
  const Eigen::MatrixXd M = pp.Information(pp.Plan(25).chosen);
  const Eigen::MatrixXd C = M.inverse();
  const Eigen::MatrixXd L = C.llt().matrixL();
  sim::Rng rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  double ss = 0;
  const int draws = 4000;
  Eigen::MatrixXd J(6, f.model.num_params());
  for (int d = 0; d < draws; ++d) {
    Eigen::VectorXd z(M.rows());
    for (int k = 0; k < z.size(); ++k) z(k) = n(rng);
    const Eigen::VectorXd dxs = L * z;
    Eigen::VectorXd dx = Eigen::VectorXd::Zero(f.model.num_params());
    for (size_t c = 0; c < pp.identifiable().size(); ++c)
      dx(pp.identifiable()[c]) = pp.scale()(c) * dxs(c);
    const auto& q = f.task[d % f.task.size()];
    f.model.IdentificationJacobian(q, f.model.Nominal(), J);
    ss += (J.topRows<3>() * dx).squaredNorm();
  }
  EXPECT_NEAR(ss / draws, pp.TaskMeanSquared(M), 0.06 * pp.TaskMeanSquared(M));
}

TEST(PosePlanning, ExchangeImprovesOnGreedyAndBothBeatRandomSubsets) {
  Fixture f(800);
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings);
  const PosePlan greedy = pp.Plan(20, false);
  const PosePlan plan = pp.Plan(20);
  EXPECT_GE(plan.log_det, greedy.log_det - 1e-9);
  EXPECT_EQ(plan.chosen.size(), 20u);
  std::vector<int> sorted = plan.chosen;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end()) << "a stop repeated";
  // No exchange is left to make: swapping any chosen stop for any free one lowers log det.
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> pick(0, pp.size() - 1);
  for (int t = 0; t < 200; ++t) {
    auto s = plan.chosen;
    const int k = pick(rng);
    if (std::find(s.begin(), s.end(), k) != s.end()) continue;
    s[t % 20] = k;
    EXPECT_LE(pp.Evaluate(s).log_det, plan.log_det + 1e-9);
  }
  // Random 20-stop subsets of the same candidates.
  std::vector<int> idx(pp.size());
  std::iota(idx.begin(), idx.end(), 0);
  double best_random = -1e300;
  for (int t = 0; t < 200; ++t) {
    std::shuffle(idx.begin(), idx.end(), rng);
    best_random = std::max(best_random, pp.Evaluate({idx.begin(), idx.begin() + 20}).log_det);
  }
  EXPECT_GT(plan.log_det, best_random + 1.0);
  const PosePlan iroc = pp.IrocGreedy(20);
  EXPECT_GT(iroc.log_det, best_random);
  EXPECT_EQ(iroc.exchanges, 0);
}

// The point of it all, against a simulated truth: the linear prediction (tr(G M⁻¹) over the
// workspace) of 20 planned stops is well below that of 20 random ones, and LM calibration from
// the planned stops is more accurate on held-out poses than from random ones.
TEST(PosePlanning, PlannedStopsCalibrateBetterThanRandomOnesAgainstTheTruth) {
  Fixture f(3000, 21);
  std::vector<Eigen::VectorXd> workspace;
  for (int i = 0; i < 3000; i += 10) workspace.push_back(f.candidates[i]);
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings, workspace);
  const PosePlan plan = pp.Plan(20);
  std::vector<int> idx(pp.size());
  std::iota(idx.begin(), idx.end(), 0);
  std::mt19937_64 shuffle(3);
  std::vector<double> predicted_random;
  for (int t = 0; t < 21; ++t) {
    std::shuffle(idx.begin(), idx.end(), shuffle);
    predicted_random.push_back(pp.Evaluate({idx.begin(), idx.begin() + 20}).task_mean_squared_m2);
  }
  std::sort(predicted_random.begin(), predicted_random.end());
  EXPECT_LT(plan.task_mean_squared_m2, 0.7 * predicted_random[10]);

  sim::PoseNoise noise;
  noise.orientation = false;
  noise.position_sigma = f.settings.position_sigma_m;
  std::vector<double> planned, random20;
  std::vector<Eigen::VectorXd> plan_q;
  for (int i : plan.chosen) plan_q.push_back(f.candidates[i]);
  for (unsigned seed = 1; seed <= 9; ++seed) {
    sim::Rng rng(100 + seed);
    const Eigen::VectorXd x_true = sim::RandomErrors(f.model, rng, 5e-4, 1e-3);
    const auto test_q = sim::SampleJoints(f.model, 100, rng);
    const auto random_q = sim::SampleJoints(f.model, 20, rng);
    const auto error = [&](const std::vector<Eigen::VectorXd>& qs) {
      const auto ms = sim::MeasurePoses(f.model, x_true, qs, noise, rng);
      const LmResult fit = BatchLm(f.model, pp.identifiable()).Solve(ms, f.model.Nominal());
      return ErrorsAgainstTruth(f.model, fit.x, x_true, test_q).mean_position_m;
    };
    planned.push_back(error(plan_q));
    random20.push_back(error(random_q));
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  EXPECT_LT(median(planned), 0.95 * median(random20));
}

TEST(PosePlanning, TaskRegionPlanLowersThePredictedTaskErrorBelowTheDOptimalOne) {
  Fixture f(1000);
  // The task: a small box the UR10 reaches, the candidates whose marker lies in it.
  PoseConstraints c;
  c.task_region = Box{Eigen::Vector3d(0.3, -0.4, 0.0), Eigen::Vector3d(0.9, 0.4, 0.6)};
  const auto task = InTaskRegion(f.model, f.model.Nominal(), f.candidates, c);
  ASSERT_GE(task.size(), 20u);
  for (const auto& q : task)
    EXPECT_TRUE(c.task_region->Contains(MarkerInBase(f.model, f.model.Nominal(), q)));
  PlanningSettings s = f.settings;
  s.criterion = PlanCriterion::kTaskRegion;
  const PlanningProblem task_pp(f.model, f.model.Nominal(), f.candidates, s, task);
  const PlanningProblem d_pp(f.model, f.model.Nominal(), f.candidates, f.settings, task);
  const PosePlan t = task_pp.Plan(15), d = d_pp.Plan(15);
  EXPECT_LT(t.task_mean_squared_m2, d_pp.Evaluate(d.chosen).task_mean_squared_m2);
  EXPECT_NEAR(t.task_mean_squared_m2, d_pp.Evaluate(t.chosen).task_mean_squared_m2,
              1e-9 * t.task_mean_squared_m2);
}

// The bound on what any `count` stops of the candidates can give (the approximate-design
// relaxation): below every exact design tried (the planner's, random ones, one stop repeated), its
// bracket closed to the tolerance, and (the prior made negligible) exactly 1/count in the stops:
// the relaxed optimum's weights do not depend on count, so doubling the stops halves it.
TEST(PosePlanning, NoSetOfStopsBeatsTheRelaxationsBound) {
  Fixture f(400);
  f.settings.criterion = PlanCriterion::kTaskRegion;
  f.settings.prior_sigma_length = f.settings.setup_sigma_length = 1.0;
  f.settings.prior_sigma_angle = f.settings.setup_sigma_angle = 1.0;
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings, f.task);
  const DesignBound b20 = pp.TaskMeanSquaredBound(20), b40 = pp.TaskMeanSquaredBound(40);
  for (const DesignBound& b : {b20, b40}) {
    EXPECT_GT(b.lower_m2, 0);
    EXPECT_LE(b.lower_m2, b.relaxed_m2);
    EXPECT_LE(b.relaxed_m2 - b.lower_m2, 0.01 * b.relaxed_m2) << b.iterations << " iterations";
  }
  EXPECT_NEAR(b40.relaxed_m2 / b20.relaxed_m2, 0.5, 0.01);
  EXPECT_NEAR(b40.lower_m2 / b20.lower_m2, 0.5, 0.01);
  // Exact designs: the planner's (near the bound), random ones (well above), a repeated stop.
  const PosePlan planned = pp.Plan(20);
  EXPECT_GE(planned.task_mean_squared_m2, b20.lower_m2);
  EXPECT_LT(planned.task_mean_squared_m2, 1.15 * b20.relaxed_m2);
  std::mt19937_64 rng(5);
  std::vector<int> idx(pp.size());
  std::iota(idx.begin(), idx.end(), 0);
  for (int t = 0; t < 30; ++t) {
    std::shuffle(idx.begin(), idx.end(), rng);
    EXPECT_GE(pp.Evaluate({idx.begin(), idx.begin() + 20}).task_mean_squared_m2, b20.lower_m2);
  }
  std::vector<int> twice = planned.chosen;
  twice.resize(10);
  twice.insert(twice.end(), planned.chosen.begin(), planned.chosen.begin() + 10);
  EXPECT_GE(pp.Evaluate(twice).task_mean_squared_m2, b20.lower_m2);
  // Without task configurations there is no criterion to bound.
  f.settings.criterion = PlanCriterion::kDOptimal;
  const PlanningProblem no_task(f.model, f.model.Nominal(), f.candidates, f.settings);
  EXPECT_THROW(no_task.TaskMeanSquaredBound(20), std::invalid_argument);
}

TEST(PosePlanning, CandidatesSatisfyTheConstraints) {
  const auto model = testing::Ur10FromUrdf();
  Eigen::VectorXd x = model.Nominal();
  // A world ← base away from identity: the constraints are in the base frame regardless.
  x(model.FindParameter("base_x")) = 1.5;
  x(model.FindParameter("base_rz")) = 0.7;
  PoseConstraints c;
  c.tool_box = Box{Eigen::Vector3d(-0.2, -1.5, -0.5), Eigen::Vector3d(1.5, 1.5, 1.5)};
  c.min_base_distance = 0.6;
  c.home = Eigen::VectorXd::Zero(6);
  c.home_tolerance = Eigen::VectorXd::Constant(6, 2.0);
  sim::Rng rng(8);
  const auto qs = SampleCandidates(model, x, c, 300, rng);
  ASSERT_EQ(qs.size(), 300u);
  for (const auto& q : qs) {
    EXPECT_TRUE(SatisfiesConstraints(model, x, q, c));
    EXPECT_LE((q - c.home).cwiseAbs().maxCoeff(), 2.0);
    // MarkerInBase is the marker with T_WB = I: T_WB⁻¹ · p_WM_W from the model at x.
    const Eigen::Vector3d p_W = model.Forward(q, x).p_WM_W;
    const Eigen::Isometry3d T_WB = model.ToolFrame(Eigen::VectorXd::Zero(6), x) *
                                   model
                                       .ToolFrame(Eigen::VectorXd::Zero(6),
                                                  [&] {
                                                    Eigen::VectorXd xb = x;
                                                    for (int i = 0; i < model.num_params(); ++i)
                                                      if (model.parameters()[i].group == "base")
                                                        xb(i) = -model.parameters()[i].nominal;
                                                    return xb;
                                                  }())
                                       .inverse();
    const Eigen::Vector3d p_B = MarkerInBase(model, x, q);
    EXPECT_LT((T_WB.inverse() * p_W - p_B).norm(), 1e-9);
    EXPECT_GE(p_B.norm(), 0.6);
    EXPECT_TRUE(c.tool_box->Contains(p_B));
  }
  // An unreachable box: refused, naming the constraint.
  c.tool_box = Box{Eigen::Vector3d(5, 5, 5), Eigen::Vector3d(6, 6, 6)};
  try {
    SampleCandidates(model, x, c, 10, rng, 0.05, 2000);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("constraints.tool_box"), std::string::npos) << e.what();
  }
  c.home = Eigen::VectorXd::Zero(5);
  EXPECT_THROW(SampleCandidates(model, x, c, 10, rng), std::invalid_argument);
}

// The Kalman posterior computed directly against NextBestPoses' gains; the order is by gain per
// distance.
TEST(PosePlanning, NextBestPosesRankByTaskErrorReductionPerDistance) {
  Fixture f(150);
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings, f.task);
  const std::vector<int>& id = pp.identifiable();
  const int n = static_cast<int>(id.size());
  // A covariance after a few stops (unscaled): D M⁻¹ D.
  const Eigen::MatrixXd P = pp.scale().asDiagonal() *
                            pp.Information({1, 2, 3, 4, 5, 6, 7, 8}).inverse() *
                            pp.scale().asDiagonal();
  const Eigen::VectorXd q_now = f.candidates[0];
  constexpr double kStopCost = 3.0;  // [rad]: a cost at which distance matters
  const auto next = NextBestPoses(f.model, f.model.Nominal(), id, P, f.candidates, f.task, q_now, 5,
                                  f.settings, kStopCost);
  ASSERT_EQ(next.size(), 5u);
  Eigen::MatrixXd J6(6, f.model.num_params()), G = Eigen::MatrixXd::Zero(n, n), Jp(3, n);
  for (const auto& q : f.task) {
    f.model.IdentificationJacobian(q, f.model.Nominal(), J6);
    for (int c = 0; c < n; ++c) Jp.col(c) = J6.col(id[c]).head<3>();
    G += Jp.transpose() * Jp / static_cast<double>(f.task.size());
  }
  double best_score = 0;
  for (size_t i = 0; i < f.candidates.size(); ++i) {
    f.model.IdentificationJacobian(f.candidates[i], f.model.Nominal(), J6);
    Eigen::MatrixXd H(3, n);
    for (int c = 0; c < n; ++c) H.col(c) = J6.col(id[c]).head<3>();
    const Eigen::MatrixXd R = Eigen::Matrix3d::Identity() * 4e-10;
    const Eigen::MatrixXd K = P * H.transpose() * (H * P * H.transpose() + R).inverse();
    const Eigen::MatrixXd P_plus = P - K * H * P;
    const double gain = (G * P).trace() - (G * P_plus).trace();
    const double score = gain / ((f.candidates[i] - q_now).norm() + kStopCost);
    best_score = std::max(best_score, score);
    for (const auto& np : next) {
      if (np.candidate == static_cast<int>(i)) {
        EXPECT_NEAR(np.gain_m2, gain, 1e-6 * gain);
      }
    }
  }
  EXPECT_NEAR(next[0].score, best_score, 1e-6 * best_score);
  for (size_t k = 1; k < next.size(); ++k) EXPECT_GE(next[k - 1].score, next[k].score);
  EXPECT_THROW(NextBestPoses(f.model, f.model.Nominal(), id, Eigen::MatrixXd::Identity(2, 2),
                             f.candidates, f.task, q_now, 5, f.settings),
               std::invalid_argument);
}

TEST(PosePlanning, BadInputIsRefusedNamingIt) {
  Fixture f(50);
  EXPECT_THROW(PlanningProblem(f.model, f.model.Nominal(), {}, f.settings), std::invalid_argument);
  auto bad = f.candidates;
  bad[7] = Eigen::VectorXd::Zero(5);
  try {
    PlanningProblem(f.model, f.model.Nominal(), bad, f.settings);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("candidates[7]"), std::string::npos);
  }
  bad[7] = f.candidates[7];
  bad[7](2) = std::nan("");
  EXPECT_THROW(PlanningProblem(f.model, f.model.Nominal(), bad, f.settings), std::invalid_argument);
  PlanningSettings s = f.settings;
  s.criterion = PlanCriterion::kTaskRegion;
  EXPECT_THROW(PlanningProblem(f.model, f.model.Nominal(), f.candidates, s), std::invalid_argument);
  const PlanningProblem pp(f.model, f.model.Nominal(), f.candidates, f.settings);
  EXPECT_THROW(pp.Plan(51), std::invalid_argument);
  EXPECT_THROW(pp.Plan(0), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
