// The filter nodes over memq:// against the library filters fed the clean stream (the truth of
// what the node must compute): the poison samples of issue 11 (utime 2^62, gyro 1e300, exact
// duplicates, a far-away position) are refused and counted, change nothing, HEALTH keeps beating
// and nothing published is non-finite; a driver that restarts is followed after resync_samples.
#include "rcal/transport/filter_nodes.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "fixture.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/health_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

constexpr int64_t kPoison = int64_t{1} << 62;
constexpr int64_t kPeriod = 10'000;  // 100 Hz [µs]

// A still IMU (ENU: specific force up, field north and down) with a small deterministic wobble.
imu_sample_t Imu(int64_t utime, int k) {
  ImuSample s;
  s.utime = utime;
  s.gyro_B = Eigen::Vector3d(1e-3 * std::sin(0.3 * k), 2e-3 * std::cos(0.2 * k), 1e-3);
  s.f_B = Eigen::Vector3d(0.01 * std::sin(0.1 * k), 0.0, 9.81);
  s.has_mag = true;
  s.m_B = Eigen::Vector3d(0.0, 20e-6, -40e-6);
  return ToMessage(s);
}

struct Outputs {
  std::vector<orientation_estimate_t> orientation;
  std::vector<tool_position_estimate_t> tool;
  std::vector<health_t> health;
  explicit Outputs(Transport& t) {
    t.Subscribe<orientation_estimate_t>(
        "ORIENTATION", [this](const orientation_estimate_t& m) { orientation.push_back(m); });
    t.Subscribe<tool_position_estimate_t>(
        "TOOL_POSITION", [this](const tool_position_estimate_t& m) { tool.push_back(m); });
    t.Subscribe<health_t>("HEALTH", [this](const health_t& m) { health.push_back(m); });
  }
};

void Drain(LcmTransport& t) {
  while (t.HandleTimeout(0) > 0) {
  }
}

TEST(OrientationKfNode, PoisonSamplesAreRefusedCountedAndChangeNothing) {
  LcmTransport t("memq://");
  Outputs out(t);
  OrientationKfNode node(t, estimation::OrientationKfSettings{});
  estimation::OrientationKf reference{estimation::OrientationKfSettings{}};
  for (int k = 0; k < 300; ++k) {
    const imu_sample_t m = Imu(k * kPeriod, k);
    node.OnImu(m);
    const ImuSample s = *ImuFromMessage(m, nullptr);
    ASSERT_TRUE(reference.Update(SensorSeconds(m.utime), s.gyro_B, s.f_B, s.m_B));
    if (k == 50) node.OnImu(Imu(kPoison, k));  // the far-future time
    if (k == 60) {
      imu_sample_t g = Imu(m.utime + 1, k);
      g.gyro[0] = 1e300;  // finite, beyond any gyro's range
      node.OnImu(g);
    }
    if (k == 70) node.OnImu(m);  // an exact duplicate
    Drain(t);
  }
  // The node's filter is the reference's, bit for bit.
  EXPECT_EQ(node.filter().q_EB(), reference.q_EB());
  EXPECT_EQ(node.filter().P(), reference.P());
  const Health& h = node.health();
  EXPECT_EQ(h.received(), 303);
  EXPECT_EQ(h.rejected(), 3) << h.last_error();
  EXPECT_EQ(h.out_of_horizon(), 1);
  EXPECT_EQ(h.duplicates(), 1);
  EXPECT_EQ(h.gaps(), 0);
  // One estimate per accepted sample, all finite, none at the poison's time.
  ASSERT_EQ(out.orientation.size(), 300u);
  for (const auto& o : out.orientation) {
    EXPECT_LT(o.utime, 300 * kPeriod);
    for (double v : o.q_EI) EXPECT_TRUE(std::isfinite(v));
  }
  // HEALTH beat at 0, 1 and 2 s of sensor time: the poison did not stop it.
  std::vector<int64_t> beats;
  for (const auto& b : out.health) beats.push_back(b.utime);
  EXPECT_EQ(beats, (std::vector<int64_t>{0, 1'000'000, 2'000'000}));
  EXPECT_EQ(out.health.back().out_of_horizon, 1);
  EXPECT_EQ(out.health.back().duplicates, 1);
}

