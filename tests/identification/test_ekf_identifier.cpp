#include "rcal/identification/ekf_identifier.hpp"

#include <gtest/gtest.h>

#include "identification_fixture.hpp"

namespace rcal::identification {
namespace {

using namespace testing;
using kinematics::testing::Grb3016;
using kinematics::testing::SevenJointSetup;
using kinematics::testing::UrLikeUrdf;

EkfIdentifier RunEkf(const Scenario& s, EkfSettings settings = {}, bool expect_all = true) {
  EkfIdentifier ekf(s.model, s.identified, settings);
  for (const auto& m : s.cal) {
    const bool accepted = ekf.Update(m).accepted;
    if (expect_all) {
      EXPECT_TRUE(accepted);
    }
  }
  return ekf;
}

void ExpectEkfMatchesTruthAndLm(const Scenario& s, const EkfIdentifier& ekf, const char* what) {
  const LmResult lm = BatchLm(s.model, s.identified).Solve(s.cal, s.model.Nominal());
  const Eigen::VectorXd x = ekf.x(), sigma = ekf.sigma();
  int beyond3 = 0;
  for (int i : s.identified) {
    const double z = (x(i) - s.x_equivalent(i)) / sigma(i);
    EXPECT_LT(std::abs(z), 4.5) << what << " " << s.model.parameters()[i].name;
    if (std::abs(z) > 3.0) ++beyond3;
    // EKF and LM agree to a small fraction of the uncertainty.
    EXPECT_LT(std::abs(x(i) - lm.x(i)), 0.25 * lm.sigma(i))
        << what << " " << s.model.parameters()[i].name;
  }
  EXPECT_LE(beyond3, 1) << what;
  EXPECT_LT(MeanTestPositionError(s, x), 1.5 * CramerRaoMeanTestPositionError(s)) << what;
}

TEST(EkfIdentifier, RecoversRandomErrorsOnThreeRobots) {
  unsigned seed = 300;
  for (const auto& model : {Grb3016(), SevenJointSetup(), UrLikeUrdf(), Ur10FromUrdf()}) {
    const Scenario s = MakeScenario(model, sim::PoseNoise{}, seed++);
    ExpectEkfMatchesTruthAndLm(s, RunEkf(s), model.name().c_str());
  }
}

TEST(EkfIdentifier, RecoversFromPositionsOnly) {
  sim::PoseNoise noise;
  noise.orientation = false;
  unsigned seed = 400;
  for (const auto& model : {Grb3016(), SevenJointSetup(), UrLikeUrdf(), Ur10FromUrdf()}) {
    const Scenario s = MakeScenario(model, noise, seed++, 60);
    ExpectEkfMatchesTruthAndLm(s, RunEkf(s), model.name().c_str());
  }
}

TEST(EkfIdentifier, CovarianceMatchesTheCramerRaoBound) {
  // With a weak prior, the EKF's P after all poses is the information of the poses: the CRB.
  const Scenario s = MakeScenario(SevenJointSetup(), sim::PoseNoise{}, 17);
  const EkfIdentifier ekf = RunEkf(s);
  const Eigen::MatrixXd C = CramerRaoBound(s.model, s.identified, s.cal, s.x_true);
  for (int i = 0; i < C.rows(); ++i)
    EXPECT_NEAR(std::sqrt(ekf.P()(i, i)) / std::sqrt(C(i, i)), 1.0, 0.05)
        << s.model.parameters()[s.identified[i]].name;
}

TEST(EkfIdentifier, PlainEkfIsWorseThanIteratedAndRelinearisedOnLargeErrors) {
  // One linearisation per pose (the paper's EKF, single pass) at degree-sized errors leaves a
  // bias no later pose removes, and its gate then rejects good poses whose innovation is mostly
  // linearisation error: the reasons for the iterated update and the relinearisation passes.
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 21, 50, 0.004, 0.03);
  EkfSettings plain;
  plain.max_iterations = 1;
  plain.relinearize_threshold = 0;
  // The paper's filter has no change test either (the test, run when the gate refuses pose after
  // pose, would release the biased parameters and retake the poses: a remedy of its own).
  plain.detect_changes = false;
  const EkfIdentifier paper = RunEkf(s, plain, /*expect_all=*/false);
  const EkfIdentifier ours = RunEkf(s);
  const double err_plain = MeanTestPositionError(s, paper.x());
  const double err_ours = MeanTestPositionError(s, ours.x());
  EXPECT_GT(err_plain, 3 * err_ours);
  EXPECT_GT(paper.rejected(), 0);
  EXPECT_EQ(ours.rejected(), 0);
  EXPECT_LT(err_ours, 1.5 * CramerRaoMeanTestPositionError(s));
}

TEST(EkfIdentifier, GateRejectsAnOutlierPoseAndCountsIt) {
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 23);
  EkfIdentifier ekf(s.model, s.identified);
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(ekf.Update(s.cal[k]).accepted);
  kinematics::PoseMeasurement bad = s.cal[30];
  bad.p_WM_W.x() += 0.005;  // a 5 mm marker glitch, 100σ
  const EkfUpdateResult r = ekf.Update(bad);
  EXPECT_FALSE(r.accepted);
  EXPECT_GT(r.nis, r.gate);
  EXPECT_NE(r.reason.find("innovation"), std::string::npos);
  EXPECT_EQ(ekf.rejected(), 1);
  for (size_t k = 30; k < s.cal.size(); ++k) ASSERT_TRUE(ekf.Update(s.cal[k]).accepted);
  EXPECT_LT(MeanTestPositionError(s, ekf.x()), 1.5 * CramerRaoMeanTestPositionError(s));
}

