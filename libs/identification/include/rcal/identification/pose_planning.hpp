// Choosing the stops: which joint configurations to measure so that a calibration learns most
// about the identifiable parameters (issue 16).
//
// The model is linearised at the planning point x (the nominal, or the current estimate): stop i
// contributes the information A_i = W_iᵀ W_i, W_i = S_i^{-1/2} J_i, with J_i the identification
// Jacobian (3 position rows, or 6 rows for full poses) restricted to the base (identifiable)
// parameter set and S_i the measurement noise covariance. A prior Λ₀ = diag(1/σ²) (the cell's
// prior, weak for set-up frames) keeps the information matrix M = Λ₀ + Σ A_i invertible while
// fewer stops are chosen than parameters, so the design starts sensibly (Bayesian optimal design).
//
// Criteria (maximised):
//   D-optimal     log det M                       (volume of the parameter confidence ellipsoid)
//   task region   −tr(G M⁻¹), G = mean over task-region configurations t of J_p,tᵀ J_p,t: minus
//                 the predicted mean squared position error [m²] over the region (I-optimal)
// A stop's gain is computed by rank-r updates (r = 3 or 6), so scoring all candidates costs one
// product of the stacked candidate Jacobians with M⁻¹.
//
// PlanPoses: greedy forward selection then exchange sweeps (DETMAX-like: each chosen stop in turn
// is replaced by the best candidate when that raises the criterion) until no exchange helps.
// IrocGreedy: the comparison baseline as FIGAROH-style tools do it: greedy D-optimal additions
// only, no exchange, no physical prior (a vanishing ridge so the first, rank-deficient steps
// still rank candidates).
// NextBestPoses: online, under the running filter's covariance: the k candidates that shrink the
// predicted task-region error most per joint-space distance from the current joints.
//
// Constraints (PoseConstraints) are in the robot's base frame (the model's world ← base set to
// identity): a box the marker stays in, a minimum distance of the marker from the base origin, a
// home the joints stay near; the task region is a box in the same frame.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "rcal/kinematics/identifiability.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::identification {

/// An axis-aligned box [m].
struct Box {
  Eigen::Vector3d min = Eigen::Vector3d::Zero(), max = Eigen::Vector3d::Zero();
  bool Contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
};

/// Where the planner may send the arm (all optional). Positions in the robot's base frame [m].
struct PoseConstraints {
  std::optional<Box> tool_box;   ///< the marker (the model's position output) stays inside
  double min_base_distance = 0;  ///< [m] marker distance from the base frame origin, at least
  /// Joints kept near a home: |q_j − home_j| ≤ home_tolerance_j [rad | m]. Empty: no home.
  Eigen::VectorXd home, home_tolerance;
  /// Where accuracy matters: the task-region criterion and NextBestPoses average the predicted
  /// error over candidate configurations whose marker lies inside.
  std::optional<Box> task_region;
};

/// The marker position in the base frame [m] at joints q with the model at errors x (its
/// world ← base replaced by identity).
Eigen::Vector3d MarkerInBase(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const Eigen::VectorXd& q);

/// Whether q is inside the joint limits and satisfies `c` (the task region is not a constraint).
bool SatisfiesConstraints(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                          const Eigen::VectorXd& q, const PoseConstraints& c);

/// `count` configurations drawn uniformly inside the limits shrunk by `margin` (and inside the
/// home tolerance, when given) that satisfy `c`, from `rng`. Draws at most `max_draws`; throws
/// std::runtime_error naming the constraint that refused most draws when fewer than `count`
/// passed.
std::vector<Eigen::VectorXd> SampleCandidates(const kinematics::KinematicModel& model,
                                              const Eigen::VectorXd& x, const PoseConstraints& c,
                                              int count, std::mt19937_64& rng, double margin = 0.05,
                                              int max_draws = 1000000);

/// The candidates whose marker is inside c.task_region (empty without one).
std::vector<Eigen::VectorXd> InTaskRegion(const kinematics::KinematicModel& model,
                                          const Eigen::VectorXd& x,
                                          const std::vector<Eigen::VectorXd>& candidates,
                                          const PoseConstraints& c);