TEST(OrientationKfNode, APoisonedFirstSampleCannotSetTheTimeBase) {
  LcmTransport t("memq://");
  Outputs out(t);
  OrientationKfNode node(t, estimation::OrientationKfSettings{});
  node.OnImu(Imu(kPoison, 0));  // no reference yet: the host-clock ceiling refuses it
  for (int k = 0; k < 50; ++k) node.OnImu(Imu(k * kPeriod, k));
  Drain(t);
  EXPECT_EQ(node.health().out_of_horizon(), 1);
  EXPECT_EQ(node.health().rejected(), 1);
  EXPECT_EQ(out.orientation.size(), 50u);
}

TEST(OrientationKfNode, ARestartedDriverIsFollowedAfterResyncSamples) {
  LcmTransport t("memq://");
  Outputs out(t);
  OrientationKfNode::Options o;
  o.time.resync_samples = 5;
  OrientationKfNode node(t, estimation::OrientationKfSettings{}, o);
  for (int k = 0; k < 100; ++k) node.OnImu(Imu(50'000'000 + k * kPeriod, k));
  // The driver starts over at 0: 4 refused, then the filter starts again at the 5th sample.
  estimation::OrientationKf reference{estimation::OrientationKfSettings{}};
  for (int k = 0; k < 100; ++k) {
    const imu_sample_t m = Imu(k * kPeriod, k);
    node.OnImu(m);
    const ImuSample s = *ImuFromMessage(m, nullptr);
    if (k >= 4) {
      ASSERT_TRUE(reference.Update(SensorSeconds(m.utime), s.gyro_B, s.f_B, s.m_B));
    }
  }
  Drain(t);
  EXPECT_EQ(node.health().resyncs(), 1);
  EXPECT_EQ(node.health().out_of_order(), 4);
  EXPECT_EQ(node.filter().q_EB(), reference.q_EB());
  EXPECT_EQ(node.filter().P(), reference.P());
  EXPECT_EQ(out.orientation.size(), 100u + 96u);
}

TEST(OrientationKfNode, GapsInTheStreamAreCounted) {
  LcmTransport t("memq://");
  OrientationKfNode node(t, estimation::OrientationKfSettings{});
  for (int k = 0; k < 100; ++k)
    if (k != 40 && k != 41 && k != 77) node.OnImu(Imu(k * kPeriod, k));
  EXPECT_EQ(node.health().gaps(), 3);
}

// An IMU silent for 0.3 s: the filter starts its attitude again from the next sample
// (OrientationKfSettings::max_step) and HEALTH's activity says so. After a restarted driver the
// filter's own count starts over; the node's is the process's life.
TEST(OrientationKfNode, HealthSaysTheImuSilencesTheFilterStartedAgainAfter) {
  LcmTransport t("memq://");
  Outputs out(t);
  OrientationKfNode::Options o;
  o.time.resync_samples = 5;
  OrientationKfNode node(t, estimation::OrientationKfSettings{}, o);
  for (int k = 0; k < 200; ++k)
    if (k < 100 || k >= 130) node.OnImu(Imu(50'000'000 + k * kPeriod, k));
  EXPECT_EQ(node.filter().counters().reinitialised, 1);
  EXPECT_EQ(node.health().activity(),
            "attitude started again from the sensors after 1 IMU silence longer than 0.1 s");
  // The driver starts over at 0 (4 refused, the filter starts again at the 5th), then falls
  // silent once more.
  for (int k = 0; k < 200; ++k)
    if (k < 100 || k >= 130) node.OnImu(Imu(k * kPeriod, k));
  Drain(t);
  EXPECT_EQ(node.health().resyncs(), 1);
  EXPECT_EQ(node.filter().counters().reinitialised, 1);
  EXPECT_EQ(node.health().activity(),
            "attitude started again from the sensors after 2 IMU silences longer than 0.1 s");
  ASSERT_FALSE(out.health.empty());
  EXPECT_EQ(out.health.back().activity, node.health().activity());
  // A sample every step, silence or not, became an estimate.
  EXPECT_EQ(out.orientation.size(), 170u + 166u);
}

