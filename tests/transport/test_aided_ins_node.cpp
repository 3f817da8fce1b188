// The tracker-aided INS node over memq:// against the library run offline in sensor-time order
// (estimation::StepAfterOrientationKf after each IMU sample, each tracker sample after the first
// IMU sample at or after its stamp): a simulated tool in motion (sim/imu_stream.hpp, ENU), its
// marker 4–6 cm off the IMU tracked at 20 Hz with stamps 3 ms after the IMU's. Whatever order the
// two streams arrive in, the node's estimates are the library's, bit for bit, and close to the
// truth. Bad input is refused, counted, named, and changes nothing; without a tracker the IMU still
// goes in; a guessed tracker frame waits for the identifier's estimate.
#include "rcal/transport/aided_ins_node.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "fixture.hpp"
#include "rcal/geometry/so3.hpp"
#include "rcal/health_t.hpp"
#include "rcal/sim/draw.hpp"
#include "rcal/sim/imu_stream.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr int64_t kTrackerLagUs = 3'000;  // the tracker's stamps after the IMU's [µs]

struct Sample {
  int64_t utime;
  imu_sample_t imu;
  Eigen::Matrix3d R_EB_truth;
  int movement;
};

struct Stream {
  std::vector<Sample> imu;
  std::vector<position_sample_t> tracker;  // 20 Hz, kTrackerLagUs after an IMU stamp
};

int64_t Utime(double t_s) {
  return std::llround(t_s * 1e6);
}

// Rest, two motions with linear accelerations of 3 m/s² at up to 2 rad/s, rests between.
Stream MakeStream(std::uint64_t seed) {
  sim::ImuStreamSettings ss;
  ss.motion_segments = 2;
  ss.rest_s = 5.0;
  ss.motion_s = 10.0;
  sim::ImuStreamEffects fx;
  fx.linear_accel = 3.0;
  std::mt19937_64 rng(seed);
  const auto samples = sim::SimulateImuStream(ss, fx, rng);
  const Eigen::Vector3d r_BM_B(0.04, -0.02, 0.06);
  std::normal_distribution<double> noise(0.0, 1e-3);
  Stream s;
  for (size_t k = 0; k < samples.size(); ++k) {
    const auto& x = samples[k];
    ImuSample m;
    m.utime = Utime(x.t);
    m.gyro_B = x.gyro;
    m.f_B = x.accel;
    m.has_mag = true;
    m.m_B = 1e-6 * x.mag_uT;
    const Eigen::Matrix3d R = geometry::QuatToMatrix(x.q_WI);
    s.imu.push_back({m.utime, ToMessage(m), R, x.movement});
    // The tracker sees the marker 3 ms after this IMU stamp: the truth then, interpolated
    // between this sample and the next (position linearly, the lever arm turned by the rate).
    if (k % 5 != 0 || k + 1 >= samples.size()) continue;
    const double a = 3e-3 / (samples[k + 1].t - x.t);
    const Eigen::Vector3d p = (1 - a) * x.p_W + a * samples[k + 1].p_W;
    const Eigen::Matrix3d R_then = R * geometry::Exp(3e-3 * samples[k + 1].gyro);
    PositionSample ps;
    ps.utime = m.utime + kTrackerLagUs;
    ps.p = p + R_then * r_BM_B + sim::Draw3(noise, rng);
    ps.covariance = 1e-6 * Eigen::Matrix3d::Identity();
    s.tracker.push_back(ToMessage(ps));
  }
  return s;
}

estimation::OrientationKfSettings OkfSettings() {
  estimation::OrientationKfSettings s;
  s.earth = estimation::EarthFrame::kEnu;
  return s;
}

estimation::AidedInsSettings InsSettings() {
  estimation::AidedInsSettings s;
  s.earth = estimation::EarthFrame::kEnu;
  // Matched to the simulated IMU, as the library's own tests.
  const sim::ImuStreamSettings ss;
  s.gyro_noise_density = ss.imu.gyro_noise_density;
  s.attitude_process_noise = 1e-4;
  s.accel_noise_density = 2.0 * ss.imu.accel_noise_density;
  s.gyro_bias_random_walk = 1e-6;
  s.accel_bias_random_walk = 1e-5;
  return s;
}

