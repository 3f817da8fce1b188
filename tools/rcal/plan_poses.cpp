#include "plan_poses.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <random>

#include "calibration_sweep.hpp"
#include "rcal/cell/online_identification.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::tool {
namespace {

double ThreadSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

std::vector<Eigen::VectorXd> Pick(const std::vector<Eigen::VectorXd>& candidates,
                                  const std::vector<int>& chosen) {
  std::vector<Eigen::VectorXd> out;
  for (int i : chosen) out.push_back(candidates[i]);
  return out;
}

// The median over 21 seeded draws of `count` random candidates of the predicted RMS position
// error over the workspace [m] (PlanningProblem::Evaluate).
double RandomPredictedRms(const identification::PlanningProblem& pp, int count,
                          std::uint64_t seed) {
  std::mt19937_64 draw(seed);
  std::vector<int> idx(static_cast<size_t>(pp.size()));
  std::iota(idx.begin(), idx.end(), 0);
  std::vector<double> ms;
  for (int t = 0; t < 21; ++t) {
    std::shuffle(idx.begin(), idx.end(), draw);
    ms.push_back(pp.Evaluate({idx.begin(), idx.begin() + count}).task_mean_squared_m2);
  }
  std::nth_element(ms.begin(), ms.begin() + 10, ms.end());
  return std::sqrt(ms[10]);
}

}  // namespace

PlanningInput PlanningInputFromCell(const io::BuiltCell& cell, bool position_only) {
  PlanningInput in;
  in.model = cell.model;
  in.constraints = cell.spec.constraints;
  auto& s = in.settings;
  const bool orientation = cell.spec.measures_orientation() && !position_only;
  s.kind = orientation ? kinematics::MeasurementKind::kFullPose
                       : kinematics::MeasurementKind::kPositionOnly;
  s.position_sigma_m = cell.spec.position.sigma.maxCoeff();
  if (cell.spec.position.orientation)
    s.orientation_sigma_rad = cell.spec.position.orientation_sigma;
  s.prior_sigma_length = cell.spec.identifier.prior_sigma_length;
  s.prior_sigma_angle = cell.spec.identifier.prior_sigma_angle;
  return in;
}

std::string JointsCsv(const std::vector<Eigen::VectorXd>& stops,
                      const std::vector<std::string>& comments) {
  std::string s;
  for (const auto& c : comments) s += "# " + c + "\n";
  const Eigen::Index n = stops.empty() ? 0 : stops.front().size();
  for (Eigen::Index j = 0; j < n; ++j) s += (j ? ",q" : "q") + std::to_string(j + 1);
  s += "\n";
  char buf[40];
  for (const auto& q : stops) {
    for (Eigen::Index j = 0; j < q.size(); ++j) {
      std::snprintf(buf, sizeof buf, "%s%.17g", j ? "," : "", q(j));
      s += buf;
    }
    s += "\n";
  }
  return s;
}

std::vector<Eigen::VectorXd> ReadJointsCsv(const std::string& path,
                                           const kinematics::KinematicModel& model) {
  const io::CsvTable t = io::CsvTable::Load(path);
  if (t.rows() == 0) throw std::runtime_error(path + ": no stops");
  const int nj = model.num_joints();
  std::vector<Eigen::VectorXd> qs;
  for (int i = 0; i < t.rows(); ++i) {
    Eigen::VectorXd q(nj);
    for (int j = 0; j < nj; ++j) {
      std::string column = std::to_string(j + 1);
      column.insert(0, 1, 'q');
      q(j) = t.At(i, column);
      const auto& J = model.joints()[j];
      if (!std::isfinite(q(j)) || q(j) < J.lower || q(j) > J.upper)
        throw std::runtime_error(path + ": row " + std::to_string(i + 1) + ", column " + column +
                                 ": " + std::to_string(q(j)) + " is not inside " + J.name +
                                 "'s limits [" + std::to_string(J.lower) + ", " +
                                 std::to_string(J.upper) + "] (rad | m)");
    }
    qs.push_back(q);
  }
  return qs;
}