TEST(ImuFromMessage, ValuesBeyondTheSensorRangeAreRefusedNamingTheField) {
  std::string error;
  imu_sample_t m = Imu(0, 0);
  m.gyro[1] = 1e300;
  EXPECT_FALSE(ImuFromMessage(m, &error));
  EXPECT_NE(error.find("imu_sample.gyro"), std::string::npos) << error;
  m = Imu(0, 0);
  m.accel[2] = -400.0;
  EXPECT_FALSE(ImuFromMessage(m, &error));
  EXPECT_NE(error.find("imu_sample.accel"), std::string::npos) << error;
  m = Imu(0, 0);
  m.mag[0] = 1.0;  // 1 T
  EXPECT_FALSE(ImuFromMessage(m, &error));
  EXPECT_NE(error.find("imu_sample.mag"), std::string::npos) << error;
  PositionSample p;
  p.p = Eigen::Vector3d(1e6, 0, 0);
  EXPECT_FALSE(PositionFromMessage(ToMessage(p), &error));
  EXPECT_NE(error.find("position_sample.p"), std::string::npos) << error;
}

// position_kf: a POSITION at 2^62 made it publish p ≈ 2.5e24 m. Refused, it changes nothing.
TEST(PositionKfNode, AFarFuturePositionIsRefusedAndNothingFarAwayIsPublished) {
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode node(t, estimation::PositionKfSettings{});
  estimation::PositionKf reference{estimation::PositionKfSettings{}};
  auto position = [](int64_t utime, int k) {
    PositionSample s;
    s.utime = utime;
    s.p = Eigen::Vector3d(1.0 + 1e-4 * std::sin(0.1 * k), 0.5, 0.2);
    s.covariance = 1e-8 * Eigen::Matrix3d::Identity();
    return ToMessage(s);
  };
  for (int k = 0; k < 200; ++k) {
    const int64_t u = k * kPeriod;
    if (k % 5 == 0) {
      const position_sample_t p = position(u, k);
      node.OnPosition(p);
      // The node applies a position once the IMU stream is orientation_wait_us (1 s) past it:
      // the last IMU sample is at 1.99 s, so the positions up to 0.99 s.
      if (u <= 990'000) {
        ASSERT_TRUE(
            reference.UpdatePosition(SensorSeconds(u), Eigen::Map<const Eigen::Vector3d>(p.p)));
      }
      if (k == 50) {
        node.OnPosition(position(kPoison, k));
        node.OnPosition(p);  // duplicate
      }
    }
    node.OnImu(Imu(u, k));  // no ORIENTATION: positions go in after orientation_wait_us
    Drain(t);
  }
  EXPECT_EQ(node.filter().p_WM_W(), reference.p_WM_W());
  EXPECT_EQ(node.health().out_of_horizon(), 1);
  EXPECT_EQ(node.health().duplicates(), 1);
  ASSERT_FALSE(out.tool.empty());
  for (const auto& m : out.tool) EXPECT_LT(Eigen::Map<const Eigen::Vector3d>(m.p).norm(), 2.0);
}

// An accelerometer sample whose orientation never comes (or comes after the filter moved on) is
// a sample the filter never uses: counted in HEALTH gaps, as missing. It was counted nowhere: a
// replay at 16x lost 8 tool updates when orientation_kf lagged by more than --orientation-wait.
TEST(PositionKfNode, AccelerometerSamplesWithoutTheirOrientationAreCountedAsMissing) {
  LcmTransport t("memq://");
  PositionKfNode node(t, estimation::PositionKfSettings{});
  for (int k = 0; k < 30; ++k) node.OnImu(Imu(k * kPeriod, k));
  EXPECT_EQ(node.health().gaps(), 0);  // waiting for their orientations
  // The first orientation is for sample 10: samples 0-9 never get theirs.
  orientation_estimate_t o{};
  o.utime = 10 * kPeriod;
  o.q_EI[0] = 1.0;
  node.OnOrientation(o);
  Drain(t);
  EXPECT_EQ(node.unpaired_accel(), 10);
  EXPECT_EQ(node.health().gaps(), 10);
  EXPECT_EQ(node.health().rejected(), 0);
}