// The library in sensor-time order: utime → q_EB after each IMU step (once started).
std::map<int64_t, Eigen::Vector4d> Offline(const Stream& s) {
  estimation::OrientationKf okf(OkfSettings());
  estimation::AidedIns ins(InsSettings());
  std::map<int64_t, Eigen::Vector4d> out;
  size_t next = 0;
  for (const Sample& x : s.imu) {
    const ImuSample m = *ImuFromMessage(x.imu, nullptr);
    const double t = SensorSeconds(x.utime);
    if (!okf.Update(t, m.gyro_B, m.f_B, m.m_B)) continue;
    EXPECT_TRUE(estimation::StepAfterOrientationKf(ins, okf, t, m.gyro_B, m.f_B, false));
    if (ins.initialized()) out[x.utime] = ins.q_EB();
    for (; next < s.tracker.size() && s.tracker[next].utime <= x.utime; ++next)
      EXPECT_TRUE(ins.UpdatePosition(SensorSeconds(s.tracker[next].utime),
                                     Eigen::Map<const Eigen::Vector3d>(s.tracker[next].p)));
  }
  return out;
}

struct Outputs {
  std::map<int64_t, orientation_estimate_t> orientation;
  std::vector<tool_position_estimate_t> tool;
  int duplicates = 0;
  explicit Outputs(Transport& t) {
    t.Subscribe<orientation_estimate_t>("INS_ORIENTATION", [this](const orientation_estimate_t& m) {
      if (!orientation.emplace(m.utime, m).second) ++duplicates;
    });
    t.Subscribe<tool_position_estimate_t>(
        "INS_TOOL_POSITION", [this](const tool_position_estimate_t& m) { tool.push_back(m); });
  }
};

void Drain(LcmTransport& t) {
  while (t.HandleTimeout(0) > 0) {
  }
}

// A node whose host clock stands still: the tracker, once heard, never counts as stopped.
AidedInsNode::Options StillClock() {
  AidedInsNode::Options o;
  o.steady_now_us = [] { return int64_t{0}; };
  return o;
}

// How the two streams reach the node: the tracker's samples `delay_us` of sensor time after the
// IMU sample of the same time (negative: ahead of it).
void Feed(const Stream& s, int64_t delay_us, const std::function<void(const imu_sample_t&)>& imu,
          const std::function<void(const position_sample_t&)>& position) {
  size_t next = 0;
  for (const Sample& x : s.imu) {
    for (; next < s.tracker.size() && s.tracker[next].utime + delay_us <= x.utime; ++next)
      position(s.tracker[next]);
    imu(x.imu);
  }
  for (; next < s.tracker.size(); ++next) position(s.tracker[next]);
}

TEST(AidedInsNode, AnyArrivalOrderGivesTheLibrarysEstimates) {
  const Stream s = MakeStream(1);
  const std::map<int64_t, Eigen::Vector4d> ref = Offline(s);
  ASSERT_GT(ref.size(), 2000u);
  // In time order; the tracker 80 ms late (its network), and 30 ms ahead (the IMU's).
  for (int64_t delay_us : {int64_t{0}, int64_t{80'000}, int64_t{-30'000}}) {
    SCOPED_TRACE("tracker delay " + std::to_string(delay_us) + " µs");
    LcmTransport t("memq://");
    Outputs out(t);
    AidedInsNode node(t, OkfSettings(), InsSettings(), StillClock());
    Feed(
        s, delay_us,
        [&](const imu_sample_t& m) {
          t.Publish("IMU", m);
          Drain(t);
        },
        [&](const position_sample_t& m) {
          t.Publish("POSITION", m);
          Drain(t);
        });
    EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
    EXPECT_EQ(out.duplicates, 0);
    // Every IMU sample up to the tracker's last one, and nothing else.
    const int64_t last = s.tracker.back().utime;
    size_t compared = 0;
    for (const auto& [utime, q] : ref) {
      const auto it = out.orientation.find(utime);
      if (utime > last) {
        EXPECT_EQ(it, out.orientation.end()) << utime;
        continue;
      }
      ASSERT_NE(it, out.orientation.end()) << "no INS_ORIENTATION at " << utime;
      for (int i = 0; i < 4; ++i) ASSERT_EQ(it->second.q_EI[i], q(i)) << utime;
      ++compared;
    }
    EXPECT_EQ(compared, out.orientation.size());
    // The first starts the INS; the last waits for an IMU sample the tracker has not reached.
    EXPECT_EQ(node.ins().counters().positions + node.ins().counters().position_rejected,
              static_cast<int64_t>(s.tracker.size()) - 2);
    // Against the truth in the second motion (the first parts the tilt from the accelerometer's
    // bias, as in the library's tests): the inclination, the angle between the true and the
    // estimated up axes, and the whole attitude error.
    double incl2 = 0, total2 = 0;
    int n = 0;
    for (const Sample& x : s.imu) {
      const auto it = out.orientation.find(x.utime);
      if (x.movement != 1 || x.utime < 20'000'000 || it == out.orientation.end()) continue;
      const Eigen::Vector4d q(it->second.q_EI[0], it->second.q_EI[1], it->second.q_EI[2],
                              it->second.q_EI[3]);
      const Eigen::Matrix3d R = geometry::QuatToMatrix(q);
      const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
      incl2 +=
          std::pow(std::acos(std::clamp((R * x.R_EB_truth.transpose() * z).dot(z), -1.0, 1.0)), 2);
      total2 += std::pow(geometry::AngleBetween(R, x.R_EB_truth), 2);
      ++n;
    }
    ASSERT_GT(n, 900);
    const double incl = std::sqrt(incl2 / n), total = std::sqrt(total2 / n);
    std::printf("second motion: inclination RMS %.4f°, attitude RMS %.4f° over %d samples\n",
                incl / kDeg, total / kDeg, n);
    EXPECT_LT(incl, 0.05 * kDeg);
    EXPECT_LT(total, 0.15 * kDeg);
    ASSERT_FALSE(out.tool.empty());
    const tool_position_estimate_t& last_tool = out.tool.back();
    const Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>> C(last_tool.covariance);
    EXPECT_GT(C.diagonal().minCoeff(), 0.0);
    EXPECT_LT(C.diagonal().head<3>().maxCoeff(), 1e-6);  // below the tracker's 1 mm²
  }
}

