#include "track_sweep.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/identification/change_detection.hpp"
#include "rcal/identification/tracking.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::tool {

namespace {

// An arm with a truth on the base set, test joints, and a pose source whose joints may read off.
struct Run {
  const kinematics::KinematicModel& model;
  std::vector<int> identified;
  Eigen::VectorXd x_true, dq;
  std::vector<Eigen::VectorXd> test_q;
  sim::PoseNoise noise;
  sim::Rng rng;

  Run(const TrackSweepArm& arm, unsigned seed) : model(arm.model), rng(seed) {
    noise.orientation = arm.full_pose;
    const auto kind = arm.full_pose ? kinematics::MeasurementKind::kFullPose
                                    : kinematics::MeasurementKind::kPositionOnly;
    const auto report = kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 80, rng),
                                                           model.Nominal(), kind);
    identified = report.identifiable;
    x_true = sim::RandomErrors(model, rng, 0.001, 0.002);
    for (const auto& c : report.unidentifiable) x_true(c.dropped) = 0;
    dq = Eigen::VectorXd::Zero(model.num_joints());
    test_q = sim::SampleJoints(model, 50, rng);
  }
  kinematics::PoseMeasurement Pose() {
    const Eigen::VectorXd q = sim::SampleJoints(model, 1, rng)[0];
    kinematics::PoseMeasurement m = sim::MeasurePose(model, x_true, q + dq, noise, rng);
    m.q = q;  // the joints as read
    return m;
  }
  double TestError(const Eigen::VectorXd& x) const {
    double sum = 0;
    for (const auto& q : test_q)
      sum += (model.Forward(q, x).p_WM_W - model.Forward(q + dq, x_true).p_WM_W).norm();
    return sum / test_q.size();
  }
};

// The link lengths of the arm itself (not a set-up frame) in the identified set.
std::vector<int> LinkLengths(const kinematics::KinematicModel& model,
                             const std::vector<int>& identified) {
  std::vector<int> out;
  for (int i : identified) {
    const auto& p = model.parameters()[i];
    if (!p.is_angle && !kinematics::IsSetupGroup(p.group) && p.group != "tool") out.push_back(i);
  }
  return out;
}

}  // namespace

double OraclePower(double noncentrality, double false_alarm) {
  const double c = identification::ChiSquareUpperQuantileLog(std::log(false_alarm), 1.0);
  const double a = std::sqrt(std::max(noncentrality, 0.0)), b = std::sqrt(c);
  // Φ(x) = erfc(−x/√2)/2.
  auto phi = [](double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); };
  return phi(a - b) + phi(-a - b);
}

double StepNoncentrality(const kinematics::KinematicModel& model, const Eigen::VectorXd& q_before,
                         const Eigen::VectorXd& x_before, const Eigen::VectorXd& q_after,
                         const Eigen::VectorXd& x_after, double position_sigma,
                         double orientation_sigma, bool orientation) {
  const kinematics::ToolPose a = model.Forward(q_before, x_before);
  const kinematics::ToolPose b = model.Forward(q_after, x_after);
  double lambda = (b.p_WM_W - a.p_WM_W).squaredNorm() / (position_sigma * position_sigma);
  if (orientation) {
    // The rotation between the two, in the earth frame (the noise is isotropic: any frame).
    const Eigen::AngleAxisd d(b.R_EI * a.R_EI.transpose());
    lambda += d.angle() * d.angle() / (orientation_sigma * orientation_sigma);
  }
  return lambda;
}

std::vector<std::vector<int>> IndistinguishableJoints(const kinematics::KinematicModel& model,
                                                      bool full_pose) {
  constexpr double kStep = 1e-3, kTolerance = 1e-12;  // [rad], [m | rad]
  sim::Rng rng(1);
  const std::vector<Eigen::VectorXd> qs = sim::SampleJoints(model, 20, rng);
  const Eigen::VectorXd x = model.Nominal();
  const int nq = model.num_joints();
  // Whether the pose after stepping joint i by +kStep equals the one after stepping j by ±kStep.
  const auto alike = [&](int i, int j, double sign) {
    for (const Eigen::VectorXd& q : qs) {
      Eigen::VectorXd qi = q, qj = q;
      qi(i) += kStep;
      qj(j) += sign * kStep;
      const kinematics::ToolPose a = model.Forward(qi, x), b = model.Forward(qj, x);
      if ((a.p_WM_W - b.p_WM_W).norm() > kTolerance) return false;
      if (full_pose && Eigen::AngleAxisd(a.R_EI * b.R_EI.transpose()).angle() > kTolerance)
        return false;
    }
    return true;
  };
  // Alike is symmetric: each pair compared once, joints in order in each set.
  std::vector<std::vector<int>> out(static_cast<size_t>(nq));
  for (int i = 0; i < nq; ++i) {
    out[static_cast<size_t>(i)].push_back(i);
    for (int j = i + 1; j < nq; ++j)
      if (alike(i, j, 1.0) || alike(i, j, -1.0)) {
        out[static_cast<size_t>(i)].push_back(j);
        out[static_cast<size_t>(j)].push_back(i);
      }
  }
  for (std::vector<int>& set : out) std::sort(set.begin(), set.end());
  return out;
}