// Imu() is level with the specific force up: an ENU earth frame.
estimation::PositionKfSettings EnuPositionKfSettings() {
  estimation::PositionKfSettings settings;
  settings.earth = estimation::EarthFrame::kEnu;
  return settings;
}

// The orientation estimate at `utime`: level (identity).
orientation_estimate_t OrientationAt(int64_t utime) {
  orientation_estimate_t o{};
  o.utime = utime;
  o.q_EI[0] = 1.0;
  return o;
}

position_sample_t PositionAt(int64_t utime, int k) {
  PositionSample s;
  s.utime = utime;
  s.p = Eigen::Vector3d(1.0 + 1e-4 * std::sin(0.1 * k), 0.5, 0.2);
  s.covariance = 1e-8 * Eigen::Matrix3d::Identity();
  return ToMessage(s);
}

// The library filter fed sample k in order (its accelerometer unless `accel` is false, level;
// the position of every fifth sample): what position_kf must equal, update for update.
struct InOrderReference {
  estimation::PositionKf kf{EnuPositionKfSettings()};
  int updates = 0;  // those that publish a TOOL_POSITION (the filter initialised)
  void Step(int k, bool accel = true) {
    const int64_t u = k * kPeriod;
    const ImuSample s = *ImuFromMessage(Imu(u, k), nullptr);
    if (accel && kf.UpdateAccel(SensorSeconds(u), s.f_B, Eigen::Matrix3d::Identity()) &&
        kf.initialized())
      ++updates;
    if (k % 5 == 0 &&
        kf.UpdatePosition(SensorSeconds(u), Eigen::Map<const Eigen::Vector3d>(PositionAt(u, k).p)))
      ++updates;
  }
};

// The lever arm (issue 17, item 2): with the IMU 10 cm from the marker the accelerometer update
// needs the body rate; position_kf gives the filter the gyro less the bias of the paired
// orientation estimate, so the node equals the library fed exactly that, update for update (fed
// the raw gyro instead it would not). An orientation whose bias is not finite is refused, named,
// and changes nothing.
TEST(PositionKfNode, TheLeverArmGetsTheGyroLessThePairedOrientationsBias) {
  estimation::PositionKfSettings settings = EnuPositionKfSettings();
  settings.lever_arm_B = Eigen::Vector3d(0.1, 0.0, -0.05);
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode node(t, settings);
  const Eigen::Vector3d bias_B(2e-3, -1e-3, 5e-4);
  auto orientation = [&](int64_t u) {
    orientation_estimate_t o = OrientationAt(u);
    for (int a = 0; a < 3; ++a) o.gyro_bias[a] = bias_B(a);
    return o;
  };
  estimation::PositionKf reference(settings), raw_gyro(settings);
  for (int k = 0; k < 300; ++k) {
    const int64_t u = k * kPeriod;
    node.OnImu(Imu(u, k));
    if (k == 150) {
      orientation_estimate_t bad = orientation(u);
      bad.gyro_bias[1] = NAN;
      node.OnOrientation(bad);
    }
    node.OnOrientation(orientation(u));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    Drain(t);
    const ImuSample s = *ImuFromMessage(Imu(u, k), nullptr);
    (void)reference.UpdateAccel(SensorSeconds(u), s.f_B, Eigen::Matrix3d::Identity(),
                                s.gyro_B - bias_B);
    (void)raw_gyro.UpdateAccel(SensorSeconds(u), s.f_B, Eigen::Matrix3d::Identity(), s.gyro_B);
    if (k % 5 == 0) {
      const Eigen::Vector3d p = Eigen::Map<const Eigen::Vector3d>(PositionAt(u, k).p);
      (void)reference.UpdatePosition(SensorSeconds(u), p);
      (void)raw_gyro.UpdatePosition(SensorSeconds(u), p);
    }
  }
  EXPECT_EQ(node.health().rejected(), 1);
  EXPECT_NE(node.health().last_error().find("orientation_estimate.gyro_bias: not finite"),
            std::string::npos)
      << node.health().last_error();
  EXPECT_EQ(node.unpaired_accel(), 0);
  EXPECT_EQ(node.filter().p_WM_W(), reference.p_WM_W());
  EXPECT_EQ(node.filter().P(), reference.P());
  EXPECT_NE(node.filter().p_WM_W(), raw_gyro.p_WM_W());
}