ArmPlans PlanArm(const kinematics::KinematicModel& model, const PlanningReportSettings& s,
                 std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Eigen::VectorXd x = model.Nominal();
  const auto candidates = sim::SampleJoints(model, s.candidates, rng);
  identification::PlanningSettings ps;
  ps.position_sigma_m = s.position_sigma_m;
  // The error that matters: over the whole workspace (an even spread of the candidates), as the
  // held-out poses are drawn.
  std::vector<Eigen::VectorXd> workspace;
  for (size_t i = 0; i < candidates.size(); i += std::max<size_t>(1, candidates.size() / 300))
    workspace.push_back(candidates[i]);
  identification::PlanningSettings planned_settings = ps;
  planned_settings.criterion = s.criterion;
  const identification::PlanningProblem pp(model, x, candidates, planned_settings, workspace);
  ArmPlans plans;
  plans.identifiable = static_cast<int>(pp.identifiable().size());
  const int max_count = s.counts.back();
  for (int n : s.counts) {
    const double t0 = ThreadSeconds();
    plans.planned.push_back(Pick(candidates, pp.Plan(n).chosen));
    if (n == 20 || plans.plan_seconds == 0) plans.plan_seconds = ThreadSeconds() - t0;
  }
  plans.iroc = Pick(candidates, pp.IrocGreedy(max_count).chosen);
  // The figure (20 planned stops against 40 random) against what any 20 stops can do.
  if (std::find(s.counts.begin(), s.counts.end(), 20) != s.counts.end())
    plans.bound20_rms_m = std::sqrt(pp.TaskMeanSquaredBound(20).lower_m2);
  if (std::find(s.counts.begin(), s.counts.end(), 40) != s.counts.end())
    plans.random40_rms_m = RandomPredictedRms(pp, 40, seed ^ 0x40);
  // Online next-best from the arm at the middle of its limits: the covariance after each stop
  // (the prior and the stops so far, linearised at the nominal) chooses the next.
  Eigen::VectorXd q_now(model.num_joints());
  for (int j = 0; j < model.num_joints(); ++j)
    q_now(j) = 0.5 * (model.joints()[j].lower + model.joints()[j].upper);
  const Eigen::VectorXd start = q_now;
  std::vector<int> chosen;
  std::vector<char> taken(candidates.size(), 0);
  const Eigen::VectorXd& D = pp.scale();
  for (int k = 0; k < max_count; ++k) {
    const Eigen::MatrixXd P = D.asDiagonal() * pp.Information(chosen).inverse() * D.asDiagonal();
    const auto next = identification::NextBestPoses(model, x, pp.identifiable(), P, candidates,
                                                    workspace, q_now, 8, ps, s.settle_distance);
    const auto it = std::find_if(next.begin(), next.end(), [&](const identification::NextPose& n) {
      return !taken[n.candidate];
    });
    if (it == next.end()) break;
    chosen.push_back(it->candidate);
    taken[it->candidate] = 1;
    q_now = candidates[it->candidate];
  }
  plans.next_best = Pick(candidates, chosen);
  const int n20 =
      std::find(s.counts.begin(), s.counts.end(), 20) != s.counts.end() ? 20 : s.counts[0];
  const auto path = [&](const std::vector<Eigen::VectorXd>& v) {
    Eigen::VectorXd at = start;
    double length = 0;
    for (int i = 0; i < n20 && i < static_cast<int>(v.size()); ++i) {
      length += (v[i] - at).norm();
      at = v[i];
    }
    return length;
  };
  const size_t c20 =
      static_cast<size_t>(std::find(s.counts.begin(), s.counts.end(), n20) - s.counts.begin());
  plans.path20[kRandom] = path(sim::SampleJoints(model, n20, rng));
  plans.path20[kPlanned] = path(plans.planned[c20]);
  plans.path20[kNextBest] = path(plans.next_best);
  plans.path20[kIroc] = path(plans.iroc);
  return plans;
}

std::array<std::vector<double>, 4> StrategyErrors(const kinematics::KinematicModel& model,
                                                  std::string_view arm_name, const ArmPlans& plans,
                                                  const PlanningReportSettings& s,
                                                  unsigned seed_index) {
  CalibrationSweepSettings cs;
  cs.poses = s.counts.back();
  cs.test_poses = s.test_poses;
  cs.position_only = true;
  cs.position_sigma_m = s.position_sigma_m;
  const SweepCell cell = MakeSweepCell(model, arm_name, cs, seed_index);
  sim::PoseNoise noise;
  noise.orientation = false;
  noise.position_sigma = s.position_sigma_m;
  const auto error = [&](const std::vector<Eigen::VectorXd>& qs, std::uint64_t stream) {
    sim::Rng rng(cell.seed ^ (0x9e3779b97f4a7c15ull * (stream + 1)));
    auto ms = sim::MeasurePoses(model, cell.x_true, qs, noise, rng);
    // The user does not know the noise: Calibrate starts from twice it and estimates it.
    identification::SetNoise(ms, cs.start_noise_factor * s.position_sigma_m, 0.0);
    const auto fit = identification::Calibrate(model, ms);
    return identification::ErrorsAgainstTruth(model, fit.x, cell.x_true, cell.test_q)
        .mean_position_m;
  };
  std::array<std::vector<double>, 4> e;
  for (size_t c = 0; c < s.counts.size(); ++c) {
    const auto n = static_cast<std::ptrdiff_t>(s.counts[c]);
    const auto prefix = [&](const std::vector<Eigen::VectorXd>& v) {
      return std::vector<Eigen::VectorXd>(v.begin(),
                                          v.begin() + std::min<std::ptrdiff_t>(n, v.size()));
    };
    e[kRandom].push_back(error(prefix(cell.cal_q), 1000 + c));
    e[kPlanned].push_back(error(plans.planned[c], 2000 + c));
    e[kNextBest].push_back(error(prefix(plans.next_best), 3000 + c));
    e[kIroc].push_back(error(prefix(plans.iroc), 4000 + c));
  }
  return e;
}