TEST(EkfIdentifier, InvalidInputIsRejectedWithoutTouchingTheState) {
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 25, 10);
  EkfIdentifier ekf(s.model, s.identified);
  for (const auto& m : s.cal) ekf.Update(m);
  const Eigen::VectorXd x_before = ekf.x_identified();
  const Eigen::MatrixXd P_before = ekf.P();
  struct Case {
    const char* field;
    std::function<void(kinematics::PoseMeasurement&)> corrupt;
  };
  const std::vector<Case> cases = {
      {"q:", [](auto& m) { m.q.resize(5); }},
      {"q: not finite", [](auto& m) { m.q(2) = std::nan(""); }},
      {"p_WM_W", [](auto& m) { m.p_WM_W(0) = INFINITY; }},
      {"R_EI: not a rotation", [](auto& m) { m.R_EI(0, 0) = 3; }},
      {"covariance: 3x3", [](auto& m) { m.covariance = Eigen::Matrix3d::Identity(); }},
      {"covariance: not positive", [](auto& m) { m.covariance(0, 0) = -1; }},
  };
  for (const auto& c : cases) {
    kinematics::PoseMeasurement m = s.test[0];
    c.corrupt(m);
    const EkfUpdateResult r = ekf.Update(m);
    EXPECT_FALSE(r.accepted) << c.field;
    EXPECT_NE(r.reason.find(c.field), std::string::npos) << r.reason;
  }
  EXPECT_EQ(ekf.rejected(), static_cast<int>(cases.size()));
  EXPECT_EQ(ekf.x_identified(), x_before);
  EXPECT_EQ(ekf.P(), P_before);
}