// position_kf --motion-model bank: the node runs estimation::PositionKfBank, and each
// TOOL_POSITION is the mixture's p, v and 6×6 covariance, update for update the library bank fed
// the same samples in order. The two models disagree here (the accelerometer says 0.01 m/s² of
// swing the positions do not show), so the mixture is neither filter.
TEST(PositionKfNode, ABankPublishesTheMixtureOfItsModels) {
  estimation::PositionKfBankSettings bank_settings;
  bank_settings.models = estimation::DefaultBankModels(EnuPositionKfSettings());
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode node(t, bank_settings, PositionKfNode::Options{});
  EXPECT_EQ(node.health().activity(), "R_WE: fixed");  // no model with an earth frame
  estimation::PositionKfBank reference(bank_settings);
  std::vector<tool_position_estimate_t> expected;
  for (int k = 0; k < 300; ++k) {
    const int64_t u = k * kPeriod;
    node.OnImu(Imu(u, k));
    node.OnOrientation(OrientationAt(u));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    Drain(t);
    const ImuSample s = *ImuFromMessage(Imu(u, k), nullptr);
    ASSERT_TRUE(
        reference.UpdateAccel(SensorSeconds(u), s.f_B, Eigen::Matrix3d::Identity(), s.gyro_B));
    if (reference.initialized()) expected.push_back(ToToolPositionEstimate(reference, u));
    if (k % 5 == 0) {
      ASSERT_TRUE(reference.UpdatePosition(SensorSeconds(u),
                                           Eigen::Map<const Eigen::Vector3d>(PositionAt(u, k).p)));
      expected.push_back(ToToolPositionEstimate(reference, u));
    }
  }
  EXPECT_EQ(node.health().rejected(), 0);
  ASSERT_EQ(out.tool.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(out.tool[i].utime, expected[i].utime);
    for (int a = 0; a < 3; ++a) {
      ASSERT_EQ(out.tool[i].p[a], expected[i].p[a]) << i;
      ASSERT_EQ(out.tool[i].v[a], expected[i].v[a]) << i;
    }
    for (int a = 0; a < 36; ++a) ASSERT_EQ(out.tool[i].covariance[a], expected[i].covariance[a]);
  }
  // The mixture, not one of its filters: their positions differ, and it is neither.
  const auto& mu = node.bank().probabilities();
  const Eigen::Map<const Eigen::Vector3d> last(out.tool.back().p);
  EXPECT_GT((node.bank().filters()[0].p_WM_W() - node.bank().filters()[1].p_WM_W()).norm(), 1e-7);
  EXPECT_NE(last, node.bank().filters()[0].p_WM_W());
  EXPECT_NE(last, node.bank().filters()[1].p_WM_W());
  EXPECT_NEAR((last - (mu[0] * node.bank().filters()[0].p_WM_W() +
                       mu[1] * node.bank().filters()[1].p_WM_W()))
                  .norm(),
              0.0, 1e-15);
}

