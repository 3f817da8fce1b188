// The online identification of a cell file (what ekf_identifier --cell and
// `rcal calibrate --log --cell` run), fed with the still windows of its simulated counterpart
// (the truth only the simulator knows): it guesses the set-up from the first poses with no
// knowledge of the simulator and reaches what the noise allows against the truth; restored
// mid-guess or mid-run it ends where an uninterrupted run ends; bad poses are refused naming the
// field and change nothing; a cell with nothing to guess starts at once. With effects (an arm
// whose joint 2 bends under gravity and payload), each pose's context enters its update: the
// compliance is found against the simulated truth and the arm predicted where the geometry alone
// cannot; a restart from the checkpoint (contexts kept) ends where an uninterrupted run ends.
#include "rcal/cell/online_identification.hpp"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <limits>
#include <optional>

#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/identification/tracking.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::cell {
namespace {

const io::BuiltCell& DemoCell() {
  static const io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  return cell;
}

// The demo cell's simulated counterpart (config/cells/grb3016.sim.yaml) with its truth, and the
// windows of `num_cal` calibration and 30 test stops.
struct SimRun {
  Cell truth;
  Windows w;
};

const SimRun& Run50() {
  static const SimRun run = [] {
    const CellSimSpec sim = LoadCellSimSpec(RCAL_SOURCE_DIR "/config/cells/grb3016.sim.yaml");
    SimRun r{MakeSimCell(DemoCell(), sim), {}};
    RunSettings rs = SimRunSettings(DemoCell(), sim);
    rs.num_cal = 50;
    rs.num_test = 30;
    r.w = SimulateWindows(r.truth, rs);
    return r;
  }();
  return run;
}

TimedPose At(const kinematics::PoseMeasurement& z, int k) {
  return {z, 1'000'000 * (k + 1), k, {}};
}

TEST(OnlineIdentification, TheCellFileAloneReachesWhatTheNoiseAllows) {
  const SimRun& r = Run50();
  ASSERT_EQ(r.w.cal.size(), 50u);
  OnlineIdentification id(DemoCell());
  EXPECT_FALSE(id.started());  // every set-up frame of the demo cell is guessed
  // The same model as the simulator's truth cell (the cell file builds it), its rank.
  ASSERT_EQ(id.model().num_params(), r.truth.model.num_params());
  EXPECT_EQ(id.base().size(), r.truth.base.size());
  int held = 0, updates = 0;
  for (int k = 0; k < 50; ++k) {
    const auto out = id.Add(At(r.w.cal[k], k));
    EXPECT_TRUE(out.rejected.empty()) << out.rejected;
    held += out.held;
    updates += static_cast<int>(out.updates.size());
    EXPECT_EQ(out.started, k == 5);  // the sixth pose completes the guess
  }
  EXPECT_EQ(held, 6);
  EXPECT_EQ(updates, 50);
  EXPECT_EQ(id.last_pose_index(), 49);
  // Against the truth on the test stops: within 1.5× the error the noise allows (Cramér–Rao of
  // the windows' covariances at the truth), as the offline experiment reaches it.
  std::vector<Eigen::VectorXd> test_q;
  for (const auto& m : r.w.test) test_q.push_back(m.q);
  const double error =
      identification::ErrorsAgainstTruth(id.model(), id.ekf().x(), r.truth.x_true, test_q)
          .mean_position_m;
  const Eigen::MatrixXd C =
      identification::CramerRaoBound(id.model(), id.base(), r.w.cal, r.truth.x_true);
  const double cr =
      identification::PredictedMeanErrors(id.model(), id.base(), C, r.truth.x_true, test_q).first;
  std::printf("test error %.4f mm, Cramér–Rao %.4f mm\n", error * 1e3, cr * 1e3);
  EXPECT_LT(error, 1.5 * cr);
  // The start was the set-up guess: the frames within centimetres and degrees of the truth.
  for (int i : DemoCell().Guessed()) {
    const auto& P = id.model().parameters()[i];
    EXPECT_NEAR(id.start()(i), r.truth.x_true(i), P.is_angle ? 0.05 : 0.05) << P.name;
  }
}

TEST(OnlineIdentification, RestoredDuringTheGuessOrAfterEndsAsAnUninterruptedRun) {
  const SimRun& r = Run50();
  OnlineIdentification ref(DemoCell());
  for (int k = 0; k < 20; ++k) ref.Add(At(r.w.cal[k], k));
  for (const int stop : {3, 12}) {  // 3: three poses held; 12: the EKF running
    OnlineIdentification a(DemoCell());
    for (int k = 0; k < stop; ++k) a.Add(At(r.w.cal[k], k));
    EXPECT_EQ(a.started(), stop >= 6);
    EXPECT_EQ(a.held().size(), stop >= 6 ? 0u : static_cast<size_t>(stop));
    OnlineIdentification b(DemoCell());
    b.Restore(a.ekf().Checkpoint(), a.held(), a.last_utime(), a.last_pose_index());
    // The last pose again (a replay after the restart): refused by time, nothing changes.
    const auto again = b.Add(At(r.w.cal[stop - 1], stop - 1));
    EXPECT_NE(again.rejected.find("pose_measurement.utime"), std::string::npos) << again.rejected;
    for (int k = stop; k < 20; ++k) b.Add(At(r.w.cal[k], k));
    EXPECT_EQ(b.ekf().x(), ref.ekf().x()) << "stopped after " << stop;
    EXPECT_EQ(b.start(), ref.start()) << "stopped after " << stop;
  }
  // Held poses cannot be restored into a cell that guesses nothing.
  OnlineIdentification poses(io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml"));
  OnlineIdentification a(DemoCell());
  a.Add(At(r.w.cal[0], 0));
  EXPECT_THROW(poses.Restore(poses.ekf().Checkpoint(), a.held(), 1, 0), std::runtime_error);
}

TEST(OnlineIdentification, BadPosesAreRefusedNamingTheFieldAndChangeNothing) {
  const SimRun& r = Run50();
  OnlineIdentification id(DemoCell());
  for (int k = 0; k < 8; ++k) id.Add(At(r.w.cal[k], k));
  const Eigen::VectorXd x = id.ekf().x();
  auto nan = At(r.w.cal[8], 8);
  nan.z.q(2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(id.Add(nan).rejected, "q: not finite");
  auto short_q = At(r.w.cal[8], 8);
  short_q.z.q.conservativeResize(5);
  EXPECT_NE(id.Add(short_q).rejected.find("q: 5 joints"), std::string::npos);
  auto early = At(r.w.cal[8], 2);  // sensor time before the last pose
  EXPECT_NE(id.Add(early).rejected.find("not after the last pose"), std::string::npos);
  auto marker = At(r.w.cal[8], 8);
  marker.z.marker = 3;  // the demo cell has one marker
  EXPECT_NE(id.Add(marker).rejected.find("marker: slot 3"), std::string::npos);
  EXPECT_EQ(id.ekf().x(), x);
  EXPECT_EQ(id.last_pose_index(), 7);
}

// The pose-level cell (config/cells/grb3016_poses.yaml: the tool frame measured in the base
// frame, every set-up frame fixed): the arm's identifiable set (25 for the GRB3016 with the D–H
// tool, full poses), the EKF from the first pose at the drawing.
TEST(OnlineIdentification, ACellWithNothingToGuessStartsAtOnce) {
  OnlineIdentification id(io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml"));
  EXPECT_TRUE(id.started());
  EXPECT_EQ(id.model().num_params(), 28);  // 4(N+1): the set-up frames are fixed, no parameters
  EXPECT_EQ(id.base().size(), 25u);
  sim::Rng rng(9);
  const auto& m = id.model();
  const auto ms = sim::MeasurePoses(m, sim::Table3Errors(m), sim::SampleJoints(m, 3, rng), {}, rng);
  const auto out = id.Add(At(ms[0], 0));
  EXPECT_FALSE(out.held);
  ASSERT_EQ(out.updates.size(), 1u);
  EXPECT_TRUE(out.updates[0].result.accepted);
  EXPECT_GT(out.updates[0].max_step_sigma, 0.0);
}

// The poses the gate refuses are kept for Window() (the discrepancy watch's evidence) between the
// accepted ones, but bounded: an arm the gate refuses pose after pose must not grow it without
// end. After 40 accepted poses, 300 the gate refuses (the marker 0.3 m off: a tracker that locked
// on another reflector): the window holds the 40 accepted poses and at most max(40, 100) refused
// ones, the newest; the next good pose is accepted and the window still ends with it.
TEST(OnlineIdentification, TheRefusedPosesKeptForTheWindowAreBounded) {
  OnlineIdentification id(io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml"));
  sim::Rng rng(11);
  const auto& m = id.model();
  const auto ms =
      sim::MeasurePoses(m, sim::Table3Errors(m), sim::SampleJoints(m, 341, rng), {}, rng);
  int k = 0;
  for (; k < 40; ++k) ASSERT_TRUE(id.Add(At(ms[k], k)).updates.at(0).result.accepted) << k;
  int refused = 0;
  for (; k < 340; ++k) {
    TimedPose bad = At(ms[k], k);
    bad.z.p_WM_W.x() += 0.3;
    const auto out = id.Add(bad);
    ASSERT_EQ(out.updates.size(), 1u);
    refused += !out.updates[0].result.accepted;
    const auto window = id.Window();
    const size_t accepted = id.ekf().history().size();
    EXPECT_LE(window.size(), accepted + std::max<size_t>(accepted, 100)) << "pose " << k;
    EXPECT_EQ(window.back().pose_index, k);
  }
  EXPECT_EQ(refused, 300);
  EXPECT_EQ(id.ekf().history().size(), 40u);
  const auto window = id.Window();
  ASSERT_EQ(window.size(), 40u + 100u);
  // The window's own 40 first, then the newest 100 refused (before, the bound dropped the oldest
  // entries whatever they were: the accepted poses went first and the window lost its start).
  for (size_t i = 0; i < window.size(); ++i)
    EXPECT_EQ(window[i].pose_index,
              i < 40 ? static_cast<int64_t>(i) : static_cast<int64_t>(200 + i))
        << "entry " << i;
  const auto out = id.Add(At(ms[340], 340));
  EXPECT_TRUE(out.updates.at(0).result.accepted);
  EXPECT_EQ(id.Window().back().pose_index, 340);
  EXPECT_LE(id.Window().size(), 41u + 100u);
}

// A change released inside the window is a step of its geometry (what the discrepancy watch fits
// around): joint 2 of the pose-level cell reads 1 mrad off from pose 30 on (an encoder swapped).
// Before the detection the window has no step; at it, one, at the onset's place in Window(), along
// the direction the identifier released (DetectedChange::directions, in the full parameter
// vector).
TEST(OnlineIdentification, AReleasedChangeIsAStepOfTheWindow) {
  OnlineIdentification id(io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml"));
  sim::Rng rng(12);
  const auto& m = id.model();
  auto ms = sim::MeasurePoses(m, sim::Table3Errors(m), sim::SampleJoints(m, 60, rng), {}, rng);
  for (size_t k = 30; k < ms.size(); ++k) ms[k].q(1) += 1e-3;
  std::optional<identification::DetectedChange> change;
  int detected_at = -1;
  for (int k = 0; k < 60 && !change; ++k) {
    for (const auto& u : id.Add(At(ms[k], k)).updates)
      if (u.result.change) {
        change = u.result.change;
        detected_at = k;
      }
    if (!change) {
      EXPECT_TRUE(id.WindowSteps().empty()) << k;
    }
  }
  ASSERT_TRUE(change.has_value());
  const auto steps = id.WindowSteps();
  ASSERT_EQ(steps.size(), 1u);
  const auto window = id.Window();
  ASSERT_LT(steps[0].first_pose, static_cast<int>(window.size()));
  const int64_t onset = window[steps[0].first_pose].pose_index;
  EXPECT_EQ(onset, detected_at - change->onset_poses_ago);
  EXPECT_GE(onset, 30);
  EXPECT_LE(onset, 32);
  // The same span: each released direction (geometric rows, full length) lies in the step's.
  const auto& identified = id.ekf().identified();
  const Eigen::MatrixXd& D = steps[0].directions;
  ASSERT_EQ(D.cols(), change->directions.cols());
  const Eigen::MatrixXd Q =
      D.householderQr().householderQ() * Eigen::MatrixXd::Identity(D.rows(), D.cols());
  for (int c = 0; c < change->directions.cols(); ++c) {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(m.num_params());
    for (size_t r = 0; r < identified.size(); ++r) u(identified[r]) = change->directions(r, c);
    EXPECT_LT((u - Q * (Q.transpose() * u)).norm(), 1e-9 * u.norm()) << c;
  }
  std::printf("detected at pose %d, a step from pose %lld along %s\n", detected_at,
              static_cast<long long>(onset), identification::ChangeNames(m, *change)[0].c_str());
}

// The pose-level cell (a 6-DoF tracker on the GRB3016, nothing to guess) whose joint 2 bends by
// c·τ (joint_compliance, c = 2e-6 rad/(N·m), τ its gravity torque with a payload of 0, 5 or
// 10 kg): stops at random joints, each with its context as a live simulator publishes it
// (sim::StopContext: approach direction, payload, warming temperature, time).
TEST(OnlineIdentification, WithEffectsEachPoseTakesItsContextAndTheEffectIsFound) {
  const io::BuiltCell cell = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml");
  const CellSimSpec sim = LoadCellSimSpec(RCAL_SOURCE_DIR "/config/cells/grb3016_poses.sim.yaml");
  const Eigen::VectorXd x_true = TrueErrors(cell, sim);
  const sim::TruthEffect compliance = sim::ParseEffectSpec("joint_compliance:j2=2e-6", cell.model);
  const sim::EffectTruth truth = sim::MakeEffectTruth(cell.model, {compliance});
  sim::PoseNoise noise;
  noise.position_sigma = cell.spec.position.sigma.maxCoeff();
  noise.orientation_sigma = cell.spec.position.orientation_sigma;
  sim::Rng rng(71), context_rng(72);
  const sim::SessionSettings session;
  std::vector<TimedPose> cal, test;
  Eigen::VectorXd q_before;
  const auto qs = sim::SampleJoints(cell.model, 110, rng);
  for (int k = 0; k < 110; ++k) {
    const auto c = sim::StopContext(10.0 * k, qs[k], q_before, session, context_rng);
    q_before = qs[k];
    const auto z = sim::MeasurePoseWithEffects(truth, x_true, qs[k], c, noise, rng);
    (k < 60 ? cal : test).push_back({z, 1'000'000 * (k + 1), k, c});
  }
  OnlineIdentification geometric(cell);
  OnlineIdentification extended(cell, {compliance.effect});
  ASSERT_EQ(extended.ekf().num_effect_params(), 1);
  for (const auto& p : cal) {
    EXPECT_TRUE(geometric.Add(p).rejected.empty());
    const auto out = extended.Add(p);
    ASSERT_TRUE(out.rejected.empty()) << out.rejected;
    ASSERT_EQ(out.updates.size(), 1u);
    EXPECT_TRUE(out.updates[0].result.accepted) << out.updates[0].result.reason;
  }
  // The compliance within 3σ of the truth, and σ small enough to tell it from 0.
  const double c = extended.ekf().e()(0), sigma = extended.ekf().sigma_e()(0);
  std::printf("joint 2 compliance %.4g ± %.2g rad/(N·m) (truth 2e-6)\n", c, sigma);
  EXPECT_NEAR(c, 2e-6, 3 * sigma);
  EXPECT_LT(sigma, 2e-6 / 5);
  // Where the arm really is at the test stops (the truth, without noise): the extended estimate
  // predicts it under each stop's context; the geometric one cannot follow the payload.
  const auto error = [&](const OnlineIdentification& id) {
    double sum = 0;
    for (const auto& p : test) {
      const Eigen::Vector3d p_true = truth.model.Forward(p.z.q, p.context, x_true, truth.e).p_WM_W;
      const Eigen::VectorXd e = id.ekf().e();
      const Eigen::Vector3d p_est =
          e.size() > 0 ? id.ekf().extended_model().Forward(p.z.q, p.context, id.ekf().x(), e).p_WM_W
                       : id.model().Forward(p.z.q, id.ekf().x()).p_WM_W;
      sum += (p_true - p_est).norm();
    }
    return sum / static_cast<double>(test.size());
  };
  const double e_geo = error(geometric), e_ext = error(extended);
  std::printf("test error: geometric %.4f mm, with the effect %.4f mm\n", e_geo * 1e3, e_ext * 1e3);
  EXPECT_LT(e_ext, 0.5 * e_geo);
  EXPECT_LT(e_ext, noise.position_sigma);
  // Restarted after 30 poses from the checkpoint (contexts and all): the same end, bit for bit.
  OnlineIdentification first(cell, {compliance.effect});
  for (int k = 0; k < 30; ++k) first.Add(cal[k]);
  const identification::EkfCheckpoint checkpoint = first.ekf().Checkpoint();
  ASSERT_EQ(checkpoint.contexts.size(), checkpoint.history.size());
  OnlineIdentification resumed(cell, {compliance.effect});
  resumed.Restore(checkpoint, {}, first.last_utime(), first.last_pose_index());
  for (int k = 30; k < 60; ++k) resumed.Add(cal[k]);
  EXPECT_EQ(resumed.ekf().state(), extended.ekf().state());
  // A context that cannot be (a dq_sign of 2) is refused naming the field, and changes nothing.
  TimedPose bad = test[0];
  bad.context.dq_sign(1) = 2;
  const auto refused = extended.Add(bad);
  ASSERT_EQ(refused.updates.size(), 1u);
  EXPECT_FALSE(refused.updates[0].result.accepted);
  EXPECT_NE(refused.updates[0].result.reason.find("dq_sign"), std::string::npos)
      << refused.updates[0].result.reason;
  EXPECT_EQ(extended.ekf().state(), resumed.ekf().state());
}

}  // namespace
}  // namespace rcal::cell
