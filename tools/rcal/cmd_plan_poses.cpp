// rcal plan-poses --robot R [--cell FILE] --count N [--position-only] [--seed S] --out P.csv:
// N joint configurations, inside the joint limits and the cell's constraints, that carry the most
// information about the identifiable parameters (identification/pose_planning.hpp: D-optimal
// greedy + exchange over seeded candidates; --task-weighting: the predicted error over the cell's
// task region instead). P.csv holds q1..qN [rad | m], one stop a row, in the order to visit them.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "command.hpp"
#include "plan_poses.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "report.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

struct Options {
  std::string robot, cell, out, tip_link, base_link;
  int count = 20;
  int candidates = 5000;
  bool position_only = false;
  bool task_weighting = false;
  unsigned seed = 1;
  double position_sigma_mm = 0;      ///< 0: the cell's, else 0.05
  double orientation_sigma_deg = 0;  ///< 0: 0.05
};

int Run(const Options& o) {
  if (o.count < 1) throw std::runtime_error("--count: at least 1");
  if (o.candidates < o.count) throw std::runtime_error("--candidates: at least --count");
  PlanningInput in;
  if (!o.cell.empty()) {
    const io::BuiltCell cell = io::LoadCell(ResolvePath(o.cell));
    if (!o.robot.empty() && std::filesystem::weakly_canonical(ResolvePath(o.robot)) !=
                                std::filesystem::weakly_canonical(cell.spec.robot.file))
      throw std::runtime_error("--robot " + o.robot + " is not the cell's robot.file " +
                               cell.spec.robot.file.string() + " (give one of them)");
    in = PlanningInputFromCell(cell, o.position_only);
  } else {
    if (o.robot.empty()) throw std::runtime_error("--robot or --cell: one is required");
    io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, "auto");
    if (!o.position_only) AddOrientationFrame(robot);
    in.model = robot.model;
    in.settings.kind = o.position_only ? kinematics::MeasurementKind::kPositionOnly
                                       : kinematics::MeasurementKind::kFullPose;
  }
  if (o.position_sigma_mm > 0) in.settings.position_sigma_m = o.position_sigma_mm / kMm;
  if (o.orientation_sigma_deg > 0)
    in.settings.orientation_sigma_rad = o.orientation_sigma_deg / kDeg;
  if (o.task_weighting) {
    if (!in.constraints.task_region)
      throw std::runtime_error("--task-weighting: the cell has no constraints.task_region");
    in.settings.criterion = identification::PlanCriterion::kTaskRegion;
  }
  const kinematics::KinematicModel& model = in.model;
  const Eigen::VectorXd x = model.Nominal();

  std::mt19937_64 rng(o.seed);
  auto candidates = identification::SampleCandidates(model, x, in.constraints, o.candidates, rng);
  const auto task = identification::InTaskRegion(model, x, candidates, in.constraints);
  if (in.constraints.task_region && task.empty())
    throw std::runtime_error(
        "constraints.task_region: none of the candidate configurations puts the marker inside");
  const identification::PlanningProblem pp(model, x, candidates, in.settings, task);
  const identification::PosePlan plan = pp.Plan(o.count);

  // The same number of stops drawn at random from the same candidates, for scale.
  std::vector<double> random_logdet, random_task;
  std::vector<int> idx(pp.size());
  std::iota(idx.begin(), idx.end(), 0);
  for (int t = 0; t < 20; ++t) {
    std::shuffle(idx.begin(), idx.end(), rng);
    const auto e = pp.Evaluate({idx.begin(), idx.begin() + o.count});
    random_logdet.push_back(e.log_det);
    random_task.push_back(e.task_mean_squared_m2);
  }
  std::sort(random_logdet.begin(), random_logdet.end());
  std::sort(random_task.begin(), random_task.end());

  std::vector<Eigen::VectorXd> stops;
  for (int i : plan.chosen) stops.push_back(candidates[i]);
  const std::string criterion =
      o.task_weighting ? "task-region predicted error (I-optimal)" : "D-optimal";
  const std::vector<std::string> comments = {
      "rcal plan-poses: " + model.name() + ", " + std::to_string(o.count) + " stops, " + criterion +
          ", " +
          (in.settings.kind == kinematics::MeasurementKind::kPositionOnly ? "positions only"
                                                                          : "full pose"),
      "candidates " + std::to_string(o.candidates) + ", seed " + std::to_string(o.seed) +
          ", joints in rad (revolute) or m (prismatic), model joint order"};
  io::AtomicWriteFile(o.out, JointsCsv(stops, comments));

  std::printf("%s: %d stops from %d candidates (%s, %s), %zu identifiable parameters\n",
              model.name().c_str(), o.count, pp.size(), criterion.c_str(),
              in.settings.kind == kinematics::MeasurementKind::kPositionOnly ? "positions only"
                                                                             : "full pose",
              plan.identifiable.size());
  std::printf("log det information: planned %.2f, %d random stops median %.2f (best of 20: %.2f)\n",
              plan.log_det, o.count, random_logdet[10], random_logdet.back());
  std::printf("  (per parameter: the planned confidence ellipsoid is %.2f× smaller in each axis)\n",
              std::exp(0.5 * (plan.log_det - random_logdet[10]) / plan.identifiable.size()));
  if (!task.empty()) {
    std::printf(
        "predicted RMS position error in the task region (%zu candidates inside): planned %.4f mm, "
        "random median %.4f mm\n",
        task.size(), std::sqrt(plan.task_mean_squared_m2) * kMm, std::sqrt(random_task[10]) * kMm);
    // What no choice among these candidates can beat (the approximate-design bound).
    const identification::DesignBound b = pp.TaskMeanSquaredBound(o.count);
    std::printf("  no %d stops from these candidates predict below %.4f mm there (bound)\n",
                o.count, std::sqrt(b.lower_m2) * kMm);
  }
  std::printf("exchange: %d swaps in %d sweeps\nwrote %s\n", plan.exchanges, plan.sweeps,
              o.out.c_str());
  return 0;
}

const RegisterCommand kPlanPoses(
    "plan-poses",
    "Joint configurations to measure: the most information on the identifiable parameters",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)");
      sub.add_option("--cell", o->cell, "cell file (rcal.cell/1): set-up, noise, constraints");
      sub.add_option("--tip", o->tip_link, "URDF tip link (default: detected)");
      sub.add_option("--base-link", o->base_link, "URDF base link (default: the root)");
      sub.add_option("--count", o->count, "stops to plan")->capture_default_str();
      sub.add_option("--candidates", o->candidates, "seeded candidate configurations")
          ->capture_default_str();
      sub.add_flag("--position-only", o->position_only, "positions only (no orientation)");
      sub.add_flag("--task-weighting", o->task_weighting,
                   "minimise the predicted error over the cell's constraints.task_region");
      sub.add_option("--seed", o->seed, "seed of the candidates")->capture_default_str();
      sub.add_option("--position-sigma-mm", o->position_sigma_mm,
                     "position noise σ per axis (default: the cell's, else 0.05)");
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "orientation noise σ per axis (default 0.05)");
      sub.add_option("--out", o->out, "CSV to write (q1..qN)")->required();
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