TEST(AidedInsNode, BadInputIsRefusedCountedNamedAndChangesNothing) {
  const Stream s = MakeStream(2);
  const std::map<int64_t, Eigen::Vector4d> ref = Offline(s);
  LcmTransport t("memq://");
  Outputs out(t);
  AidedInsNode node(t, OkfSettings(), InsSettings(), StillClock());
  int injected = 0;
  const auto expect_named = [&](const char* field) {
    EXPECT_NE(node.health().last_error().find(field), std::string::npos)
        << node.health().last_error();
  };
  size_t k_imu = 0;
  Feed(
      s, 0,
      [&](const imu_sample_t& m) {
        t.Publish("IMU", m);
        Drain(t);
        if (++k_imu != 1500) return;
        imu_sample_t dup = m;  // an exact duplicate
        t.Publish("IMU", dup);
        Drain(t);
        expect_named("imu_sample.utime");
        imu_sample_t no_mag = m;
        no_mag.utime += 1;
        no_mag.has_mag = false;
        t.Publish("IMU", no_mag);
        Drain(t);
        expect_named("has_mag");
        imu_sample_t nan = m;
        nan.utime += 2;
        nan.gyro[1] = NAN;
        t.Publish("IMU", nan);
        Drain(t);
        expect_named("gyro");
        const char bytes[] = "not an LCM message";
        t.PublishRaw("POSITION", bytes, sizeof bytes);
        Drain(t);
        injected += 4;
      },
      [&](const position_sample_t& m) {
        t.Publish("POSITION", m);
        Drain(t);
        if (m.utime < 15'000'000 || m.utime > 15'100'000) return;
        position_sample_t far = m;
        far.utime += 1;
        far.p[0] = 1e3;
        t.Publish("POSITION", far);
        Drain(t);
        expect_named("position_sample.p");
        injected += 1;
      });
  EXPECT_EQ(node.health().rejected(), injected);
  // Nothing refused changed anything.
  for (const auto& [utime, q] : ref) {
    const auto it = out.orientation.find(utime);
    if (it == out.orientation.end()) continue;
    for (int i = 0; i < 4; ++i) ASSERT_EQ(it->second.q_EI[i], q(i)) << utime;
  }
  EXPECT_GT(out.orientation.size(), ref.size() - 10);
}