TEST(EkfIdentifier, DriftNoiseTracksAGrowingLink) {
  // Thermal growth: a2 lengthens by 0.5 mm over 300 poses. With drift noise the estimate follows;
  // without it (and without change detection, which would release a2 once the lag shows) the
  // estimate lags at the average.
  const auto model = Grb3016();
  sim::Rng rng(31);
  const auto report =
      kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 80, rng), model.Nominal(),
                                         kinematics::MeasurementKind::kFullPose);
  const int a2 = model.FindParameter("a2");
  Eigen::VectorXd x_true = sim::RandomErrors(model, rng, 0.001, 0.002);
  for (const auto& c : report.unidentifiable)
    x_true(c.dropped) = 0;  // keep the truth on the base set
  EkfSettings tracking, still;
  tracking.drift_sigma_length = 2e-5;
  still.detect_changes = false;
  EkfIdentifier constant(model, report.identifiable, still),
      drifting(model, report.identifiable, tracking);
  const int n = 300;
  const double a2_start = x_true(a2);
  for (int k = 0; k < n; ++k) {
    x_true(a2) = a2_start + 5e-4 * k / (n - 1);
    const auto q = sim::SampleJoints(model, 1, rng)[0];
    const auto m = sim::MeasurePose(model, x_true, q, sim::PoseNoise{}, rng);
    constant.Update(m);
    drifting.Update(m);
  }
  EXPECT_LT(std::abs(drifting.x()(a2) - x_true(a2)), 5e-5);
  EXPECT_GT(std::abs(constant.x()(a2) - x_true(a2)), 1.5e-4);
}

// An arm whose truth is on the base set (so a step of one parameter is a step of that parameter in
// the identified set), and poses measured from it.
struct Tracked {
  kinematics::KinematicModel model;
  std::vector<int> identified;
  Eigen::VectorXd x_true;
  std::vector<Eigen::VectorXd> test_q;
};

Tracked MakeTracked(const kinematics::KinematicModel& model, sim::Rng& rng,
                    kinematics::MeasurementKind kind) {
  const BaseSetTruth b = MakeBaseSetTruth(model, rng, kind);
  Tracked t{model, b.identified, b.x_true, {}};
  t.test_q = sim::SampleJoints(model, 50, rng);
  return t;
}

// dq: the arm's joints are at the readings plus dq (an encoder offset) [rad].
double MeanTestError(const Tracked& t, const Eigen::VectorXd& x, const Eigen::VectorXd& dq) {
  double sum = 0;
  for (const auto& q : t.test_q)
    sum += (t.model.Forward(q, x).p_WM_W - t.model.Forward(q + dq, t.x_true).p_WM_W).norm();
  return sum / t.test_q.size();
}

TEST(EkfIdentifier, AWindowAtLeastAsLongAsTheRunIsTheUnboundedFilter) {
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 41, 60);
  EkfSettings all, window;
  all.window_poses = 0;
  window.window_poses = 60;
  const EkfIdentifier a = RunEkf(s, all), b = RunEkf(s, window);
  EXPECT_EQ(a.x(), b.x());
  EXPECT_EQ(a.P(), b.P());
  EXPECT_EQ(b.window_size(), 60);
}

