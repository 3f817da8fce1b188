// The LCM <-> DDS conversion (services/dds_bridge/convert.hpp): every field lands in its DDS
// field bit for bit, LCM → DDS → LCM is the identity, the stamp follows ROS 2's sec/nanosec
// split, and bad input is rejected naming the field.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "rcal/dds/convert.hpp"
#include "test_messages.hpp"

namespace rcal::dds {
namespace {

using testing::TestOrientation;
using testing::TestParams;
using testing::TestStatus;
using testing::TestToolPosition;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Bitwise equality (so -0.0 != 0.0 and the subnormal is checked exactly).
bool Same(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

// LCM messages compare equal when their encodings do.
template <typename Msg>
std::vector<uint8_t> Bytes(const Msg& m) {
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return b;
}

TEST(DdsStamp, SplitsMicrosecondsIntoSecondsAndNanoseconds) {
  std::string e;
  auto t = StampFromUtime(12'345'678, "f", &e);
  ASSERT_TRUE(t) << e;
  EXPECT_EQ(t->sec, 12);
  EXPECT_EQ(t->nanosec, 345'678'000u);
  t = StampFromUtime(-1, "f", &e);  // before the epoch: floor, nanosec stays non-negative
  ASSERT_TRUE(t) << e;
  EXPECT_EQ(t->sec, -1);
  EXPECT_EQ(t->nanosec, 999'999'000u);
  for (int64_t u : {int64_t{0}, int64_t{-1}, int64_t{1}, int64_t{-1'000'000}, int64_t{999'999},
                    int64_t{1'700'000'000'123'456}, int64_t{2147483647} * 1'000'000 + 999'999,
                    int64_t{-2147483648} * 1'000'000}) {
    const auto s = StampFromUtime(u, "f", &e);
    ASSERT_TRUE(s) << u << ": " << e;
    EXPECT_EQ(UtimeFromStamp(*s, "f", &e), u);
  }
}

TEST(DdsStamp, RejectsOutOfRangeNamingTheField) {
  std::string e;
  EXPECT_FALSE(StampFromUtime(int64_t{2147483648} * 1'000'000, "kinematic_params.utime", &e));
  EXPECT_NE(e.find("kinematic_params.utime"), std::string::npos) << e;
  EXPECT_FALSE(UtimeFromStamp(Time{1, 1'000'000'000u}, "x.header.stamp", &e));
  EXPECT_NE(e.find("x.header.stamp.nanosec"), std::string::npos) << e;
  EXPECT_EQ(UtimeFromStamp(Time{2, 999}, "f", &e), 2'000'000);  // sub-µs dropped
}

TEST(DdsKinematicParams, EveryFieldLandsInItsDdsField) {
  const auto m = TestParams(2);
  std::string e;
  const auto s = ToDds(m, &e);
  ASSERT_TRUE(s) << e;
  const KinematicParams& d = s->get();
  EXPECT_EQ(d.header.stamp.sec, 20);
  EXPECT_EQ(d.header.stamp.nanosec, 123'457'000u);
  EXPECT_STREQ(d.header.frame_id, "base");
  EXPECT_STREQ(d.robot_id, "robot_a");
  EXPECT_STREQ(d.model_id, m.model_id.c_str());
  ASSERT_EQ(d.names._length, 28u);
  ASSERT_EQ(d.values._length, 28u);
  ASSERT_EQ(d.sigmas._length, 28u);
  ASSERT_EQ(d.identified._length, 28u);
  for (size_t i = 0; i < 28; ++i) {
    EXPECT_STREQ(d.names._buffer[i], m.names[i].c_str());
    EXPECT_TRUE(Same(d.values._buffer[i], m.values[i])) << i;
    EXPECT_TRUE(Same(d.sigmas._buffer[i], m.sigmas[i])) << i;
    EXPECT_EQ(d.identified._buffer[i], m.identified[i] != 0) << i;
  }
  EXPECT_EQ(d.poses_used, 20);
  ASSERT_EQ(d.effect_names._length, 2u);
  ASSERT_EQ(d.effect_units._length, 2u);
  ASSERT_EQ(d.effect_values._length, 2u);
  ASSERT_EQ(d.effect_sigmas._length, 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_STREQ(d.effect_names._buffer[k], m.effect_names[k].c_str());
    EXPECT_STREQ(d.effect_units._buffer[k], m.effect_units[k].c_str());
    EXPECT_TRUE(Same(d.effect_values._buffer[k], m.effect_values[k])) << k;
    EXPECT_TRUE(Same(d.effect_sigmas._buffer[k], m.effect_sigmas[k])) << k;
  }
}

TEST(DdsKinematicParams, RoundTripsExactly) {
  for (int version : {1, 2, 7}) {
    const auto m = TestParams(version, "cell3/arm2");
    std::string e;
    const auto s = ToDds(m, &e);
    ASSERT_TRUE(s) << e;
    const auto back = FromDds(s->get(), &e);
    ASSERT_TRUE(back) << e;
    EXPECT_EQ(Bytes(*back), Bytes(m));
    EXPECT_TRUE(Same(back->values[5], -0.0));
    EXPECT_TRUE(Same(back->values[6], std::numeric_limits<double>::denorm_min()));
  }
}

TEST(DdsKinematicParams, EmptyParameterListRoundTrips) {
  kinematic_params_t m;
  m.utime = 5;
  m.robot_id = "r";
  m.num_params = 0;
  m.poses_used = 0;
  m.num_effect_params = 0;
  std::string e;
  const auto s = ToDds(m, &e);
  ASSERT_TRUE(s) << e;
  const auto back = FromDds(s->get(), &e);
  ASSERT_TRUE(back) << e;
  EXPECT_EQ(Bytes(*back), Bytes(m));
}

TEST(DdsKinematicParams, SampleMovesOwnership) {
  std::string e;
  auto s = ToDds(TestParams(1), &e);
  ASSERT_TRUE(s);
  Sample<KinematicParams> moved = std::move(*s);
  EXPECT_EQ(s->get().names._buffer, nullptr);
  EXPECT_EQ(moved.get().names._length, 28u);
  Sample<KinematicParams> other;
  other = std::move(moved);
  EXPECT_STREQ(other.get().names._buffer[27], "theta_tool");
}

TEST(DdsKinematicParams, RejectsNaNAndInfinityNamingTheField) {
  std::string e;
  auto m = TestParams(1);
  m.values[2] = kNaN;
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_EQ(e, "kinematic_params.values[2] (d1): NaN");
  m = TestParams(1);
  m.sigmas[9] = kInf;
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_EQ(e, "kinematic_params.sigmas[9] (alpha3): infinite");

  // The way back checks too (another DDS writer may send anything).
  auto s = ToDds(TestParams(1), &e);
  ASSERT_TRUE(s) << e;
  s->get().values._buffer[0] = kNaN;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_EQ(e, "kinematic_params.values[0] (a1): NaN");
  // The effect parameters too, both ways.
  m = TestParams(1);
  m.effect_sigmas[1] = kInf;
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_EQ(e, "kinematic_params.effect_sigmas[1] (thermal.k): infinite");
  s = ToDds(TestParams(1), &e);
  ASSERT_TRUE(s) << e;
  s->get().effect_values._buffer[0] = kNaN;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_EQ(e, "kinematic_params.effect_values[0] (joint_compliance.j2.c): NaN");
}

TEST(DdsKinematicParams, RejectsSizesThatDisagreeAndAnEmptyRobotId) {
  std::string e;
  auto m = TestParams(1);
  m.sigmas.pop_back();
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_NE(e.find("kinematic_params.sigmas"), std::string::npos) << e;
  m = TestParams(1);
  m.names.push_back("extra");
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_NE(e.find("kinematic_params.names"), std::string::npos) << e;
  m = TestParams(1);
  m.num_params = -1;
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_NE(e.find("kinematic_params.num_params"), std::string::npos) << e;
  m = TestParams(1, "");
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_EQ(e, "kinematic_params.robot_id: empty");

  auto s = ToDds(TestParams(1), &e);
  ASSERT_TRUE(s) << e;
  s->get().identified._length = 27;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_NE(e.find("kinematic_params.identified"), std::string::npos) << e;
  s->get().identified._length = 28;
  s->get().effect_sigmas._length = 1;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_NE(e.find("kinematic_params.effect_sigmas"), std::string::npos) << e;
  s->get().effect_sigmas._length = 2;
  m = TestParams(1);
  m.effect_units.pop_back();
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_NE(e.find("kinematic_params.effect_units"), std::string::npos) << e;
  m = TestParams(1);
  m.num_effect_params = -1;
  EXPECT_FALSE(ToDds(m, &e));
  EXPECT_NE(e.find("kinematic_params.num_effect_params"), std::string::npos) << e;
  s->get().header.stamp.nanosec = 1'000'000'000u;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_NE(e.find("kinematic_params.header.stamp.nanosec"), std::string::npos) << e;
}

TEST(DdsCalibrationStatus, RoundTripsExactlyWithTheRobotId) {
  for (int version : {1, 2}) {
    const auto m = TestStatus(version);
    std::string e;
    const auto s = ToDds(m, "robot_b", &e);
    ASSERT_TRUE(s) << e;
    const CalibrationStatus& d = s->get();
    EXPECT_STREQ(d.robot_id, "robot_b");
    EXPECT_STREQ(d.header.frame_id, "");
    EXPECT_EQ(d.header.stamp.sec, 10 * version);
    EXPECT_EQ(d.header.stamp.nanosec, 123'457'000u);
    EXPECT_EQ(d.poses_accepted, m.poses_accepted);
    EXPECT_EQ(d.poses_rejected, m.poses_rejected);
    EXPECT_STREQ(d.last_rejection, m.last_rejection.c_str());
    EXPECT_TRUE(Same(d.condition_number, m.condition_number));
    EXPECT_TRUE(Same(d.rms_position_residual, m.rms_position_residual));
    EXPECT_TRUE(Same(d.rms_orientation_residual, m.rms_orientation_residual));
    EXPECT_TRUE(Same(d.last_nis, m.last_nis));
    EXPECT_EQ(d.relinearizations, m.relinearizations);
    EXPECT_EQ(d.converged, m.converged != 0);
    const auto back = FromDds(d, &e);
    ASSERT_TRUE(back) << e;
    EXPECT_EQ(Bytes(*back), Bytes(m));
  }
}

TEST(DdsCalibrationStatus, InfiniteConditionNumberPassesNaNDoesNot) {
  std::string e;
  auto m = TestStatus(1);
  m.condition_number = kInf;
  auto s = ToDds(m, "r", &e);
  ASSERT_TRUE(s) << e;
  EXPECT_EQ(Bytes(*FromDds(s->get(), &e)), Bytes(m));
  m.condition_number = kNaN;
  EXPECT_FALSE(ToDds(m, "r", &e));
  EXPECT_EQ(e, "calibration_status.condition_number: NaN");
  m = TestStatus(1);
  m.rms_position_residual = kInf;
  EXPECT_FALSE(ToDds(m, "r", &e));
  EXPECT_EQ(e, "calibration_status.rms_position_residual: infinite");
  m = TestStatus(1);
  m.last_nis = kNaN;
  EXPECT_FALSE(ToDds(m, "r", &e));
  EXPECT_EQ(e, "calibration_status.last_nis: NaN");
  EXPECT_FALSE(ToDds(TestStatus(1), "", &e));
  EXPECT_NE(e.find("robot id"), std::string::npos) << e;
}

TEST(DdsToolPose, CarriesPositionAndTheLatestOrientationExactly) {
  const auto p = TestToolPosition(1, 3);
  const auto o = TestOrientation(1, 2);
  std::string e;
  const auto s = ToDds(p, &o, "robot_a", &e);
  ASSERT_TRUE(s) << e;
  const ToolPose& d = s->get();
  EXPECT_STREQ(d.robot_id, "robot_a");
  EXPECT_STREQ(d.header.frame_id, "meas");
  EXPECT_EQ(UtimeFromStamp(d.header.stamp, "f", &e), p.utime);
  EXPECT_EQ(std::memcmp(d.position, p.p, sizeof p.p), 0);
  EXPECT_EQ(std::memcmp(d.velocity, p.v, sizeof p.v), 0);
  EXPECT_EQ(std::memcmp(d.covariance, p.covariance, sizeof p.covariance), 0);
  ASSERT_TRUE(d.has_orientation);
  EXPECT_EQ(UtimeFromStamp(d.orientation_stamp, "f", &e), o.utime);
  EXPECT_EQ(std::memcmp(d.orientation, o.q_EI, sizeof o.q_EI), 0);
  EXPECT_EQ(std::memcmp(d.orientation_covariance, o.covariance, sizeof o.covariance), 0);

  const auto back = FromDds(d, &e);
  ASSERT_TRUE(back) << e;
  EXPECT_EQ(Bytes(back->position), Bytes(p));
  ASSERT_TRUE(back->orientation);
  EXPECT_EQ(Bytes(*back->orientation), Bytes(o));  // gyro_bias is zero in TestOrientation
}

TEST(DdsToolPose, WithoutOrientation) {
  const auto p = TestToolPosition(2, 0);
  std::string e;
  const auto s = ToDds(p, nullptr, "robot_a", &e);
  ASSERT_TRUE(s) << e;
  EXPECT_FALSE(s->get().has_orientation);
  for (double q : s->get().orientation) EXPECT_EQ(q, 0.0);
  const auto back = FromDds(s->get(), &e);
  ASSERT_TRUE(back) << e;
  EXPECT_EQ(Bytes(back->position), Bytes(p));
  EXPECT_FALSE(back->orientation);
}

TEST(DdsToolPose, RejectsNonFiniteNamingTheField) {
  std::string e;
  auto p = TestToolPosition(1, 0);
  p.p[1] = kNaN;
  EXPECT_FALSE(ToDds(p, nullptr, "r", &e));
  EXPECT_EQ(e, "tool_position_estimate.p[1]: NaN");
  p = TestToolPosition(1, 0);
  p.covariance[35] = -kInf;
  EXPECT_FALSE(ToDds(p, nullptr, "r", &e));
  EXPECT_EQ(e, "tool_position_estimate.covariance[35]: infinite");
  auto o = TestOrientation(1, 0);
  o.q_EI[0] = kNaN;
  EXPECT_FALSE(ToDds(TestToolPosition(1, 0), &o, "r", &e));
  EXPECT_EQ(e, "orientation_estimate.q_EI[0]: NaN");
  o = TestOrientation(1, 0);
  auto s = ToDds(TestToolPosition(1, 0), &o, "r", &e);
  ASSERT_TRUE(s) << e;
  s->get().orientation_covariance[4] = kNaN;
  EXPECT_FALSE(FromDds(s->get(), &e));
  EXPECT_EQ(e, "tool_pose.orientation_covariance[4]: NaN");
}

}  // namespace
}  // namespace rcal::dds