enum class PlanCriterion { kDOptimal, kTaskRegion };

struct PlanningSettings {
  kinematics::MeasurementKind kind = kinematics::MeasurementKind::kPositionOnly;
  double position_sigma_m = 5e-5;         ///< measurement noise per axis
  double orientation_sigma_rad = 8.7e-4;  ///< per axis (full pose)
  PlanCriterion criterion = PlanCriterion::kDOptimal;
  /// Prior σ of the arm's parameters [m | rad] (the cell's identifier.prior_sigma_*) and of the
  /// set-up frames' (weak: they are guessed from the data).
  double prior_sigma_length = 0.01, prior_sigma_angle = 0.035;
  double setup_sigma_length = 1.0, setup_sigma_angle = 1.0;
  int max_exchange_sweeps = 20;
  /// At most this many candidates decide the base parameter set (pivoted QR).
  int base_set_candidates = 400;
};

/// How low the task-region criterion can go with `count` stops from the candidates (see
/// PlanningProblem::TaskMeanSquaredBound).
struct DesignBound {
  double lower_m2 = 0;    ///< no `count` stops (repeats allowed) give tr(G M⁻¹) below this [m²]
  double relaxed_m2 = 0;  ///< the best relaxed design found: the bound is within [lower, relaxed]
  int iterations = 0;
};

/// A chosen set of stops.
struct PosePlan {
  std::vector<int> chosen;          ///< indices into the candidates (selection order, then swaps)
  std::vector<int> identifiable;    ///< the base parameter set planned for (model indices)
  double log_det = 0;               ///< log det of M on the base set, columns unit-scaled
  double task_mean_squared_m2 = 0;  ///< tr(G M⁻¹) [m²] (0 without task configurations)
  int exchanges = 0;                ///< swaps the exchange sweeps made
  int sweeps = 0;
};

/// The linearised planning problem over a candidate set (see the file comment).
class PlanningProblem {
 public:
  /// Linearises at x over `candidates`; `task` are configurations in the task region (may be
  /// empty: then the task-region criterion is unavailable). Throws std::invalid_argument for no
  /// candidates, joint vectors of the wrong size, or the task criterion without task poses.
  PlanningProblem(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                  std::vector<Eigen::VectorXd> candidates, const PlanningSettings& settings,
                  const std::vector<Eigen::VectorXd>& task = {});

  int size() const { return static_cast<int>(candidates_.size()); }
  const std::vector<Eigen::VectorXd>& candidates() const { return candidates_; }
  const std::vector<int>& identifiable() const { return base_; }

  /// Greedy + exchange (`exchange` false: greedy only), starting from the prior.
  PosePlan Plan(int count, bool exchange = true) const;
  /// The IROC-style baseline: greedy D-optimal, no exchange, vanishing prior.
  PosePlan IrocGreedy(int count) const;
  /// Criteria of a given selection (indices into the candidates; repeats allowed).
  PosePlan Evaluate(const std::vector<int>& chosen, bool with_prior = true) const;

  /// The information matrix M of a selection on the base set, unit-scaled columns.
  Eigen::MatrixXd Information(const std::vector<int>& chosen, bool with_prior = true) const;
  /// Gain of adding each candidate at information M for `criterion` (log-det increase, or the
  /// decrease of the task-region mean squared error [m²]).
  Eigen::VectorXd Gains(const Eigen::MatrixXd& M, PlanCriterion criterion) const;
  /// tr(G M⁻¹) [m²]: predicted mean squared position error over the task configurations.
  double TaskMeanSquared(const Eigen::MatrixXd& M) const;
  /// The least predicted mean squared task-region error [m²] any `count` stops drawn from the
  /// candidates (repeats allowed) can give under the linearised model: the approximate-design
  /// relaxation (stop i taken with weight wᵢ ≥ 0, Σ wᵢ = 1, M(w) = Λ₀ + count Σ wᵢ Aᵢ; an exact
  /// design is wᵢ = nᵢ / count) is convex, solved by Frank–Wolfe with an exact line search, and its
  /// duality gap certifies `lower_m2` at any iterate: f(w*) ≥ f(w) + minⱼ ∂ⱼf − ∇fᵀw. Stops until
  /// relaxed − lower ≤ `tolerance` · relaxed or after `max_iterations`. Needs task configurations
  /// (std::invalid_argument otherwise).
  DesignBound TaskMeanSquaredBound(int count, int max_iterations = 400,
                                   double tolerance = 0.01) const;
  /// Column scale D (base set): parameter error δx_base = D · δx_scaled.
  const Eigen::VectorXd& scale() const { return scale_; }