// WindowEvidence is the prediction-error decomposition of the window's likelihood: for the
// measurement model linearised at the estimate it equals −2 ln of the joint Gaussian of all the
// window's residuals at once, N(H (x0 − x̂), H P0 Hᵀ + R) stacked (up to the 2π constant). A
// released-change inflation the poses do not need (an unchanged arm) makes the window less
// likely: its Occam factor.
TEST(EkfIdentifier, WindowEvidenceIsTheJointLikelihoodOfTheWindowsResiduals) {
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 43, 20);
  EkfSettings settings;
  settings.detect_changes = false;
  const EkfIdentifier ekf = RunEkf(s, settings);
  const EkfCheckpoint c = ekf.Checkpoint();
  ASSERT_EQ(c.history.size(), s.cal.size());
  const auto n = static_cast<Eigen::Index>(s.identified.size());
  int rows = 0;
  for (const auto& m : c.history) rows += m.dimension();
  Eigen::VectorXd r_all(rows);
  Eigen::MatrixXd H_all(rows, n), R_all = Eigen::MatrixXd::Zero(rows, rows);
  int at = 0;
  for (const auto& m : c.history) {
    Eigen::VectorXd r;
    Eigen::MatrixXd H;
    kinematics::ResidualAndJacobian(s.model, m, ekf.x(), s.identified, r, H);
    const auto d = static_cast<Eigen::Index>(r.size());
    r_all.segment(at, d) = r;
    H_all.middleRows(at, d) = H;
    R_all.block(at, at, d, d) = m.covariance;
    at += static_cast<int>(d);
  }
  const Eigen::VectorXd mean = H_all * (c.x0 - c.x);
  const Eigen::MatrixXd Sigma = H_all * c.P0 * H_all.transpose() + R_all;
  const Eigen::LLT<Eigen::MatrixXd> llt(Sigma);
  const Eigen::VectorXd e = r_all - mean;
  const double batch =
      e.dot(llt.solve(e)) + 2 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
  EXPECT_NEAR(ekf.WindowEvidence(), batch, 1e-8 * std::abs(batch));
  std::printf("−2 ln L of %zu poses: sequential %.9g, joint %.9g\n", c.history.size(),
              ekf.WindowEvidence(), batch);
  // An inflation of σ 0.01 (m or rad) on the first parameter at pose 10, which no step needs: a
  // less likely window.
  EkfCheckpoint inflated = c;
  inflated.inflations.assign(c.history.size(), Eigen::MatrixXd());
  inflated.inflations[10] = Eigen::MatrixXd::Zero(n, n);
  inflated.inflations[10](0, 0) = 1e-4;
  EkfIdentifier other(s.model, s.identified, settings);
  other.Restore(inflated);
  other.Refine(5);
  EXPECT_GT(other.WindowEvidence(), ekf.WindowEvidence() + 5.0);
}

TEST(EkfIdentifier, FoldedPosesKeepTheirInformation) {
  // 150 poses through a window of 30: the estimate stays at the unbounded filter's (the batch
  // optimum) to a small fraction of σ, and its σ too; the window holds 30 poses.
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 43, 150);
  EkfSettings all, window;
  all.window_poses = window.window_poses = 0;
  window.window_poses = 30;
  const EkfIdentifier a = RunEkf(s, all), b = RunEkf(s, window);
  EXPECT_EQ(b.window_size(), 30);
  EXPECT_EQ(b.Checkpoint().history.size(), 30u);
  const Eigen::VectorXd sa = a.sigma(), sb = b.sigma();
  for (int i : s.identified) {
    EXPECT_LT(std::abs(a.x()(i) - b.x()(i)), 0.01 * sa(i)) << s.model.parameters()[i].name;
    EXPECT_NEAR(sb(i) / sa(i), 1.0, 1e-3) << s.model.parameters()[i].name;
  }
}