std::vector<TrackSweepResult> RunTrackSweep(const TrackSweepArm& arm, const TrackSweepSettings& s) {
  TrackSweepResult joint, length;
  joint.arm = length.arm = arm.name;
  joint.full_pose = length.full_pose = arm.full_pose;
  joint.kind = "joint offset";
  length.kind = "link length";
  const int nq = arm.model.num_joints();
  const std::vector<std::vector<int>> alike = IndistinguishableJoints(arm.model, arm.full_pose);
  if (s.first_seed < 0 || s.seeds < 0 || s.first_seed + s.seeds > 1000)
    throw std::invalid_argument("track sweep: seeds must lie in 0 … 999");
  for (int seed = s.first_seed; seed < s.first_seed + s.seeds; ++seed) {
    for (int kind = 0; kind < 2; ++kind) {
      TrackSweepResult& r = kind == 0 ? joint : length;
      Run run(arm, 1000u * static_cast<unsigned>(kind + 1) + static_cast<unsigned>(seed));
      identification::EkfIdentifier ekf(run.model, run.identified, s.ekf);
      for (int k = 0; k < s.converge_poses; ++k) ekf.Update(run.Pose());
      const size_t changes_before = ekf.changes().size();
      const double before = run.TestError(ekf.x());
      int joint_stepped = -1, param_stepped = -1;
      if (kind == 0) {
        joint_stepped = seed % nq;
        run.dq(joint_stepped) = s.joint_step_rad;
      } else {
        const std::vector<int> lengths = LinkLengths(run.model, run.identified);
        if (lengths.empty()) continue;
        param_stepped = lengths[seed % lengths.size()];
        run.x_true(param_stepped) += s.length_step_m;
      }
      ++r.seeds;
      int delay = -1;
      bool right = false, right_at_detection = false, right_by_another = false;
      // The stepped joint, or one no data can tell from it.
      const auto is_stepped_joint = [&](int j) {
        const std::vector<int>& a = alike[static_cast<size_t>(joint_stepped)];
        return j >= 0 && std::find(a.begin(), a.end(), j) != a.end();
      };
      std::string named, named_at_detection;
      // The oracle's noncentrality: the step's whitened signature over the poses since it.
      Eigen::VectorXd x_before = run.x_true;
      if (param_stepped >= 0) x_before(param_stepped) -= s.length_step_m;
      double lambda = 0;
      for (int k = 0; k < s.after_poses; ++k) {
        const kinematics::PoseMeasurement m = run.Pose();
        lambda += StepNoncentrality(run.model, m.q, x_before, m.q + run.dq, run.x_true,
                                    run.noise.position_sigma, run.noise.orientation_sigma,
                                    run.noise.orientation);
        if (k + 1 == s.oracle_poses)
          r.oracle_power.push_back(OraclePower(lambda, s.oracle_false_alarm));
        const identification::EkfUpdateResult u = ekf.Update(m);
        // Named at the detection, and again by the second look at it (EkfSettings::
        // change_second_look) if that comes within the poses run.
        const bool first = u.change && delay < 0;
        if (first) delay = k + 1;
        if (first || (delay > 0 && u.reattributed && ekf.changes().size() == changes_before + 1)) {
          const auto& c = first ? *u.change : *u.reattributed;
          right = kind == 0 ? (!c.joints.empty() && is_stepped_joint(c.joints[0]))
                            : (!c.parameters.empty() && c.parameters[0] == param_stepped);
          right_by_another = right && kind == 0 && c.joints[0] != joint_stepped;
          if (first) right_at_detection = right;
          if (first && !c.probability.empty()) {
            ++r.alternatives_at_detection;
            for (size_t i = 0; i < c.joints.size(); ++i)
              if (kind == 0 ? is_stepped_joint(c.joints[i]) : c.parameters[i] == param_stepped) {
                ++r.right_among_alternatives;
                break;
              }
          }
          named.clear();
          for (const std::string& n : identification::ChangeNames(run.model, c))
            named += (named.empty() ? "" : ",") + n;
          if (first) named_at_detection = named;
        }
      }
      r.stepped.push_back(kind == 0 ? run.model.joints()[joint_stepped].name
                                    : run.model.parameters()[param_stepped].name);
      r.seed_delay.push_back(delay);
      r.named.push_back(named);
      r.named_at_detection.push_back(named_at_detection);
      r.oracle_power_after.push_back(OraclePower(lambda, s.oracle_false_alarm));
      if (delay > 0 && delay <= s.oracle_poses) ++r.detected_within_oracle_poses;
      if (delay > 0) {
        ++r.detected;
        r.delays.push_back(delay);
        r.named_right += right;
        r.named_indistinguishable += right_by_another;
        r.named_right_at_detection += right_at_detection;
      }
      const double after = run.TestError(ekf.x());
      r.error_before_m.push_back(before);
      r.error_after_m.push_back(after);
      r.recovery.push_back(after / before);
    }
    // The unchanged arm: false alarms over quiet_poses; the steady state against the former
    // filter (all poses kept, no change detection) at steady_poses.
    if (s.quiet_poses > 0) {
      Run run(arm, 5000u + static_cast<unsigned>(seed));
      identification::EkfSettings former = s.ekf;
      former.window_poses = 0;
      former.detect_changes = false;
      identification::EkfIdentifier ekf(run.model, run.identified, s.ekf),
          old(run.model, run.identified, former);
      for (int k = 0; k < s.quiet_poses; ++k) {
        const kinematics::PoseMeasurement m = run.Pose();
        ekf.Update(m);
        if (k < s.steady_poses) old.Update(m);
        if (k + 1 == s.steady_poses)
          joint.steady_ratio.push_back(run.TestError(ekf.x()) / run.TestError(old.x()));
      }
      joint.false_alarms += static_cast<int>(ekf.changes().size());
      joint.quiet_poses += s.quiet_poses;
    }
  }
  return {joint, length};
}

}  // namespace rcal::tool
