// services/ros2_input/ros2_input: the ROS 2 drivers' samples into the pipeline's events — joints
// by name, the magnetometer paired with the IMU, one time order out of several drivers, every bad
// sample counted, a restarted driver re-synchronised.
#include "ros2_input.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "rcal/io/cell_yaml.hpp"

namespace rcal::ros2 {
namespace {

io::BuiltCell DemoCell() {
  return io::LoadCell(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
}

joint_state_t Joints(const io::BuiltCell& cell, int64_t utime, double q0 = 0.1) {
  joint_state_t js;
  js.utime = utime;
  js.num_joints = cell.model.num_joints();
  js.names = cell.ros2_joint_names;
  for (int i = 0; i < js.num_joints; ++i) {
    js.q.push_back(q0 * (i + 1));
    js.dq.push_back(0.0);
  }
  return js;
}

dds::Sample<dds::JointState> RosJoints(const io::BuiltCell& cell, int64_t utime,
                                       std::vector<int> order = {}) {
  std::string error;
  auto s = dds::ToRos(Joints(cell, utime), order, "", &error);
  EXPECT_TRUE(s) << error;
  return std::move(*s);
}

dds::Sample<dds::Imu> RosImu(int64_t utime, const char* frame = "imu_link") {
  transport::ImuSample s;
  s.utime = utime;
  s.gyro_B = {0.01, 0.02, -0.03};
  s.f_B = {0.1, 0.2, 9.8};
  std::string error;
  return std::move(*dds::ToRos(s, frame, &error));
}

dds::Sample<dds::PointStamped> RosPoint(int64_t utime, double x = 1.0) {
  transport::PositionSample p;
  p.utime = utime;
  p.p = {x, 0.2, 0.3};
  std::string error;
  return std::move(*dds::ToRosPoint(p, "tracker", &error));
}

int64_t Utime(const sensors::SensorEvent& e) {
  return sensors::Utime(e);
}

class Ros2InputTest : public ::testing::Test {
 protected:
  Ros2InputTest() : cell_(DemoCell()), health_("ros2_input") {
    settings_ = FromCell(cell_);
    settings_.estimate_clock_offsets = false;  // one clock: these tests are about the rest
    settings_.reorder_delay = 0.05;
  }
  io::BuiltCell cell_;
  Ros2InputSettings settings_;
  transport::Health health_;
};

TEST_F(Ros2InputTest, SettingsComeFromTheCell) {
  EXPECT_EQ(settings_.joint_topic, "/joint_states");
  EXPECT_EQ(settings_.imu_topic, "/imu/data");
  EXPECT_EQ(settings_.mag_topic, "/imu/mag");
  ASSERT_EQ(settings_.positions.size(), 1u);
  EXPECT_EQ(settings_.positions[0].topic, "/tracker/point");
  EXPECT_EQ(settings_.positions[0].frame_id, "tracker");
  // The cell's σ = 0.5 mm per axis.
  EXPECT_DOUBLE_EQ(settings_.position_covariance(1, 1), 2.5e-7);
  EXPECT_EQ(settings_.position_covariance(0, 1), 0.0);
  io::BuiltCell ur10 = io::LoadCell(RCAL_SOURCE_DIR "/config/cells/ur10.yaml");
  EXPECT_THROW(FromCell(ur10), std::runtime_error);  // no ros2: section
}

TEST_F(Ros2InputTest, EventsLeaveInOneTimeOrderAfterTheReorderDelay) {
  Ros2Input in(settings_, cell_.model, health_);
  // Joints in a shuffled order, at 0.100 s; the tracker's sample of 0.095 s arrives after them.
  in.OnJointState(RosJoints(cell_, 100'000, {5, 3, 1, 0, 2, 4}).get());
  in.OnPoint(0, RosPoint(95'000).get());
  EXPECT_TRUE(in.Ready().empty());  // newer than the delay (50 ms here)
  in.OnJointState(RosJoints(cell_, 160'000).get());
  const auto out = in.Ready();
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(Utime(out[0]), 95'000);
  ASSERT_TRUE(std::holds_alternative<transport::PositionSample>(out[0]));
  EXPECT_EQ(std::get<transport::PositionSample>(out[0]).marker_id, 0);
  ASSERT_TRUE(std::holds_alternative<joint_state_t>(out[1]));
  const auto& js = std::get<joint_state_t>(out[1]);
  EXPECT_EQ(js.names, cell_.ros2_joint_names);  // chain order again
  EXPECT_DOUBLE_EQ(js.q[2], 0.3);
  // A sample older than what left: late, counted, dropped.
  in.OnPoint(0, RosPoint(99'000).get());
  EXPECT_EQ(in.late(), 1);
  EXPECT_EQ(health_.rejected(), 1);
  EXPECT_NE(health_.last_error().find("reorder delay"), std::string::npos);
  const auto rest = in.Ready(true);
  ASSERT_EQ(rest.size(), 1u);
  EXPECT_EQ(Utime(rest[0]), 160'000);
}

TEST_F(Ros2InputTest, TheImuCarriesTheLatestMagnetometerReading) {
  Ros2Input in(settings_, cell_.model, health_);
  std::string error;
  in.OnImu(RosImu(10'000).get());  // no reading yet
  auto mag = dds::ToRos(dds::MagReading{15'000, {2e-5, 0, 4e-5}}, "imu_link", &error);
  in.OnMagneticField(mag->get());
  in.OnImu(RosImu(20'000).get());
  in.OnImu(RosImu(200'000).get());  // 185 ms after the reading: too old
  const auto out = in.Ready(true);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_FALSE(std::get<transport::ImuSample>(out[0]).has_mag);
  const auto& paired = std::get<transport::ImuSample>(out[1]);
  EXPECT_TRUE(paired.has_mag);
  EXPECT_EQ(paired.m_B, Eigen::Vector3d(2e-5, 0, 4e-5));
  EXPECT_FALSE(std::get<transport::ImuSample>(out[2]).has_mag);
  EXPECT_EQ(in.mag_paired(), 1);
}

TEST_F(Ros2InputTest, BadSamplesAreCountedNamedAndNeverStopTheStream) {
  Ros2Input in(settings_, cell_.model, health_);
  auto nan_joints = RosJoints(cell_, 10'000);
  nan_joints.get().position._buffer[1] = std::numeric_limits<double>::quiet_NaN();
  in.OnJointState(nan_joints.get());
  EXPECT_EQ(health_.rejected(), 1);
  EXPECT_EQ(health_.last_error(), "/joint_states.position[1] (j2): NaN");
  in.OnImu(RosImu(10'000, "base_link").get());
  EXPECT_EQ(health_.last_error(),
            "/imu/data.header.frame_id: 'base_link' is not the cell's 'imu_link'");
  auto far = RosPoint(10'000, 5e3);  // 5 km
  in.OnPoint(0, far.get());
  EXPECT_EQ(health_.rejected(), 3);
  // A duplicate and an out-of-order joint stamp: refused by the stream's time gate.
  in.OnJointState(RosJoints(cell_, 20'000).get());
  in.OnJointState(RosJoints(cell_, 20'000).get());
  in.OnJointState(RosJoints(cell_, 19'000).get());
  EXPECT_EQ(health_.duplicates(), 1);
  EXPECT_EQ(health_.out_of_order(), 1);
  // The good ones went through.
  in.OnJointState(RosJoints(cell_, 30'000).get());
  EXPECT_EQ(in.Ready(true).size(), 2u);
  EXPECT_EQ(health_.received(), 7);
}

TEST_F(Ros2InputTest, ARestartedDriverIsResynchronisedAndItsClockEstimatedAnew) {
  Ros2Input in(settings_, cell_.model, health_);
  for (int k = 0; k < 10; ++k) in.OnImu(RosImu(500'000'000 + k * 10'000).get());
  // The IMU driver restarts: its clock starts again near 0 (time since its boot).
  for (int k = 0; k < 10; ++k) in.OnImu(RosImu(2'000'000 + k * 10'000).get());
  EXPECT_EQ(health_.resyncs(), 1);
  const auto clocks = in.Clocks();
  ASSERT_EQ(clocks.size(), 2u);
  EXPECT_EQ(clocks[0].source, "imu");
  EXPECT_EQ(clocks[0].resets, 1);
  EXPECT_EQ(clocks[1].resets, 0);
  EXPECT_EQ(clocks[0].state, ClockState::kFixed);  // clock_offsets: none
}

dds::Sample<dds::Temperature> RosTemperature(int64_t utime, double celsius) {
  transport::ArmConditions c;
  c.utime = utime;
  c.temperature_c = celsius;
  std::string error;
  return std::move(*dds::ToRos(c, 0.09, "arm", &error));
}

// The conditions among events, in their order.
std::vector<transport::ArmConditions> ConditionsIn(
    const std::vector<sensors::SensorEvent>& events) {
  std::vector<transport::ArmConditions> out;
  for (const auto& e : events)
    if (const auto* c = std::get_if<transport::ArmConditions>(&e)) out.push_back(*c);
  return out;
}

TEST_F(Ros2InputTest, TheArmsTemperatureBecomesArmConditionsOnTheArmsClock) {
  EXPECT_EQ(settings_.temperature_topic, "/arm/temperature");
  // clock_offsets none: the drivers share the joints' clock, the report keeps its stamp.
  Ros2Input in(settings_, cell_.model, health_);
  EXPECT_TRUE(in.OnTemperature(RosTemperature(2'000'000, 24.5).get()));
  // A duplicate, one out of order, and kelvin: refused, counted, named.
  EXPECT_FALSE(in.OnTemperature(RosTemperature(2'000'000, 24.5).get()));
  EXPECT_FALSE(in.OnTemperature(RosTemperature(1'000'000, 24.5).get()));
  EXPECT_FALSE(in.OnTemperature(RosTemperature(3'000'000, 297.6).get()));
  EXPECT_EQ(health_.duplicates(), 1);
  EXPECT_EQ(health_.out_of_order(), 1);
  EXPECT_NE(health_.last_error().find("/arm/temperature.temperature: 297.600000 °C"),
            std::string::npos)
      << health_.last_error();
  // A controller that reports slowly (every 60 s, beyond the sensors' 10 s horizon) is taken.
  EXPECT_TRUE(in.OnTemperature(RosTemperature(62'000'000, 25.0).get()));
  EXPECT_EQ(health_.out_of_horizon(), 0);
  EXPECT_EQ(in.temperatures(), 2);
  // Out through the reorder buffer, as ARM_CONDITIONS events only.
  const auto events = in.Ready(true);
  const auto out = ConditionsIn(events);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(events.size(), 2u);
  EXPECT_EQ(out[0].utime, 2'000'000);
  EXPECT_EQ(out[0].temperature_c, 24.5);
  EXPECT_TRUE(std::isnan(out[0].payload_kg));
  EXPECT_EQ(out[1].utime, 62'000'000);
  EXPECT_EQ(out[1].temperature_c, 25.0);
}

// clock_offsets estimate: the temperature driver counts from its boot; its reports are moved to
// the arm's clock by the median of their arrival lags, so a report that ros2_input takes late (a
// loaded CPU, a DDS hiccup) still stands when it was made, not when it was taken. Truth: the
// simulated time each report was made at.
TEST_F(Ros2InputTest, AReportTakenLateStandsWhenItWasMade) {
  Ros2InputSettings s = settings_;
  s.estimate_clock_offsets = true;
  s.reorder_delay = 0.2;
  transport::Health health("ros2_input");
  Ros2Input in(s, cell_.model, health);
  constexpr int64_t kArm0 = 1'700'000'000'000'000;  // the arm's clock at t = 0 [µs]
  constexpr int64_t kBoot = 5'000'000;              // the temperature driver's at t = 0 [µs]
  EXPECT_FALSE(in.OnTemperature(RosTemperature(kBoot, 24.0).get()));
  EXPECT_NE(health.last_error().find("before the arm's first joints"), std::string::npos);
  std::vector<transport::ArmConditions> out;
  // Joints at 125 Hz (8 ms) for 4 s; a report every 100 ms, taken 3 ms after it is made, but
  // those made from 3.0 s to 3.4 s taken together 0.5 s late (a stalled reader: its topic keeps
  // its order, the joints go on).
  std::vector<int64_t> made;  // [µs], t
  for (int64_t k = 0; k <= 500; ++k) {
    const int64_t t = 8'000 * k;
    in.OnJointState(RosJoints(cell_, kArm0 + t).get());
    if (t == 3'504'000)
      for (int64_t r = 30; r < 35; ++r) {
        ASSERT_TRUE(in.OnTemperature(RosTemperature(kBoot + 100'000 * r, 20.0 + 0.1 * r).get()));
        made.push_back(100'000 * r);
      }
    for (int64_t r = (t - 8'000 - 3'000) / 100'000 + 1; r * 100'000 + 3'000 <= t; ++r) {
      if (r < 1 || (r >= 30 && r < 35)) continue;  // before the joints; stalled
      ASSERT_TRUE(in.OnTemperature(RosTemperature(kBoot + 100'000 * r, 20.0 + 0.1 * r).get()));
      made.push_back(100'000 * r);
    }
    for (const auto& c : ConditionsIn(in.Ready())) out.push_back(c);
  }
  for (const auto& c : ConditionsIn(in.Ready(true))) out.push_back(c);
  std::sort(made.begin(), made.end());
  ASSERT_EQ(out.size(), made.size());
  // The three made more than the reorder delay (0.2 s) before they were taken came after the
  // samples of their time had left: counted, published all the same, at their time.
  EXPECT_EQ(in.conditions_late(), 3);
  for (size_t i = 0; i < out.size(); ++i) {
    // In time order, each within a joints' period and the taking delay of when it was made.
    EXPECT_NEAR(static_cast<double>(out[i].utime - kArm0), static_cast<double>(made[i]), 11'000.0)
        << "report " << i;
    if (i > 0) {
      EXPECT_GT(out[i].utime, out[i - 1].utime);
    }
  }
  // The stalled ones where they were made, not up to 0.5 s later at their arrival: 23.0 °C
  // was made at 3.0 s.
  const auto stalled = std::find_if(out.begin(), out.end(), [](const transport::ArmConditions& c) {
    return std::abs(c.temperature_c - 23.0) < 1e-9;
  });
  ASSERT_NE(stalled, out.end());
  EXPECT_NEAR(static_cast<double>(stalled->utime - kArm0), 3e6, 11'000.0);
  EXPECT_EQ(health.rejected(), 1);
}

dds::Sample<dds::InertiaStamped> RosPayload(int64_t utime, double kg) {
  transport::ArmConditions c;
  c.utime = utime;
  c.payload_kg = kg;
  std::string error;
  return std::move(*dds::ToRosPayload(c, "tool0", &error));
}

// The payload (geometry_msgs/InertiaStamped) and the temperature make one stream of conditions:
// in time order across the two topics, each report carries the newest of both; a report older
// than what already left stands a microsecond after it, counted, not dropped; a payload in grams
// is refused and named.
TEST_F(Ros2InputTest, ThePayloadAndTheTemperatureMakeOneStreamOfConditions) {
  EXPECT_EQ(settings_.payload_topic, "/arm/payload");
  Ros2Input in(settings_, cell_.model, health_);  // clock_offsets none: own stamps
  EXPECT_TRUE(in.OnTemperature(RosTemperature(2'000'000, 24.5).get()));
  EXPECT_TRUE(in.OnPayload(RosPayload(3'000'000, 5.0).get()));
  EXPECT_TRUE(in.OnTemperature(RosTemperature(4'000'000, 25.0).get()));
  EXPECT_TRUE(in.Ready().empty());  // the samples set the pace: none yet
  in.OnJointState(RosJoints(cell_, 4'000'000).get());
  auto out = ConditionsIn(in.Ready());  // the two older than the delay (50 ms) before 4 s
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].utime, 2'000'000);
  EXPECT_TRUE(std::isnan(out[0].payload_kg));  // none reported yet
  EXPECT_EQ(out[1].utime, 3'000'000);
  EXPECT_EQ(out[1].temperature_c, 24.5);
  EXPECT_EQ(out[1].payload_kg, 5.0);
  // In order on its own topic, before the other topic's last report, not yet published: in its
  // place in time.
  EXPECT_TRUE(in.OnPayload(RosPayload(3'500'000, 7.0).get()));
  out = ConditionsIn(in.Ready(true));
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].utime, 3'500'000);
  EXPECT_EQ(out[0].temperature_c, 24.5);
  EXPECT_EQ(out[0].payload_kg, 7.0);
  EXPECT_EQ(out[1].utime, 4'000'000);
  EXPECT_EQ(out[1].temperature_c, 25.0);
  EXPECT_EQ(out[1].payload_kg, 7.0);
  // Older than what was published: not dropped, counted, at once, and after the stream's last
  // report (a microsecond after it).
  in.OnJointState(RosJoints(cell_, 4'200'000).get());
  EXPECT_EQ(in.Ready().size(), 0u);  // 4.2 s: newer than the delay
  EXPECT_TRUE(in.OnPayload(RosPayload(3'800'000, 8.0).get()));
  EXPECT_EQ(in.conditions_late(), 1);
  EXPECT_NE(health_.last_error().find("/arm/payload: a report at 3800000"), std::string::npos)
      << health_.last_error();
  out = ConditionsIn(in.Ready());
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].utime, 4'000'001);
  EXPECT_EQ(out[0].payload_kg, 8.0);
  // What left does not go back with it: a sample older than 4 s is still late (a fuzzer's
  // finding: one was published after newer ones).
  in.OnPoint(0, RosPoint(3'900'000).get());
  EXPECT_EQ(in.late(), 1);
  // Two reports at one time: a microsecond apart (one time twice would be a duplicate
  // downstream).
  EXPECT_TRUE(in.OnTemperature(RosTemperature(5'000'000, 25.5).get()));
  EXPECT_TRUE(in.OnPayload(RosPayload(5'000'000, 9.0).get()));
  out = ConditionsIn(in.Ready(true));
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].utime, 5'000'000);
  EXPECT_EQ(out[1].utime, 5'000'001);
  EXPECT_EQ(out[1].temperature_c, 25.5);
  EXPECT_EQ(out[1].payload_kg, 9.0);
  EXPECT_FALSE(in.OnPayload(RosPayload(5'000'000, 9.0).get()));  // a duplicate
  EXPECT_FALSE(in.OnPayload(RosPayload(6'000'000, 7000.0).get()));
  EXPECT_NE(health_.last_error().find("/arm/payload.inertia.m: 7000.000000 kg"), std::string::npos)
      << health_.last_error();
  EXPECT_EQ(health_.duplicates(), 1);
  EXPECT_EQ(in.payloads(), 4);
  EXPECT_EQ(in.temperatures(), 3);
  // Every report is one ARM_CONDITIONS accepts.
  std::string error;
  EXPECT_TRUE(transport::ArmConditionsFromMessage(transport::ToArmConditions(out[1]), &error))
      << error;
}

TEST_F(Ros2InputTest, ClockMessageListsEverySource) {
  Ros2Input in(settings_, cell_.model, health_);
  const clock_offset_t m = in.ClockMessage(123);
  EXPECT_EQ(m.utime, 123);
  ASSERT_EQ(m.num_sources, 2);
  EXPECT_EQ(m.source[0], "imu");
  EXPECT_EQ(m.source[1], "position/0");
  EXPECT_EQ(m.state[1], static_cast<int8_t>(ClockState::kFixed));
}

}  // namespace
}  // namespace rcal::ros2