// A converged filter, then the arm changes: joint `joint` (≥ 0) reads `step` [rad] less than it
// is (an encoder swap), or else the truth's parameter `name` steps by `step` [m | rad]. The
// change is detected within 5 poses and named, and 30 poses after the step the test error is
// back near the pre-step error (the step was ~40× it): within 1.8× on this one seed (the issue's
// 1.2× is a median over seeds, measured by `rcal track --sweep`).
void ExpectStepDetected(const kinematics::KinematicModel& model, int joint, const std::string& name,
                        double step, kinematics::MeasurementKind kind, unsigned seed) {
  sim::Rng rng(seed);
  Tracked t = MakeTracked(model, rng, kind);
  sim::PoseNoise noise;
  noise.orientation = kind == kinematics::MeasurementKind::kFullPose;
  EkfIdentifier ekf(t.model, t.identified);
  Eigen::VectorXd dq = Eigen::VectorXd::Zero(t.model.num_joints());
  const auto pose = [&] {
    const Eigen::VectorXd q = sim::SampleJoints(t.model, 1, rng)[0];
    kinematics::PoseMeasurement m = sim::MeasurePose(t.model, t.x_true, q + dq, noise, rng);
    m.q = q;
    return m;
  };
  for (int k = 0; k < 300; ++k) ekf.Update(pose());
  ASSERT_EQ(ekf.status(), TrackingStatus::kConverged) << model.name();
  ASSERT_TRUE(ekf.changes().empty()) << model.name();
  const double before = MeanTestError(t, ekf.x(), dq);
  const int p = joint >= 0 ? -1 : t.model.FindParameter(name);
  if (joint >= 0)
    dq(joint) = step;
  else
    t.x_true(p) += step;
  ASSERT_TRUE(joint >= 0 || p >= 0) << name;
  int detected_at = -1;
  for (int k = 0; k < 30; ++k) {
    const EkfUpdateResult r = ekf.Update(pose());
    if (r.change && detected_at < 0) {
      detected_at = k;
      EXPECT_EQ(r.status, TrackingStatus::kChangeDetected);
      ASSERT_FALSE(r.change->parameters.empty());
      if (joint >= 0)
        EXPECT_EQ(r.change->joints[0], joint) << model.name();
      else
        EXPECT_EQ(r.change->parameters[0], p) << model.name();
      EXPECT_NEAR(r.change->step(0), step, 0.3 * std::abs(step)) << model.name();
      EXPECT_GE(r.change->onset_poses_ago, k - 1);  // the onset found within a pose
    }
  }
  EXPECT_GE(detected_at, 0) << model.name();
  EXPECT_LT(detected_at, 5) << model.name();
  EXPECT_EQ(ekf.changes().size(), 1u) << model.name();
  EXPECT_LT(MeanTestError(t, ekf.x(), dq), 1.8 * before) << model.name() << " before " << before;
  EXPECT_NE(ekf.status(), TrackingStatus::kConverging);
}

TEST(EkfIdentifier, DetectsNamesAndFollowsAJointOffsetStep) {
  // θ2 of the D–H arm is one parameter; the URDF arm's elbow offset is spread over its base set.
  ExpectStepDetected(Grb3016(), 1, "", 1e-3, kinematics::MeasurementKind::kFullPose, 51);
  ExpectStepDetected(UrLikeUrdf(), 2, "", 1e-3, kinematics::MeasurementKind::kPositionOnly, 52);
}

TEST(EkfIdentifier, DetectsNamesAndFollowsALinkLengthStep) {
  ExpectStepDetected(Grb3016(), -1, "a2", 5e-4, kinematics::MeasurementKind::kFullPose, 53);
}