CellPlans PlanCell(const io::BuiltCell& cell, const CellReportSettings& s) {
  // The planner chooses from the advisor's candidates and averages over its workspace spread:
  // the same draw for every strategy.
  CellPlans plans;
  plans.advisor = std::make_shared<const cell::NextPoseAdvisor>(cell, s.candidates, 1);
  const auto& candidates = plans.advisor->candidates();
  identification::PlanningSettings ps = PlanningInputFromCell(cell, false).settings;
  ps.position_sigma_m = s.position_sigma_m;
  ps.orientation_sigma_rad = s.orientation_sigma_rad;
  const identification::PlanningProblem pp(cell.model, cell.model.Nominal(), candidates, ps,
                                           plans.advisor->task());
  plans.identifiable = static_cast<int>(pp.identifiable().size());
  for (int n : s.counts) plans.planned.push_back(Pick(candidates, pp.Plan(n).chosen));
  plans.iroc = Pick(candidates, pp.IrocGreedy(s.counts.back()).chosen);
  if (std::find(s.counts.begin(), s.counts.end(), 20) != s.counts.end())
    plans.bound20_rms_m = std::sqrt(pp.TaskMeanSquaredBound(20).lower_m2);
  if (std::find(s.counts.begin(), s.counts.end(), 50) != s.counts.end())
    plans.random50_rms_m = RandomPredictedRms(pp, 50, 0x50);
  return plans;
}

std::array<std::vector<double>, 4> CellStrategyErrors(const io::BuiltCell& cell,
                                                      const cell::CellSimSpec& sim,
                                                      const CellPlans& plans,
                                                      const CellReportSettings& s, unsigned seed) {
  const int max_count = s.counts.back();
  const cell::SimProgramme programme =
      cell::MakeSimProgramme(cell, sim, seed, max_count, s.test_poses);
  const kinematics::KinematicModel& truth_model = programme.cell.model;
  const Eigen::VectorXd& x_true = programme.cell.x_true;
  const std::vector<Eigen::VectorXd> random(programme.stops.begin(),
                                            programme.stops.begin() + max_count);
  const std::vector<Eigen::VectorXd> test(programme.stops.begin() + max_count,
                                          programme.stops.end());
  sim::PoseNoise noise;
  noise.orientation = cell.spec.measures_orientation();
  noise.position_sigma = s.position_sigma_m;
  noise.orientation_sigma = s.orientation_sigma_rad;
  const auto test_error = [&](const cell::OnlineIdentification& id) {
    if (!id.started()) return std::numeric_limits<double>::quiet_NaN();
    return identification::ErrorsAgainstTruth(truth_model, id.ekf().x(), x_true, test)
        .mean_position_m;
  };
  // The stops in order through the live identifier's logic; the error after each count.
  const auto run = [&](const std::vector<Eigen::VectorXd>& stops, std::uint64_t stream,
                       const std::vector<int>& at_counts) {
    sim::Rng rng(seed * 1000003ull + stream);
    cell::OnlineIdentification id(cell);
    std::vector<double> e;
    for (size_t k = 0; k < stops.size(); ++k) {
      id.Add({sim::MeasurePose(truth_model, x_true, stops[k], noise, rng),
              static_cast<int64_t>(k + 1) * 1'000'000,
              static_cast<int64_t>(k),
              {}});
      if (std::find(at_counts.begin(), at_counts.end(), static_cast<int>(k + 1)) != at_counts.end())
        e.push_back(test_error(id));
    }
    return e;
  };
  std::array<std::vector<double>, 4> e;
  e[kRandom] = run(random, 1, s.counts);
  e[kIroc] = run(plans.iroc, 4, s.counts);
  for (size_t c = 0; c < s.counts.size(); ++c)
    e[kPlanned].push_back(run(plans.planned[c], 200 + c, {s.counts[c]}).front());
  // Online next-best: a pose-level cell that follows NEXT_POSES.
  {
    sim::Rng rng(seed * 1000003ull + 3);
    cell::OnlineIdentification id(cell);
    cell::NextPoseAdvisor advisor = *plans.advisor;  // a copy: it learns its poses' noise
    std::vector<Eigen::VectorXd> stood;
    for (int k = 0; k < max_count; ++k) {
      Eigen::VectorXd q = random[static_cast<size_t>(k)];
      if (id.started() && !stood.empty()) {
        const auto advice = advisor.Suggest(id.ekf(), stood.back(), 8, s.settle_distance);
        if (const auto next = cell::NextStopToFollow(advice.q, stood)) q = *next;
      }
      const kinematics::PoseMeasurement z = sim::MeasurePose(truth_model, x_true, q, noise, rng);
      advisor.Measured(z);
      id.Add({z, static_cast<int64_t>(k + 1) * 1'000'000, k, {}});
      stood.push_back(q);
      if (std::find(s.counts.begin(), s.counts.end(), k + 1) != s.counts.end())
        e[kNextBest].push_back(test_error(id));
    }
  }
  return e;
}

}  // namespace rcal::tool