// HEALTH's activity says, per filter of the bank, the positions it refused by its χ² gate and its
// re-initialisations, counted over the node's life. The tracker is re-registered 5 cm away in each
// of two stretches; between them every stream starts over (a restarted driver), and so do the
// filters' own counters: the activity's counts are both stretches', the filters' the second's.
TEST(PositionKfNode, HealthSaysThePositionsEachFilterRefusedOverItsLife) {
  estimation::PositionKfBankSettings bank_settings;
  bank_settings.models = estimation::DefaultBankModels(EnuPositionKfSettings());
  LcmTransport t("memq://");
  PositionKfNode::Options o;
  o.time.resync_samples = 5;
  PositionKfNode node(t, bank_settings, o);
  const auto counts = [&] {
    std::vector<std::array<int64_t, 2>> c;
    for (const auto& f : node.bank().filters())
      c.push_back({f.counters().position_rejected, f.counters().reinitialised});
    return c;
  };
  std::vector<std::array<int64_t, 2>> first;
  for (const int64_t start : {int64_t{50'000'000}, int64_t{0}}) {
    for (int k = 0; k < 400; ++k) {
      const int64_t u = start + k * kPeriod;
      node.OnImu(Imu(u, k));
      node.OnOrientation(OrientationAt(u));
      position_sample_t p = PositionAt(u, k);
      if (k >= 200) p.p[0] += 0.05;
      if (k % 5 == 0) node.OnPosition(p);
      Drain(t);
    }
    if (first.empty()) first = counts();
  }
  const auto second = counts();
  ASSERT_EQ(first.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_GE(first[i][0], 1) << "filter " << i;  // the jump was refused before it was taken
    EXPECT_GE(second[i][0], 1) << "filter " << i;
  }
  const auto said = [&](int k) {
    return std::to_string(first[0][k] + second[0][k]) + ", " +
           std::to_string(first[1][k] + second[1][k]);
  };
  EXPECT_EQ(node.health().activity(),
            "R_WE: fixed; positions (white jerk, accelerometer-driven): " + said(0) +
                " refused by the χ² gate; " + said(1) + " re-initialised");
  std::printf("%s; the filters' own: %ld, %ld refused, %ld, %ld re-initialised\n",
              node.health().activity().c_str(), static_cast<long>(second[0][0]),
              static_cast<long>(second[1][0]), static_cast<long>(second[0][1]),
              static_cast<long>(second[1][1]));
}

// The position sensor's frame (issue 17, item 2): position_kf turns accelerations by R_WE, the
// identity until the identifier's KINEMATIC_PARAMS of the cell's model place the earth frame, then
// R_EW(x)ᵀ, from the next accelerometer sample on: update for update the library filter told the
// same R_WE at the same sample, with the covariance of R_WE the message's sigmas give (three
// earth angles of 1 mrad: 1e-6 rad² per axis). Another model's estimate is ignored (counted, not
// an error); a message naming the wrong parameters, or with a NaN σ, is refused, named, and
// changes nothing.
TEST(PositionKfNode, TheIdentifiersEarthFrameTurnsTheAccelerations) {
  const auto model = testing::OneJointWithEarthFrame();
  Eigen::VectorXd x = model->Nominal();
  x(model->FindParameter("earth_rz")) = 0.87;  // the tracker turned about the vertical
  x(model->FindParameter("earth_rx")) = -0.01;
  // R_EW = Rz(yaw) Ry(pitch) Rx(roll), the builder's convention, written out independently.
  const Eigen::Matrix3d R_WE = geometry::FromRpy(-0.01, 0.0, 0.87).transpose();
  const Eigen::VectorXd sigma = Eigen::VectorXd::Constant(model->num_params(), 1e-3);
  const kinematic_params_t params =
      ToKinematicParams(*model, x, sigma, {}, "earth-robot", 1'000'000, 12);
  kinematic_params_t wrong = params;
  wrong.names[0] = "not_a1";
  kinematic_params_t nan_sigma = params;
  nan_sigma.sigmas[2] = NAN;
  const Eigen::Matrix3d C_WE = model->WorldFromEarthCovariance(x, sigma);
  EXPECT_NEAR(C_WE.trace(), 3e-6, 1e-8);
  const kinematic_params_t foreign = testing::ForeignParams();

  const estimation::PositionKfSettings settings = EnuPositionKfSettings();
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode::Options options;
  options.model = model;
  PositionKfNode node(t, settings, options);
  estimation::PositionKf reference(settings), never_told(settings);
  constexpr int kTold = 100;  // the identifier's estimate arrives before sample kTold
  EXPECT_EQ(node.health().activity(), "R_WE: the cell's, awaiting the identifier's");
  for (int k = 0; k < 300; ++k) {
    const int64_t u = k * kPeriod;
    if (k == kTold) {
      t.Publish("KINEMATIC_PARAMS", foreign);
      t.Publish("KINEMATIC_PARAMS", wrong);
      Drain(t);
      EXPECT_NE(node.health().last_error().find("kinematic_params.names[0]"), std::string::npos)
          << node.health().last_error();
      t.Publish("KINEMATIC_PARAMS", nan_sigma);
      Drain(t);
      EXPECT_NE(node.health().last_error().find("kinematic_params.sigmas"), std::string::npos)
          << node.health().last_error();
      EXPECT_EQ(node.health().activity(), "R_WE: the cell's, awaiting the identifier's");
      t.Publish("KINEMATIC_PARAMS", params);
      Drain(t);
      EXPECT_EQ(node.health().activity(), "R_WE: the identifier's (1 estimate)");
      ASSERT_TRUE(reference.SetWorldFromEarth(R_WE, C_WE).ok());
    }
    node.OnImu(Imu(u, k));
    node.OnOrientation(OrientationAt(u));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    Drain(t);
    const ImuSample s = *ImuFromMessage(Imu(u, k), nullptr);
    for (estimation::PositionKf* kf : {&reference, &never_told}) {
      (void)kf->UpdateAccel(SensorSeconds(u), s.f_B, Eigen::Matrix3d::Identity(), s.gyro_B);
      if (k % 5 == 0)
        (void)kf->UpdatePosition(SensorSeconds(u),
                                 Eigen::Map<const Eigen::Vector3d>(PositionAt(u, k).p));
    }
  }
  EXPECT_EQ(node.world_from_earth_updates(), 1);
  EXPECT_EQ(node.ignored_params(), 1);
  EXPECT_EQ(node.health().rejected(), 2);
  EXPECT_LT((node.filter().R_WE() - R_WE).norm(), 1e-15);
  EXPECT_EQ(node.filter().R_WE_covariance(), C_WE);
  EXPECT_EQ(node.filter().p_WM_W(), reference.p_WM_W());
  EXPECT_EQ(node.filter().P(), reference.P());
  EXPECT_GT((node.filter().a_W() - never_told.a_W()).norm(), 1e-4);
}