// Near-twins and the second look (EkfSettings::change_naming_probability, change_second_look).
// A 0.5 mm step of d5 of the GRB3016, positions only: d5 and α5 move a marker near the wrist
// almost alike over the two to four poses a detection sees. Named by the likeliest direction
// alone, the detection names α5 in some seeds, and the release then covers the wrong direction
// until the second look (30 poses after the onset, the whole window choosing again with the onset
// known) moves it. Named by the directions that hold the step's probability, the detection
// releases both where the poses cannot tell them apart, and the second look keeps the one the
// window prefers. A rename is reported on the pose that completes change_window poses since the
// onset; without the second look every first name is kept.
TEST(EkfIdentifier, NearTwinsAreReleasedTogetherAndTheSecondLookChoosesBetweenThem) {
  const kinematics::KinematicModel model = Grb3016();
  struct Config {
    const char* name;
    double naming_probability;
    bool second_look;
    int held_at_detection = 0, alone_at_detection = 0, right_after = 0, runs = 0;
    double error = 0;
  };
  Config configs[] = {{"likeliest alone, no second look", 0.0, false},
                      {"likeliest alone, second look", 0.0, true},
                      {"alternatives, second look", 0.95, true}};
  for (unsigned seed = 60; seed < 80; ++seed) {
    for (Config& config : configs) {
      sim::Rng rng(seed);
      Tracked t = MakeTracked(model, rng, kinematics::MeasurementKind::kPositionOnly);
      sim::PoseNoise noise;
      noise.orientation = false;
      EkfSettings settings;
      settings.change_naming_probability = config.naming_probability;
      settings.change_second_look = config.second_look;
      EkfIdentifier ekf(t.model, t.identified, settings);
      const Eigen::VectorXd dq = Eigen::VectorXd::Zero(t.model.num_joints());
      const auto pose = [&] {
        return sim::MeasurePose(t.model, t.x_true, sim::SampleJoints(t.model, 1, rng)[0], noise,
                                rng);
      };
      for (int k = 0; k < 300; ++k) ekf.Update(pose());
      ASSERT_TRUE(ekf.changes().empty()) << seed;
      const int d5 = t.model.FindParameter("d5");
      t.x_true(d5) += 5e-4;
      std::optional<DetectedChange> detected;
      int reattributed_at = -1, detected_at = -1, onset = -1;
      for (int k = 0; k < 40; ++k) {
        const EkfUpdateResult r = ekf.Update(pose());
        if (r.change && detected_at < 0) {
          detected_at = k;
          onset = k - r.change->onset_poses_ago;
          detected = r.change;
        }
        if (r.reattributed) {
          EXPECT_EQ(k - r.reattributed->onset_poses_ago, onset) << seed;
          reattributed_at = k;
        }
      }
      ASSERT_TRUE(detected) << seed;
      ASSERT_GE(ekf.changes().size(), 1u) << seed;
      const DetectedChange& last = ekf.changes()[0];
      const auto holds_d5 = [&](const DetectedChange& c) {
        return std::find(c.parameters.begin(), c.parameters.end(), d5) != c.parameters.end();
      };
      ++config.runs;
      config.held_at_detection += holds_d5(*detected);
      config.alone_at_detection += detected->parameters == std::vector<int>{d5};
      config.right_after += last.parameters[0] == d5;
      config.error += MeanTestError(t, ekf.x(), dq);
      // Alternatives: most probable first, their probabilities adding up to at least 0.95.
      if (!detected->probability.empty()) {
        ASSERT_EQ(detected->probability.size(), detected->parameters.size());
        double mass = 0;
        for (size_t i = 0; i < detected->probability.size(); ++i) {
          mass += detected->probability[i];
          if (i > 0) {
            EXPECT_LE(detected->probability[i], detected->probability[i - 1]);
          }
        }
        EXPECT_GE(mass, 0.95 - 1e-9) << seed;
        EXPECT_GT(config.naming_probability, 0);
      }
      if (!config.second_look) {
        EXPECT_EQ(reattributed_at, -1) << seed;
      }
      if (reattributed_at >= 0 && ekf.changes().size() == 1) {  // the pose completing the window
        EXPECT_EQ(reattributed_at, onset + settings.change_window - 1) << seed;
      }
      std::printf(
          "seed %u, %s: detected at %d, %zu name(s), first %s; second look at %d; d5 first at the "
          "end: %d\n",
          seed, config.name, detected_at, detected->parameters.size(),
          t.model.parameters()[detected->parameters[0]].name.c_str(), reattributed_at,
          last.parameters[0] == d5);
    }
  }
  for (const Config& c : configs)
    std::printf(
        "%s: d5 held at detection %d of %d (alone %d), first after 40 poses %d; mean test error "
        "%.4f mm\n",
        c.name, c.held_at_detection, c.runs, c.alone_at_detection, c.right_after,
        c.error / c.runs * 1e3);
  const Config &none = configs[0], &look = configs[1], &both = configs[2];
  EXPECT_LE(none.held_at_detection, none.runs - 3);  // the case exists
  EXPECT_EQ(look.held_at_detection, none.held_at_detection);
  EXPECT_EQ(none.right_after, none.held_at_detection);  // no look: the first name stays
  EXPECT_GT(look.right_after, none.right_after);
  EXPECT_GT(both.held_at_detection, none.held_at_detection);
  EXPECT_GE(both.right_after, look.right_after);
  EXPECT_LT(look.error, none.error);
  EXPECT_LE(both.error, look.error);
}