 private:
  PosePlan Run(int count, bool exchange, PlanCriterion criterion, const Eigen::MatrixXd& prior,
               bool with_prior) const;
  PlanningSettings settings_;
  std::vector<Eigen::VectorXd> candidates_;
  std::vector<int> base_;
  int rows_ = 3;           ///< rows per stop
  Eigen::VectorXd scale_;  ///< column norms of the candidates' Jacobian over the base set
  Eigen::MatrixXd W_;      ///< stacked weighted, scaled Jacobians (rows_ per candidate)
  Eigen::MatrixXd prior_;  ///< Λ₀, scaled
  Eigen::MatrixXd G_;      ///< task-region weight, scaled (empty: none)
};

/// tr(G P) [m²]: the predicted mean squared position error over the configurations `task` of an
/// estimate with covariance P [m², rad²] on the parameters `identified` (model indices), G the
/// mean of J_pᵀ J_p over `task` at x.
double PredictedTaskMeanSquared(const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                                const std::vector<int>& identified, const Eigen::MatrixXd& P,
                                const std::vector<Eigen::VectorXd>& task);

/// The cost of a stop in NextBestPoses' ranking, as joint-space distance [rad | m]. Chosen by
/// cross-validation: the held-out error per stop of the online next-best on random D–H arms
/// 101–104 (`rcal plan-poses-report --stop-cost`, positions only) was lowest at 100 among 2, 5,
/// 10, 30, 100 and 10⁶ (median 23.4 µm at 20 stops; 40.8 µm at 2). A cost of about a stop's time
/// (2 rad) ranks nearby stops of little gain first: a third of the joint path but 1.7× the
/// error per stop, and no better per second of cell time on the demo's cell. At 100 the ranking
/// is by gain, nearer stops winning near-ties; the joint path stays shorter than random stops'.
inline constexpr double kDefaultStopCost = 100.0;

/// One suggested next stop.
struct NextPose {
  int candidate = -1;   ///< index into the candidates
  double gain_m2 = 0;   ///< decrease of the predicted task-region mean squared error [m²]
  double distance = 0;  ///< joint-space distance from the current joints [rad | m, Euclidean]
  double score = 0;     ///< gain_m2 / (distance + settle_distance) [m² per rad]
};

/// The k candidates that shrink the predicted mean squared position error over `task` (every
/// candidate when `task` is empty) most under the parameter covariance P [m², rad²] of the
/// parameters `identified` (model indices; P is |identified| square), per joint-space distance
/// from q_now, best first. `settle_distance` [rad | m] stands for the cost of a stop itself
/// (decelerating, settling, the still window, accelerating), so a stop next to the current one
/// is not nearly free (kDefaultStopCost: how it was chosen). Candidates outside
/// the limits are skipped.
std::vector<NextPose> NextBestPoses(const kinematics::KinematicModel& model,
                                    const Eigen::VectorXd& x, const std::vector<int>& identified,
                                    const Eigen::MatrixXd& P,
                                    const std::vector<Eigen::VectorXd>& candidates,
                                    const std::vector<Eigen::VectorXd>& task,
                                    const Eigen::VectorXd& q_now, int k,
                                    const PlanningSettings& settings,
                                    double settle_distance = kDefaultStopCost);

}  // namespace rcal::identification
