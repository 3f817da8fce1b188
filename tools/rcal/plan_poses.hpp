// `rcal plan-poses` and `rcal plan-poses-report` (issue 16), apart so that tests can call them:
// the planning input of a cell, the stops file, and one seeded comparison of the strategies
// (random, planned offline, online next-best, IROC-style greedy) on a simulated cell.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/next_poses.hpp"
#include "rcal/identification/pose_planning.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::tool {

/// What planning needs: the model (set-up frames included), the settings (noise, prior, kind)
/// and the constraints.
struct PlanningInput {
  kinematics::KinematicModel model;
  identification::PlanningSettings settings;
  identification::PoseConstraints constraints;
};

/// From a cell: its model, the position sensor's largest σ, the orientation σ of a tracker that
/// measures it (else the planning default), the identifier's prior σ, the constraints. Positions
/// only when the cell measures no orientation or `position_only`.
PlanningInput PlanningInputFromCell(const io::BuiltCell& cell, bool position_only);

/// The stops file: '#' comment lines, the header q1..qN, one stop a row, SI, 17 digits.
std::string JointsCsv(const std::vector<Eigen::VectorXd>& stops,
                      const std::vector<std::string>& comments = {});

/// Reads a stops file (JointsCsv's layout: columns q1..qN, N = the model's joints): each row
/// finite and inside the joint limits. Throws std::runtime_error naming the file, row and column.
std::vector<Eigen::VectorXd> ReadJointsCsv(const std::string& path,
                                           const kinematics::KinematicModel& model);

/// The four strategies of the report, in this order.
enum Strategy { kRandom = 0, kPlanned = 1, kNextBest = 2, kIroc = 3 };
inline constexpr std::array<const char*, 4> kStrategyNames = {
    "random", "planned (D-optimal, greedy + exchange)", "online next-best", "IROC-style greedy"};

struct PlanningReportSettings {
  std::vector<int> counts{15, 20, 25, 30, 40, 50};  ///< stops, ascending
  int candidates = 5000;
  double position_sigma_m = 2e-5;                             ///< positions only, per axis
  int test_poses = 200;                                       ///< held-out poses per cell
  double settle_distance = identification::kDefaultStopCost;  ///< a stop's cost [rad]
  /// The planned strategy's criterion: D-optimal, or the predicted error over the workspace (the
  /// task-region criterion with an even spread of the candidates as the region).
  identification::PlanCriterion criterion = identification::PlanCriterion::kDOptimal;
};

/// The stops each strategy visits on one arm (independent of the truth: planned at the nominal).
struct ArmPlans {
  std::vector<std::vector<Eigen::VectorXd>> planned;  ///< one plan per count
  std::vector<Eigen::VectorXd> iroc, next_best;       ///< max(counts) stops; prefixes are used
  int identifiable = 0;
  /// Joint-space path [rad] from the middle of the limits through the first 20 stops (or the
  /// first count), in visiting order, per strategy (random: its first draw).
  std::array<double, 4> path20{};
  double plan_seconds = 0;  ///< CPU time of the planned plan at 20 stops (or the first count)
  /// Predicted RMS position error over the workspace [m] (linearised at the nominal): the least
  /// any 20 stops from the candidates can give (PlanningProblem::TaskMeanSquaredBound: its
  /// certified lower end), and the median of 21 draws of 40 random candidates. 0 when the counts
  /// lack 20 (40).
  double bound20_rms_m = 0, random40_rms_m = 0;
};
ArmPlans PlanArm(const kinematics::KinematicModel& model, const PlanningReportSettings& s,
                 std::uint64_t seed);

/// Held-out mean position error [m] against the truth, per strategy and count, on one simulated
/// cell (calibration_sweep.hpp MakeSweepCell: truth, random stops, test poses) calibrated by
/// identification::Calibrate from a wrong starting noise.
std::array<std::vector<double>, 4> StrategyErrors(const kinematics::KinematicModel& model,
                                                  std::string_view arm_name, const ArmPlans& plans,
                                                  const PlanningReportSettings& s,
                                                  unsigned seed_index);

/// The report's side for a cell of rcal's own (issue 16: "a report row for the demo cell"): the
/// four strategies on the simulated cell of a sim file (its cell file, and the truth only the
/// simulator knows), measured pose by pose with the still windows' noise and identified by the live
/// identifier's logic (cell::OnlineIdentification: the poses held for the set-up guess, then the
/// EKF), judged at the programme's test stops against the truth, as the live pipeline is.
struct CellReportSettings {
  std::vector<int> counts{15, 20, 25, 30, 40, 50};  ///< stops, ascending
  int candidates = 2000;             ///< as ekf_identifier's NEXT_POSES advisor draws them (seed 1)
  double position_sigma_m = 5.1e-5;  ///< a still window's pose, per axis [m]
  double orientation_sigma_rad = 6.1e-4;  ///< per axis [rad] (cells that measure orientation)
  int test_poses = 50;                    ///< the programme's test stops
  double settle_distance = identification::kDefaultStopCost;  ///< a stop's cost [rad]
};

/// The cell's plans, made once at the nominal (a user plans before knowing the errors).
struct CellPlans {
  /// ekf_identifier's NEXT_POSES advisor for the cell (its candidates, seed 1): the planner
  /// chooses among its candidates, and each programme's online next-best follows a copy of it.
  std::shared_ptr<const cell::NextPoseAdvisor> advisor;
  std::vector<std::vector<Eigen::VectorXd>> planned;  ///< one plan per count
  std::vector<Eigen::VectorXd> iroc;                  ///< max(counts) stops; prefixes are used
  int identifiable = 0;
  /// Predicted RMS position error over the workspace [m] (linearised at the nominal): the least
  /// any 20 stops from the candidates can give (certified), and the median of 21 draws of 50
  /// random candidates (0 when the counts lack 20 / 50).
  double bound20_rms_m = 0, random50_rms_m = 0;
};
CellPlans PlanCell(const io::BuiltCell& cell, const CellReportSettings& s);

/// Test-stop mean position error [m] against the truth, per strategy and count, for the
/// programme of `seed` (sensor_acquisition --seed): random = the programme's own stops; planned
/// and IROC = CellPlans; online next-best = the programme's stops until the identifier has started
/// (the set-up guess), then the best suggestion of cell::NextPoseAdvisor after each pose not
/// stood at before (a pose-level cell following NEXT_POSES).
std::array<std::vector<double>, 4> CellStrategyErrors(const io::BuiltCell& cell,
                                                      const cell::CellSimSpec& sim,
                                                      const CellPlans& plans,
                                                      const CellReportSettings& s, unsigned seed);

}  // namespace rcal::tool