// A restart between a change and its second look (the checkpoint keeps the pending look, and
// that its directions are alternatives) ends as the uninterrupted run: the same rename on the same
// pose, the same estimate. Seed 65 of the test above (its detection names α5, d5 and a third
// alternative; its second look d5 alone).
TEST(EkfIdentifier, ARestartBeforeTheSecondLookEndsAsAnUninterruptedRun) {
  sim::Rng rng(65);
  Tracked t = MakeTracked(Grb3016(), rng, kinematics::MeasurementKind::kPositionOnly);
  sim::PoseNoise noise;
  noise.orientation = false;
  std::vector<kinematics::PoseMeasurement> poses;
  for (int k = 0; k < 340; ++k) {
    if (k == 300) t.x_true(t.model.FindParameter("d5")) += 5e-4;
    poses.push_back(
        sim::MeasurePose(t.model, t.x_true, sim::SampleJoints(t.model, 1, rng)[0], noise, rng));
  }
  EkfIdentifier a(t.model, t.identified), b(t.model, t.identified);
  int renamed_a = -1, renamed_b = -1;
  for (int k = 0; k < 340; ++k) {
    if (a.Update(poses[k]).reattributed) renamed_a = k;
    if (k == 310) {  // after the detection (pose 302), before the look (329)
      ASSERT_EQ(a.changes().size(), 1u);
      const EkfCheckpoint c = a.Checkpoint();
      ASSERT_GE(c.second_look_onset, 0);
      EXPECT_GT(a.changes()[0].probability.size(), 1u);
      EXPECT_TRUE(c.second_look_alternatives);
      b.Restore(c);
    }
    if (k > 310 && b.Update(poses[k]).reattributed) renamed_b = k;
  }
  EXPECT_GE(renamed_a, 0);
  EXPECT_EQ(renamed_b, renamed_a);
  EXPECT_EQ(a.x(), b.x());
  ASSERT_EQ(b.changes().size(), 1u);  // after the restart: the renamed change
  EXPECT_EQ(b.changes()[0].parameters, a.changes()[0].parameters);
  EXPECT_EQ(t.model.parameters()[a.changes()[0].parameters[0]].name, "d5");
  EXPECT_TRUE(a.changes()[0].probability.empty());  // one direction: d5
  EXPECT_EQ(a.Checkpoint().second_look_onset, -1);  // looked at: nothing pending
}

// The arm changes before the filter has settled (joint 2 reads 1 mrad less from the 15th pose,
// status still converging). Before, the test waited for "converged", which the gate's refusals
// then never let come: every later pose refused, nothing said. Now two refusals in a row let the
// test run: the change is found within 5 poses, named (joint 2), and the filter re-converges to
// the new arm.
TEST(EkfIdentifier, AStepBeforeTheFilterSettledIsFoundOnceTheGateRefusesItsPoses) {
  sim::Rng rng(57);
  Tracked t = MakeTracked(Grb3016(), rng, kinematics::MeasurementKind::kFullPose);
  EkfSettings settings;
  settings.gate_after = 10;  // as the cell's identifier (the first poses define x)
  EkfIdentifier ekf(t.model, t.identified, settings);
  Eigen::VectorXd dq = Eigen::VectorXd::Zero(t.model.num_joints());
  const auto pose = [&] {
    const Eigen::VectorXd q = sim::SampleJoints(t.model, 1, rng)[0];
    kinematics::PoseMeasurement m = sim::MeasurePose(t.model, t.x_true, q + dq, {}, rng);
    m.q = q;
    return m;
  };
  for (int k = 0; k < 15; ++k) ekf.Update(pose());
  ASSERT_EQ(ekf.status(), TrackingStatus::kConverging);
  dq(1) = 1e-3;
  int detected_at = -1, refused = 0;
  for (int k = 0; k < 40; ++k) {
    const EkfUpdateResult r = ekf.Update(pose());
    if (!r.accepted) ++refused;
    if (r.change && detected_at < 0) {
      detected_at = k;
      EXPECT_EQ(r.change->joints[0], 1);
      EXPECT_NEAR(r.change->step(0), 1e-3, 0.3e-3);
    }
  }
  EXPECT_GE(detected_at, 0) << refused << " of 40 poses refused";
  EXPECT_LT(detected_at, 5);
  EXPECT_EQ(ekf.changes().size(), 1u);
  EXPECT_LT(refused, 5);
  EXPECT_EQ(ekf.status(), TrackingStatus::kConverged);
  EXPECT_LT(MeanTestError(t, ekf.x(), dq), 1e-4);  // the step moved the tool ~1 mm
}