// A driver (or a replay) that stalled sends what fell due at once: 6 s of IMU and POSITION
// samples reach position_kf before orientation_kf has answered any of them. The orientation
// stream is behind, not stopped (the host clock did not move), so every update waits for its
// orientation and the result is the in-order reference, update for update. Taking IMU sensor time
// alone for the fallback (as before) applied the positions ahead and lost 118 accelerometer
// updates in a 4x replay with a 1.5 s stall.
TEST(PositionKfNode, ABurstAheadOfTheOrientationsLosesNothing) {
  LcmTransport t("memq://");
  Outputs out(t);
  int64_t now_us = 0;  // the host clock, frozen: the burst takes no time
  PositionKfNode::Options options;
  options.steady_now_us = [&] { return now_us; };
  PositionKfNode node(t, EnuPositionKfSettings(), options);
  InOrderReference reference;
  constexpr int kSamples = 700;  // 7 s at 100 Hz, positions at 20 Hz
  // The first second in step, so the orientation stream is known to be alive.
  auto in_step = [&](int k) {
    const int64_t u = k * kPeriod;
    node.OnImu(Imu(u, k));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    node.OnOrientation(OrientationAt(u));
    Drain(t);
  };
  for (int k = 0; k < 100; ++k) in_step(k);
  // Then the burst: all IMU and POSITION samples first, their orientations after.
  for (int k = 100; k < kSamples; ++k) {
    node.OnImu(Imu(k * kPeriod, k));
    if (k % 5 == 0) node.OnPosition(PositionAt(k * kPeriod, k));
  }
  for (int k = 100; k < kSamples; ++k) {
    node.OnOrientation(OrientationAt(k * kPeriod));
    Drain(t);  // memq
  }
  for (int k = 0; k < kSamples; ++k) reference.Step(k);
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
  EXPECT_EQ(node.health().gaps(), 0);
  EXPECT_EQ(node.unpaired_accel(), 0);
  EXPECT_EQ(static_cast<int>(out.tool.size()), reference.updates);
  EXPECT_EQ(node.filter().p_WM_W(), reference.kf.p_WM_W());
  EXPECT_EQ(node.filter().P(), reference.kf.P());
}