TEST(AidedInsNode, WithoutATrackerTheImuGoesInAfterTheWait) {
  const Stream s = MakeStream(3);
  LcmTransport t("memq://");
  Outputs out(t);
  int64_t now_us = 0;
  AidedInsNode::Options o;
  o.steady_now_us = [&] { return now_us; };
  AidedInsNode node(t, OkfSettings(), InsSettings(), o);
  // No tracker yet: the IMU goes in position_wait_us behind; the INS waits for its first position.
  for (size_t k = 0; k < 300; ++k) node.OnImu(s.imu[k].imu);
  EXPECT_TRUE(node.orientation_kf().initialized());
  EXPECT_FALSE(node.ins().initialized());
  EXPECT_EQ(node.health().rejected(), 0);
  // The tracker comes: the INS starts at its first sample and publishes; the IMU now waits for it.
  size_t next = 0;
  for (size_t k = 300; k < 600; ++k) {
    for (; next < s.tracker.size() && s.tracker[next].utime <= s.imu[k].utime; ++next)
      if (s.tracker[next].utime > s.imu[299].utime) node.OnPosition(s.tracker[next]);
    node.OnImu(s.imu[k].imu);
  }
  Drain(t);
  EXPECT_TRUE(node.ins().initialized());
  EXPECT_GT(out.orientation.size(), 250u);
  // The tracker stops (no POSITION for over position_timeout_us of host time): the IMU goes on
  // alone, position_wait_us behind.
  now_us += 2'000'000;
  const size_t before = out.orientation.size();
  for (size_t k = 600; k < 900; ++k) node.OnImu(s.imu[k].imu);
  Drain(t);
  EXPECT_GT(out.orientation.size(), before + 250);
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
  // A tracker sample that comes back after the INS has gone past its step: refused, naming it.
  position_sample_t late = s.tracker[140];  // 3 ms after IMU sample 700
  ASSERT_GT(late.utime, s.tracker[next - 1].utime);
  node.OnPosition(late);
  EXPECT_NE(node.health().last_error().find("not within the last IMU step"), std::string::npos)
      << node.health().last_error();
  EXPECT_EQ(node.health().rejected(), 1);
}

// HEALTH's activity says the positions the INS refused, took as shocks or re-anchored, over the
// node's life. The tracker is re-registered twice (5 cm in x, in each motion), and the IMU is
// silent for 0.5 s at the rest between the motions, which re-initialises the INS (its own
// counters start again): the activity's counts are both stretches', the INS's the second's, and
// it says the silence.
TEST(AidedInsNode, HealthSaysThePositionsTheInsRefusedOverItsLife) {
  Stream s = MakeStream(1);  // rest 0–5 s, motion 5–15 s, rest 15–20 s, motion 20–30 s, rest
  const auto silent = [](int64_t utime) { return utime >= Utime(16.0) && utime < Utime(16.5); };
  std::erase_if(s.imu, [&](const Sample& x) { return silent(x.utime); });
  std::erase_if(s.tracker, [&](const position_sample_t& m) { return silent(m.utime); });
  for (position_sample_t& m : s.tracker)
    m.p[0] += 0.05 * ((m.utime > Utime(10.0)) + (m.utime > Utime(25.0)));
  LcmTransport t("memq://");
  AidedInsNode node(t, OkfSettings(), InsSettings(), StillClock());
  std::optional<estimation::AidedIns::Counters> before_gap;
  Feed(
      s, 0,
      [&](const imu_sample_t& m) {
        if (!before_gap && m.utime >= Utime(16.5)) before_gap = node.ins().counters();
        node.OnImu(m);
      },
      [&](const position_sample_t& m) { node.OnPosition(m); });
  ASSERT_TRUE(before_gap);
  const auto& c1 = *before_gap;
  const auto& c2 = node.ins().counters();
  EXPECT_EQ(c2.reinitialised, 1);      // the IMU's silence
  ASSERT_GE(c1.position_rejected, 3);  // each jump, refused until re-anchored
  ASSERT_GE(c2.position_rejected, 3);
  ASSERT_GE(c1.reanchored, 1);
  ASSERT_GE(c2.reanchored, 1);
  EXPECT_EQ(node.health().rejected(), 0) << node.health().last_error();
  const std::string said =
      "; positions: " + std::to_string(c1.position_rejected + c2.position_rejected) +
      " refused by the χ² gate, " + std::to_string(c1.shocks_taken + c2.shocks_taken) +
      " taken as the accelerometer's shock, " + std::to_string(c1.reanchored + c2.reanchored) +
      " re-anchored; attitude started again from the sensors after 1 IMU silence longer than "
      "0.1 s";
  const std::string& activity = node.health().activity();
  ASSERT_GE(activity.size(), said.size()) << activity;
  EXPECT_EQ(activity.substr(activity.size() - said.size()), said) << activity;
  std::printf("%s; the INS's own: %ld refused, %ld re-anchored\n", activity.c_str(),
              static_cast<long>(c2.position_rejected), static_cast<long>(c2.reanchored));
}