TEST(EkfIdentifier, AnUnchangedArmRaisesNoChangeAndAnOutlierIsNotOne) {
  // 2000 poses of an unchanged arm (the seeded sweep `rcal track --sweep` runs 10 000 × 20), with
  // a 5 mm outlier pose now and then: the gate refuses the outliers and nothing is detected.
  sim::Rng rng(61);
  const Tracked t = MakeTracked(Grb3016(), rng, kinematics::MeasurementKind::kFullPose);
  EkfIdentifier ekf(t.model, t.identified);
  int rejected = 0;
  for (int k = 0; k < 2000; ++k) {
    auto m = sim::MeasurePose(t.model, t.x_true, sim::SampleJoints(t.model, 1, rng)[0],
                              sim::PoseNoise{}, rng);
    if (k % 250 == 249) m.p_WM_W.x() += 0.005;
    const EkfUpdateResult r = ekf.Update(m);
    EXPECT_FALSE(r.change) << "pose " << k;
    if (!r.accepted) ++rejected;
  }
  EXPECT_EQ(rejected, 8);
  EXPECT_EQ(ekf.status(), TrackingStatus::kConverged);
  EXPECT_LE(ekf.window_size(), 100);
}

TEST(EkfIdentifier, CheckpointResumesExactlyAndBadOnesAreRefused) {
  const Scenario s = MakeScenario(Grb3016(), sim::PoseNoise{}, 27, 20);
  EkfIdentifier a(s.model, s.identified), b(s.model, s.identified);
  for (int k = 0; k < 10; ++k) a.Update(s.cal[k]);
  b.Restore(a.Checkpoint());
  for (int k = 10; k < 20; ++k) {
    a.Update(s.cal[k]);
    b.Update(s.cal[k]);
  }
  EXPECT_EQ(a.x(), b.x());
  EXPECT_EQ(a.P(), b.P());
  EXPECT_EQ(b.accepted(), 20);

  EkfCheckpoint bad = a.Checkpoint();
  bad.history[4].q(0) = std::nan("");
  try {
    b.Restore(bad);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("history[4].q"), std::string::npos) << e.what();
  }
  EXPECT_EQ(a.x(), b.x());  // untouched by the refused checkpoint
  EXPECT_THROW(b.SetState(Eigen::VectorXd::Zero(3), a.P()), std::invalid_argument);
}

TEST(EkfIdentifier, KeepsTheValuesOfParametersItDoesNotEstimate) {
  const auto model = SevenJointSetup();
  sim::Rng rng(4);
  Eigen::VectorXd x_fixed = sim::RandomErrors(model, rng, 0.01, 0.02);
  EkfIdentifier ekf(model, {0, 1, 2}, {}, x_fixed);
  const Eigen::VectorXd x = ekf.x();
  for (int i = 3; i < model.num_params(); ++i) EXPECT_EQ(x(i), x_fixed(i));
  EXPECT_EQ(x(0), 0.0);
  EXPECT_THROW(EkfIdentifier(model, {0}, {}, Eigen::VectorXd::Zero(3)), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::identification
