// services/dds_bridge/ros2_convert: the ROS 2 drivers' messages into rcal's types (joints by name,
// stamps, units), and rcal's results out as TF, diagnostics and the tool pose; every refusal names
// its field.
#include "rcal/dds/ros2_convert.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>

#include "rcal/sim/draw.hpp"

namespace rcal::dds {
namespace {

const std::vector<std::string> kNames = {"shoulder_pan", "shoulder_lift", "elbow",
                                         "wrist_1",      "wrist_2",       "wrist_3"};

joint_state_t Joints(int64_t utime) {
  joint_state_t js;
  js.utime = utime;
  js.num_joints = 6;
  js.names = kNames;
  for (int i = 0; i < 6; ++i) {
    js.q.push_back(0.1 * (i + 1));
    js.dq.push_back(-0.01 * (i + 1));
  }
  return js;
}

TEST(Ros2Convert, JointsAreMappedByNameNeverByOrder) {
  // The driver lists the joints shuffled; the model's order comes back.
  const JointNameMap map(kNames);
  const joint_state_t js = Joints(1'234'567'891);
  std::string error;
  auto ros = ToRos(js, {3, 0, 5, 1, 4, 2}, "", &error);
  ASSERT_TRUE(ros) << error;
  EXPECT_STREQ(ros->get().name._buffer[0], "wrist_1");
  const auto back = FromRos(ros->get(), map, "joint_states", &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->utime, js.utime);
  EXPECT_EQ(back->names, kNames);
  EXPECT_EQ(back->q, js.q);
  EXPECT_EQ(back->dq, js.dq);
}

TEST(Ros2Convert, JointsOfSomethingElseAreIgnoredAndAMissingJointIsNamed) {
  // A driver that also publishes a gripper finger: fine. One that lacks the elbow: refused.
  JointNameMap with_gripper({"shoulder_pan", "shoulder_lift", "elbow"});
  joint_state_t three = Joints(10);
  std::string error;
  auto ros = ToRos(three, {}, "", &error);
  ASSERT_TRUE(ros);
  const auto ok = FromRos(ros->get(), with_gripper, "joint_states", &error);
  ASSERT_TRUE(ok) << error;
  EXPECT_EQ(ok->num_joints, 3);
  EXPECT_DOUBLE_EQ(ok->q[2], 0.3);

  JointNameMap more({"shoulder_pan", "elbow", "linear_axis"});
  EXPECT_FALSE(FromRos(ros->get(), more, "joint_states", &error));
  EXPECT_EQ(error, "joint_states.name: 'linear_axis' missing");
}

TEST(Ros2Convert, BadJointStatesAreRefusedNamingTheField) {
  const JointNameMap map(kNames);
  std::string error;
  {
    joint_state_t js = Joints(10);
    js.q[2] = std::numeric_limits<double>::quiet_NaN();
    auto ros = ToRos(js, {}, "", &error);
    ASSERT_TRUE(ros);
    EXPECT_FALSE(FromRos(ros->get(), map, "joint_states", &error));
    EXPECT_EQ(error, "joint_states.position[2] (elbow): NaN");
  }
  {
    auto ros = ToRos(Joints(10), {}, "", &error);
    ros->get().position._length = 5;  // a malformed sample: fewer positions than names
    EXPECT_FALSE(FromRos(ros->get(), map, "joint_states", &error));
    EXPECT_EQ(error, "joint_states.position: 5 entries, name has 6");
    ros->get().position._length = 6;
    ros->get().header.stamp.nanosec = 1'000'000'000u;
    EXPECT_FALSE(FromRos(ros->get(), map, "joint_states", &error));
    EXPECT_EQ(error, "joint_states.header.stamp.nanosec: 1000000000 is not below 1e9");
    ros->get().header.stamp.nanosec = 0;
    ros->get().header.stamp.sec = -3;  // ROS time is never negative
    EXPECT_FALSE(FromRos(ros->get(), map, "joint_states", &error));
    EXPECT_EQ(error, "joint_states.header.stamp.sec: -3 is negative");
    ros->get().header.stamp.sec = 0;
    // The same joint twice.
    dds_free(ros->get().name._buffer[4]);
    ros->get().name._buffer[4] = dds_string_dup("elbow");
    EXPECT_FALSE(FromRos(ros->get(), map, "joint_states", &error));
    EXPECT_EQ(error, "joint_states.name[4]: 'elbow' repeated");
  }
  EXPECT_THROW(JointNameMap({"a", "a"}), std::invalid_argument);
  EXPECT_THROW(JointNameMap({"a", ""}), std::invalid_argument);
}

TEST(Ros2Convert, ImuStampsAndUnits) {
  transport::ImuSample s;
  s.utime = 5'000'000'123;
  s.gyro_B = {0.1, -0.2, 0.3};
  s.f_B = {0.2, 9.7, -0.5};
  std::string error;
  auto ros = ToRos(s, "imu_link", &error);
  ASSERT_TRUE(ros);
  EXPECT_EQ(ros->get().header.stamp.sec, 5000);
  EXPECT_EQ(ros->get().header.stamp.nanosec, 123'000u);
  const auto back = FromRos(ros->get(), transport::SensorRanges{}, "imu", &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->utime, s.utime);
  EXPECT_EQ(back->gyro_B, s.gyro_B);
  EXPECT_EQ(back->f_B, s.f_B);
  EXPECT_FALSE(back->has_mag);

  // A driver publishing g instead of m/s², and one publishing °/s: refused, the unit named.
  auto in_g = ToRos(s, "imu_link", &error);
  in_g->get().linear_acceleration = {0.02, 0.99, -0.05};
  EXPECT_FALSE(FromRos(in_g->get(), transport::SensorRanges{}, "imu", &error));
  EXPECT_NE(error.find("in g?"), std::string::npos) << error;
  auto in_deg = ToRos(s, "imu_link", &error);
  in_deg->get().angular_velocity.z = 90.0;
  EXPECT_FALSE(FromRos(in_deg->get(), transport::SensorRanges{}, "imu", &error));
  EXPECT_NE(error.find("degrees per second?"), std::string::npos) << error;
  EXPECT_EQ(error.rfind("imu: ", 0), 0u) << error;
}

TEST(Ros2Convert, MagneticFieldInTeslaOnly) {
  std::string error;
  auto ros = ToRos(MagReading{77, {2e-5, -1e-5, 4e-5}}, "imu_link", &error);
  ASSERT_TRUE(ros);
  const auto back = FromRos(ros->get(), transport::SensorRanges{}, "imu/mag", &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->utime, 77);
  EXPECT_EQ(back->m_S, Eigen::Vector3d(2e-5, -1e-5, 4e-5));
  ros->get().magnetic_field.x = 20.0;  // µT
  EXPECT_FALSE(FromRos(ros->get(), transport::SensorRanges{}, "imu/mag", &error));
  EXPECT_NE(error.find("imu/mag.magnetic_field"), std::string::npos);
  EXPECT_NE(error.find("µT or gauss?"), std::string::npos);
  ros->get().magnetic_field.y = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(FromRos(ros->get(), transport::SensorRanges{}, "imu/mag", &error));
  EXPECT_EQ(error, "imu/mag.magnetic_field[1]: infinite");
}

TEST(Ros2Convert, TheArmsTemperatureInCelsiusOnly) {
  std::string error;
  transport::ArmConditions c;
  c.utime = 1'500'000'123;
  c.temperature_c = 31.25;
  auto ros = ToRos(c, 0.09, "arm", &error);
  ASSERT_TRUE(ros) << error;
  EXPECT_EQ(ros->get().header.stamp.sec, 1500);
  EXPECT_EQ(ros->get().header.stamp.nanosec, 123'000u);
  const auto back = FromRos(ros->get(), "/arm/temperature", &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->utime, c.utime);
  EXPECT_EQ(back->temperature_c, 31.25);
  EXPECT_TRUE(std::isnan(back->payload_kg));  // another topic says it (InertiaStamped)
  auto refused = [&](const std::function<void(Temperature&)>& spoil) {
    auto m = ToRos(c, 0.09, "arm", &error);
    spoil(m->get());
    EXPECT_FALSE(FromRos(m->get(), "/arm/temperature", &error));
    return error;
  };
  EXPECT_EQ(refused([](Temperature& m) { m.temperature = 304.4; }),
            "/arm/temperature.temperature: 304.400000 °C is not -60 to 200 (kelvin?) (ROS wants "
            "°C)");
  EXPECT_EQ(refused([](Temperature& m) { m.temperature = std::nan(""); }),
            "/arm/temperature.temperature: NaN");
  EXPECT_EQ(refused([](Temperature& m) { m.temperature = -300; }),
            "/arm/temperature.temperature: -300.000000 °C is not -60 to 200 (ROS wants °C)");
  EXPECT_EQ(refused([](Temperature& m) { m.variance = -1; }),
            "/arm/temperature.variance: -1.000000 is negative");
  EXPECT_EQ(refused([](Temperature& m) { m.variance = HUGE_VAL; }),
            "/arm/temperature.variance: infinite");
  EXPECT_NE(refused([](Temperature& m) {
              m.header.stamp.nanosec = 1'000'000'000u;
            }).find("/arm/temperature.header.stamp"),
            std::string::npos);
  // 0 is "variance unknown" (sensor_msgs/Temperature): taken.
  ros->get().variance = 0.0;
  EXPECT_TRUE(FromRos(ros->get(), "/arm/temperature", &error)) << error;
  c.temperature_c = std::nan("");
  EXPECT_FALSE(ToRos(c, 0.09, "arm", &error));
}

// The payload (geometry_msgs/InertiaStamped, its mass m): kilograms only, through the encoded
// round trip; grams are named, a tensor that is not finite refused.
TEST(Ros2Convert, ThePayloadInKilogramsOnly) {
  std::string error;
  transport::ArmConditions c;
  c.utime = 1'500'000'123;
  c.payload_kg = 5.5;
  auto ros = ToRosPayload(c, "tool0", &error);
  ASSERT_TRUE(ros) << error;
  EXPECT_EQ(ros->get().header.stamp.sec, 1500);
  EXPECT_EQ(ros->get().inertia.m, 5.5);
  const auto back = FromRos(ros->get(), "/arm/payload", &error);
  ASSERT_TRUE(back) << error;
  EXPECT_EQ(back->utime, c.utime);
  EXPECT_EQ(back->payload_kg, 5.5);
  EXPECT_TRUE(std::isnan(back->temperature_c));  // another topic says it (Temperature)
  auto refused = [&](const std::function<void(InertiaStamped&)>& spoil) {
    auto m = ToRosPayload(c, "tool0", &error);
    spoil(m->get());
    EXPECT_FALSE(FromRos(m->get(), "/arm/payload", &error));
    return error;
  };
  EXPECT_EQ(refused([](InertiaStamped& m) { m.inertia.m = 5500; }),
            "/arm/payload.inertia.m: 5500.000000 kg is not 0 to 1000 (grams?) (ROS wants kg)");
  EXPECT_EQ(refused([](InertiaStamped& m) { m.inertia.m = -1; }),
            "/arm/payload.inertia.m: -1.000000 kg is not 0 to 1000 (ROS wants kg)");
  EXPECT_EQ(refused([](InertiaStamped& m) { m.inertia.m = std::nan(""); }),
            "/arm/payload.inertia.m: NaN");
  EXPECT_EQ(refused([](InertiaStamped& m) { m.inertia.ixx = HUGE_VAL; }),
            "/arm/payload.inertia: the centre of mass or the tensor is not finite");
  EXPECT_EQ(refused([](InertiaStamped& m) { m.inertia.com.y = std::nan(""); }),
            "/arm/payload.inertia: the centre of mass or the tensor is not finite");
  EXPECT_NE(refused([](InertiaStamped& m) {
              m.header.stamp.nanosec = 1'000'000'000u;
            }).find("/arm/payload.header.stamp"),
            std::string::npos);
  c.payload_kg = std::nan("");
  EXPECT_FALSE(ToRosPayload(c, "tool0", &error));
}

TEST(Ros2Convert, TrackerPosesAndPointsBecomePositions) {
  transport::PositionSample p;
  p.utime = 9'999;
  p.p = {1.2, -0.3, 0.8};
  const Eigen::Matrix3d cov = 1e-8 * Eigen::Matrix3d::Identity();
  std::string error;
  auto pose = ToRosPose(p, "tracker", &error);
  auto point = ToRosPoint(p, "tracker", &error);
  ASSERT_TRUE(pose && point);
  for (const auto& back :
       {FromRos(pose->get(), 3, cov, transport::SensorRanges{}, "mocap", &error),
        FromRos(point->get(), 3, cov, transport::SensorRanges{}, "tracker", &error)}) {
    ASSERT_TRUE(back) << error;
    EXPECT_EQ(back->utime, 9'999);
    EXPECT_EQ(back->marker_id, 3);
    EXPECT_EQ(back->p, p.p);
    EXPECT_EQ(back->covariance, cov);
  }
  pose->get().pose.orientation.w = 0.5;  // not a unit quaternion: a broken driver
  EXPECT_FALSE(FromRos(pose->get(), 0, cov, transport::SensorRanges{}, "mocap", &error));
  EXPECT_EQ(error.rfind("mocap.pose.orientation: norm", 0), 0u) << error;
  point->get().point.x = 1e4;  // 10 km: millimetres?
  EXPECT_FALSE(FromRos(point->get(), 0, cov, transport::SensorRanges{}, "tracker", &error));
  EXPECT_EQ(error.rfind("tracker.point: ", 0), 0u) << error;
}

TEST(Ros2Convert, TransformsRoundTrip) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  std::vector<NamedTransform> in;
  for (const char* child : {"rcal_base", "rcal_marker_0", "rcal_imu"}) {
    NamedTransform t;
    t.parent = "rcal_world";
    t.child = child;
    t.p_PC_P = {g(rng), g(rng), g(rng)};
    const Eigen::Vector4d q_wxyz = sim::Draw4(g, rng);
    t.q_PC = Eigen::Quaterniond(q_wxyz(0), q_wxyz(1), q_wxyz(2), q_wxyz(3)).normalized();
    in.push_back(t);
  }
  std::string error;
  auto ros = ToRos(in, 3'000'000, &error);
  ASSERT_TRUE(ros) << error;
  ASSERT_EQ(ros->get().transforms._length, 3u);
  // ROS's field order is x, y, z, w.
  EXPECT_EQ(ros->get().transforms._buffer[1].transform.rotation.w, in[1].q_PC.w());
  EXPECT_EQ(ros->get().transforms._buffer[1].transform.rotation.x, in[1].q_PC.x());
  const auto back = FromRos(ros->get(), &error);
  ASSERT_TRUE(back) << error;
  ASSERT_EQ(back->size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_EQ((*back)[i].parent, "rcal_world");
    EXPECT_EQ((*back)[i].child, in[i].child);
    EXPECT_EQ((*back)[i].p_PC_P, in[i].p_PC_P);
    EXPECT_EQ((*back)[i].q_PC.coeffs(), in[i].q_PC.coeffs());
  }
  in[2].q_PC.coeffs() *= 2.0;
  EXPECT_FALSE(ToRos(in, 0, &error));
  EXPECT_EQ(error.rfind("tf.transforms[2] (rcal_world -> rcal_imu)", 0), 0u) << error;
}

TEST(Ros2Convert, HealthBecomesDiagnosticsWithLevels) {
  health_t a{};
  a.process = "position_kf";
  a.pid = 42;
  a.received = 100;
  a.published = 99;
  health_t b = a;
  b.received = 200;
  EXPECT_EQ(LevelOf(a, nullptr), DiagnosticLevel::kOk);
  EXPECT_EQ(LevelOf(b, &a), DiagnosticLevel::kOk);
  b.rejected = 1;
  b.last_error = "position.p[0]: NaN";
  EXPECT_EQ(LevelOf(b, &a), DiagnosticLevel::kWarn);
  health_t c = b;
  EXPECT_EQ(LevelOf(c, &b), DiagnosticLevel::kOk);  // nothing new since
  c.filter_resets = 1;
  EXPECT_EQ(LevelOf(c, &b), DiagnosticLevel::kError);

  std::string error;
  auto ros = ToRos({{b, DiagnosticLevel::kWarn, {{"clock_offset_imu_s", "0.037"}}}}, "ur10",
                   5'000'000, &error);
  ASSERT_TRUE(ros) << error;
  const auto back = FromRos(ros->get(), &error);
  ASSERT_TRUE(back) << error;
  ASSERT_EQ(back->size(), 1u);
  const DiagnosticReading& r = back->front();
  EXPECT_EQ(r.name, "rcal/position_kf");
  EXPECT_EQ(r.hardware_id, "ur10");
  EXPECT_EQ(r.level, DiagnosticLevel::kWarn);
  EXPECT_EQ(r.message, "position.p[0]: NaN");
  auto value = [&](const std::string& key) {
    for (const auto& [k, v] : r.values)
      if (k == key) return v;
    return std::string("(absent)");
  };
  EXPECT_EQ(value("received"), "200");
  EXPECT_EQ(value("rejected"), "1");
  EXPECT_EQ(value("clock_offset_imu_s"), "0.037");
  ros->get().status._buffer[0].level = 9;
  EXPECT_FALSE(FromRos(ros->get(), &error));
  EXPECT_EQ(error, "diagnostics.status[0].level: 9 is not OK, WARN, ERROR or STALE");
}

TEST(Ros2Convert, ToolPoseInTheWorldFrame) {
  tool_position_estimate_t p{};
  p.utime = 1'500'000;
  p.p[0] = 0.5;
  p.p[1] = 0.1;
  p.p[2] = 0.9;
  for (int i = 0; i < 6; ++i) p.covariance[7 * i] = 1e-8 * (i + 1);
  // R_EI: 90° about x; R_WE: 90° about z. R_WI = R_WE R_EI, the covariance rotated with R_WE.
  orientation_estimate_t o{};
  const Eigen::Quaterniond q_EI(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()));
  o.q_EI[0] = q_EI.w();
  o.q_EI[1] = q_EI.x();
  o.q_EI[2] = q_EI.y();
  o.q_EI[3] = q_EI.z();
  o.covariance[0] = 1e-4;  // about earth x only
  const Eigen::Matrix3d R_WE =
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  std::string error;
  auto ros = ToRos(p, &o, &R_WE, "rcal_world", &error);
  ASSERT_TRUE(ros) << error;
  const auto& d = ros->get();
  EXPECT_STREQ(d.header.frame_id, "rcal_world");
  EXPECT_EQ(d.pose.pose.position.x, 0.5);
  const auto& q = d.pose.pose.orientation;
  const Eigen::Matrix3d R_WI = Eigen::Quaterniond(q.w, q.x, q.y, q.z).toRotationMatrix();
  EXPECT_LT((R_WI - R_WE * q_EI.toRotationMatrix()).norm(), 1e-12);
  // Earth x is world y: the rotation variance moves to the world y entry (row 4, column 4).
  EXPECT_NEAR(d.pose.covariance[6 * 4 + 4], 1e-4, 1e-18);
  EXPECT_NEAR(d.pose.covariance[6 * 3 + 3], 0.0, 1e-18);
  EXPECT_DOUBLE_EQ(d.pose.covariance[6 * 2 + 2], 3e-8);
  // No orientation yet: identity, rotation covariance "unknown".
  auto bare = ToRos(p, nullptr, nullptr, "rcal_world", &error);
  ASSERT_TRUE(bare);
  EXPECT_EQ(bare->get().pose.pose.orientation.w, 1.0);
  EXPECT_EQ(bare->get().pose.covariance[6 * 5 + 5], -1.0);
  p.p[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(ToRos(p, &o, &R_WE, "rcal_world", &error));
  EXPECT_EQ(error, "tool_position_estimate.p[1]: NaN");
}

TEST(Ros2Convert, RobotDescriptionIsTheText) {
  const std::string urdf = "<robot name=\"r\"/>";
  EXPECT_STREQ(ToRos(urdf).get().data, urdf.c_str());
}

}  // namespace
}  // namespace rcal::dds