// Two senders are not ordered: the multicast copy of an IMU sample can reach position_kf after
// orientation_kf has already answered it (seen in CI: 6 of 3 599 tool updates lost at a 4x replay,
// counted only as gaps). Here every ORIENTATION, and the position of the same utime, come before
// their IMU sample: each waits for it, and the result is the in-order reference, update for update.
// Before, the orientation found nothing to pair, the next one dropped the sample, and the position
// went in ahead of the accelerometer sample of its utime.
TEST(PositionKfNode, AnOrientationAheadOfItsImuSampleWaitsForIt) {
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode node(t, EnuPositionKfSettings());
  InOrderReference reference;
  for (int k = 0; k < 300; ++k) {
    const int64_t u = k * kPeriod;
    node.OnOrientation(OrientationAt(u));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    node.OnImu(Imu(u, k));
    Drain(t);
    reference.Step(k);
  }
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
  EXPECT_EQ(node.health().gaps(), 0);
  EXPECT_EQ(node.unpaired_accel(), 0);
  ASSERT_GT(reference.updates, 300);
  EXPECT_EQ(static_cast<int>(out.tool.size()), reference.updates);
  EXPECT_EQ(node.filter().p_WM_W(), reference.kf.p_WM_W());
  EXPECT_EQ(node.filter().P(), reference.kf.P());
}

// An orientation whose IMU sample never comes (refused, or lost on the way) pairs with nothing:
// the next sample pairs with its own orientation and nothing is counted twice.
TEST(PositionKfNode, AnEarlyOrientationWhoseSampleNeverComesPairsWithNothing) {
  LcmTransport t("memq://");
  Outputs out(t);
  PositionKfNode node(t, EnuPositionKfSettings());
  InOrderReference reference;
  for (int k = 0; k < 100; ++k) {
    const int64_t u = k * kPeriod;
    node.OnOrientation(OrientationAt(u));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    if (k != 42) node.OnImu(Imu(u, k));  // sample 42 never reaches position_kf
    Drain(t);
    reference.Step(k, /*accel=*/k != 42);
  }
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
  EXPECT_EQ(node.unpaired_accel(), 0);
  EXPECT_EQ(static_cast<int>(out.tool.size()), reference.updates);
  EXPECT_EQ(node.filter().p_WM_W(), reference.kf.p_WM_W());
  EXPECT_EQ(node.filter().P(), reference.kf.P());
}

// orientation_kf stops (killed, hung): once no ORIENTATION came for orientation_timeout_us of the
// host clock, positions go in when the IMU stream is orientation_wait_us past them; before that
// they wait, however far the IMU stream runs ahead.
TEST(PositionKfNode, AStoppedOrientationStreamLetsPositionsInAfterTheTimeout) {
  LcmTransport t("memq://");
  Outputs out(t);
  int64_t now_us = 0;
  PositionKfNode::Options options;
  options.steady_now_us = [&] { return now_us; };
  PositionKfNode node(t, EnuPositionKfSettings(), options);
  for (int k = 0; k < 100; ++k) {
    const int64_t u = k * kPeriod;
    node.OnImu(Imu(u, k));
    if (k % 5 == 0) node.OnPosition(PositionAt(u, k));
    node.OnOrientation(OrientationAt(u));
    Drain(t);
  }
  const size_t before = out.tool.size();
  ASSERT_GT(before, 0u);
  // The orientations stop; 3 s of IMU and positions arrive within 0.9 s of host time.
  for (int k = 100; k < 400; ++k) {
    now_us = (k - 100) * 3'000;
    node.OnImu(Imu(k * kPeriod, k));
    if (k % 5 == 0) node.OnPosition(PositionAt(k * kPeriod, k));
  }
  Drain(t);
  EXPECT_EQ(out.tool.size(), before) << "applied while the orientation stream might be late";
  // Past the timeout, the next IMU sample lets in the positions 1 s behind it (utime ≤ 3.0 s).
  now_us = options.orientation_timeout_us + 1;
  node.OnImu(Imu(400 * kPeriod, 400));
  Drain(t);
  ASSERT_EQ(out.tool.size(), before + (300 - 100) / 5 + 1);  // positions at 1.00 … 3.00 s
  EXPECT_EQ(out.tool.back().utime, 300 * kPeriod);
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
}

}  // namespace
}  // namespace rcal::transport