// A guessed tracker frame (a cell's earth_from_world: guess): positions are not used and the INS
// does not start until the identifier's first estimate of the cell's model places the frame
// (roughly: 0.6° off, σ 10 mrad); a later, better one (σ 1 mrad) adds what it learned since
// (AidedIns::UpdateWorldFromEarth); another model's estimate is counted and left, one that names
// the wrong parameters refused and named.
TEST(AidedInsNode, AGuessedFrameWaitsForTheIdentifiersEstimate) {
  const auto model = testing::OneJointWithEarthFrame();
  Eigen::VectorXd x = model->Nominal();
  x(model->FindParameter("earth_rz")) = 0.3;
  const Eigen::VectorXd sigma = Eigen::VectorXd::Constant(model->num_params(), 1e-3);
  const kinematic_params_t params =
      ToKinematicParams(*model, x, sigma, {}, "earth-robot", 1'000'000, 12);
  Eigen::VectorXd x_rough = x;
  x_rough(model->FindParameter("earth_rz")) += 0.01;
  kinematic_params_t rough =
      ToKinematicParams(*model, x_rough, Eigen::VectorXd::Constant(model->num_params(), 1e-2), {},
                        "earth-robot", 1'000'000, 5);
  kinematic_params_t wrong = params;
  wrong.names[0] = "not_a1";
  const kinematic_params_t foreign = testing::ForeignParams();

  Stream s = MakeStream(4);
  // The tracker's axes are where the identifier finds them: p_WM_W = R_WE p_EM_E.
  const Eigen::Matrix3d R_WE = model->EarthFromWorld(x).transpose();
  for (position_sample_t& m : s.tracker) {
    const Eigen::Vector3d p_W = R_WE * Eigen::Map<const Eigen::Vector3d>(m.p);
    for (int i = 0; i < 3; ++i) m.p[i] = p_W(i);
  }
  LcmTransport t("memq://");
  Outputs out(t);
  AidedInsNode::Options o = StillClock();
  o.world_from_earth_known = false;
  o.model = model;
  AidedInsNode node(t, OkfSettings(), InsSettings(), o);
  EXPECT_EQ(node.health().activity(), "R_WE: awaiting the identifier's (0 positions unused)");
  size_t k_imu = 0;
  Feed(
      s, 0,
      [&](const imu_sample_t& m) {
        node.OnImu(m);
        if (++k_imu == 300) {
          EXPECT_FALSE(node.ins().initialized());
          const kinematic_params_t* const sent[] = {&foreign, &wrong, &rough};
          for (const kinematic_params_t* p : sent) {
            t.Publish("KINEMATIC_PARAMS", *p);
            Drain(t);
          }
          EXPECT_NE(node.health().last_error().find("kinematic_params.names[0]"), std::string::npos)
              << node.health().last_error();
        }
        if (k_imu == 1000) {
          EXPECT_TRUE(node.ins().initialized());
          EXPECT_GT(geometry::AngleBetween(node.ins().R_WE(), R_WE), 2e-3);
          t.Publish("KINEMATIC_PARAMS", params);
          Drain(t);
        }
      },
      [&](const position_sample_t& m) { node.OnPosition(m); });
  EXPECT_EQ(node.positions_awaiting_frame(), 60);  // 3 s of 20 Hz before the estimate
  EXPECT_EQ(node.ignored_params(), 1);
  EXPECT_EQ(node.frame_estimates(), 2);
  EXPECT_EQ(node.ins().counters().frame_updates, 1);
  // The refined frame moved the marker: a few positions refused, said with where R_WE comes from.
  const auto& c = node.ins().counters();
  EXPECT_GT(c.position_rejected, 0);
  EXPECT_EQ(node.health().activity(),
            "R_WE: the identifier's (2 estimates; 60 positions unused before); positions: " +
                std::to_string(c.position_rejected) + " refused by the χ² gate, " +
                std::to_string(c.shocks_taken) + " taken as the accelerometer's shock, " +
                std::to_string(c.reanchored) + " re-anchored");
  EXPECT_TRUE(node.ins().initialized());
  EXPECT_LT(geometry::AngleBetween(node.ins().R_WE(), R_WE), 2e-3);
  EXPECT_EQ(node.health().rejected(), 1) << node.health().last_error();
  // Options that cannot work are refused.
  AidedInsNode::Options bad;
  bad.world_from_earth_known = false;
  EXPECT_THROW(AidedInsNode(t, OkfSettings(), InsSettings(), bad), std::invalid_argument);
}

}  // namespace
}  // namespace rcal::transport
