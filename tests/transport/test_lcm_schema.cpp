// The LCM schemas parsed from lcmtypes/*.lcm and the bounds check before every decode
// (services/transport/src/lcm_schema.cpp). The truths are independent of the parser: the
// fingerprints lcm-gen put into the generated code (getHash()), bytes encoded by the generated
// code, and, for the grammar the rcal types do not use (nested structs, 2-D arrays, constants,
// several names per member), a type compiled once with lcm-gen 1.3.1 (its hash and encoding
// copied below).
#include "rcal/transport/lcm_schema.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "rcal/arm_conditions_t.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/clock_offset_t.hpp"
#include "rcal/health_t.hpp"
#include "rcal/ik_command_t.hpp"
#include "rcal/ik_request_t.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/joint_state_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/model_discrepancy_t.hpp"
#include "rcal/next_poses_t.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/supervisor_state_t.hpp"
#include "rcal/tool_position_estimate_t.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

template <typename Msg>
std::vector<uint8_t> Encode(const Msg& m) {
  std::vector<uint8_t> b(static_cast<size_t>(m.getEncodedSize()));
  EXPECT_EQ(m.encode(b.data(), 0, static_cast<int>(b.size())), static_cast<int>(b.size()));
  return b;
}

void PutBe32(std::vector<uint8_t>& b, size_t at, int64_t v) {
  const auto u = static_cast<uint32_t>(v);
  for (int k = 0; k < 4; ++k)
    b[at + static_cast<size_t>(k)] = static_cast<uint8_t>(u >> (24 - 8 * k));
}

// The pose of the fuzzing report (422 bytes then, 426 with marker_id): 6 joints, 6×6 covariance.
pose_measurement_t Pose6() {
  pose_measurement_t m{};
  m.utime = 1000;
  m.pose_index = 3;
  m.num_joints = 6;
  m.q = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6};
  m.p[0] = 1;
  m.has_orientation = 1;
  m.q_EI[0] = 1;
  m.dimension = 6;
  m.num_covariance = 36;
  m.covariance.assign(36, 1e-6);
  m.temperature_c = 25.0;
  m.payload_kg = 0.0;
  m.time_s = 1e-3;
  m.dq_sign = {1, -1, 0, 1, 1, -1};
  return m;
}
constexpr size_t kNumJointsAt = 8 + 8 + 4 + 4;  // fingerprint, utime, pose_index, marker_id

joint_state_t Joints() {
  joint_state_t m{};
  m.utime = 5;
  m.num_joints = 2;
  m.names = {"j1", "joint_2"};
  m.q = {1, 2};
  m.dq = {0, 0};
  return m;
}

template <typename Msg>
std::string CheckAs(const std::vector<uint8_t>& b) {
  return CheckLcmMessage(Msg::getTypeName(), Msg::getHash(), b.data(), b.size());
}

TEST(LcmSchema, EveryLcmFileIsParsedAndEachFingerprintIsTheGeneratedCodes) {
  const LcmSchema& s = RcalLcmSchema();
  ASSERT_EQ(s.structs().size(), detail::EmbeddedLcmFiles().size());  // one struct per file
  // The fingerprint hashes every member's name, primitive type and dimensions: equal to lcm-gen's
  // getHash() means the parsed table is the .lcm file, field by field.
  const auto expect = [&](const char* name, int64_t hash) {
    const LcmStruct* t = s.Find(name);
    ASSERT_NE(t, nullptr) << name;
    EXPECT_EQ(t->package, "rcal");
    EXPECT_EQ(s.Fingerprint(*t), hash) << name;
  };
  expect("calibration_status_t", calibration_status_t::getHash());
  expect("health_t", health_t::getHash());
  expect("ik_command_t", ik_command_t::getHash());
  expect("ik_request_t", ik_request_t::getHash());
  expect("imu_sample_t", imu_sample_t::getHash());
  expect("joint_state_t", joint_state_t::getHash());
  expect("kinematic_params_t", kinematic_params_t::getHash());
  expect("next_poses_t", next_poses_t::getHash());
  expect("model_discrepancy_t", model_discrepancy_t::getHash());
  expect("clock_offset_t", clock_offset_t::getHash());
  expect("arm_conditions_t", arm_conditions_t::getHash());
  expect("orientation_estimate_t", orientation_estimate_t::getHash());
  expect("pose_measurement_t", pose_measurement_t::getHash());
  expect("position_sample_t", position_sample_t::getHash());
  expect("supervisor_state_t", supervisor_state_t::getHash());
  expect("tool_position_estimate_t", tool_position_estimate_t::getHash());
  EXPECT_NE(s.Find("rcal.pose_measurement_t"), nullptr);
  EXPECT_EQ(s.Find("nonexistent_t"), nullptr);
}

TEST(LcmSchema, PoseMeasurementMembersInOrder) {
  const LcmStruct* t = RcalLcmSchema().Find("pose_measurement_t");
  ASSERT_NE(t, nullptr);
  std::vector<std::string> names;
  for (const auto& m : t->members) names.push_back(m.name);
  EXPECT_EQ(names, (std::vector<std::string>{"utime", "pose_index", "marker_id", "num_joints", "q",
                                             "p", "has_orientation", "q_EI", "dimension",
                                             "num_covariance", "covariance", "temperature_c",
                                             "payload_kg", "time_s", "dq_sign"}));
  ASSERT_EQ(t->members[4].dimensions.size(), 1u);
  EXPECT_TRUE(t->members[4].dimensions[0].variable);
  EXPECT_EQ(t->members[4].dimensions[0].size, "num_joints");
  EXPECT_FALSE(t->members[5].dimensions[0].variable);
  EXPECT_EQ(t->members[5].dimensions[0].constant, 3);
}

TEST(LcmSchema, ValidMessagesOfEveryTypePass) {
  EXPECT_EQ(CheckAs<pose_measurement_t>(Encode(Pose6())), "");
  EXPECT_EQ(CheckAs<joint_state_t>(Encode(Joints())), "");
  joint_state_t empty{};
  EXPECT_EQ(CheckAs<joint_state_t>(Encode(empty)), "");
  kinematic_params_t k{};
  k.robot_id = "grb3016";
  k.model_id = "dh";
  k.num_params = 2;
  k.names = {"a1", "d2"};
  k.values = {1e-3, 2e-3};
  k.sigmas = {1e-4, 1e-4};
  k.identified = {1, 0};
  k.num_effect_params = 1;
  k.effect_names = {"joint_compliance.j2.c"};
  k.effect_units = {"rad/(N*m)"};
  k.effect_values = {2e-6};
  k.effect_sigmas = {1e-7};
  EXPECT_EQ(CheckAs<kinematic_params_t>(Encode(k)), "");
  supervisor_state_t sv{};
  sv.num_processes = 1;
  sv.names = {"logger"};
  sv.pids = {12};
  sv.states = {"running"};
  sv.restarts = {0};
  sv.last_exit = {0};
  sv.reasons = {""};
  EXPECT_EQ(CheckAs<supervisor_state_t>(Encode(sv)), "");
  ik_request_t r{};
  r.num_joints = 6;
  r.q_seed.assign(6, 0.1);
  EXPECT_EQ(CheckAs<ik_request_t>(Encode(r)), "");
  ik_command_t c{};
  c.status = "converged";
  c.num_joints = 1;
  c.q = {1};
  c.q_nominal = {1};
  EXPECT_EQ(CheckAs<ik_command_t>(Encode(c)), "");
  health_t h{};
  h.process = "ekf_identifier";
  EXPECT_EQ(CheckAs<health_t>(Encode(h)), "");
  calibration_status_t cs{};
  EXPECT_EQ(CheckAs<calibration_status_t>(Encode(cs)), "");
  EXPECT_EQ(CheckAs<imu_sample_t>(Encode(imu_sample_t{})), "");
  EXPECT_EQ(CheckAs<orientation_estimate_t>(Encode(orientation_estimate_t{})), "");
  EXPECT_EQ(CheckAs<position_sample_t>(Encode(position_sample_t{})), "");
  EXPECT_EQ(CheckAs<tool_position_estimate_t>(Encode(tool_position_estimate_t{})), "");
}

TEST(LcmSchema, TheFuzzedLengthsAreRefusedNamingTheField) {
  std::vector<uint8_t> b = Encode(Pose6());
  // 426 bytes up to the covariance, then the context: 3 doubles and a byte per joint.
  constexpr size_t kContextBytes = 3 * 8 + 6;
  ASSERT_EQ(b.size(), 426u + kContextBytes);
  PutBe32(b, kNumJointsAt, (int64_t{1} << 28) + 6);
  EXPECT_EQ(CheckAs<pose_measurement_t>(b),
            "pose_measurement_t.num_joints = 268435462 exceeds the 428 bytes left "
            "(q[num_joints])");
  PutBe32(b, kNumJointsAt, -1);
  EXPECT_EQ(CheckAs<pose_measurement_t>(b),
            "pose_measurement_t.num_joints = -1 is negative (q[num_joints])");
  // Below the bytes left as a count, but not as 8-byte doubles.
  PutBe32(b, kNumJointsAt, 60);
  EXPECT_NE(CheckAs<pose_measurement_t>(b).find("pose_measurement_t.num_joints = 60: q needs 480 "
                                                "bytes, 428 left"),
            std::string::npos)
      << CheckAs<pose_measurement_t>(b);
  PutBe32(b, kNumJointsAt, 6);
  PutBe32(b, 426 - 4 - 8 * 36, 600000000);  // num_covariance = 6e8
  EXPECT_EQ(CheckAs<pose_measurement_t>(b),
            "pose_measurement_t.num_covariance = 600000000 exceeds the 318 bytes left "
            "(covariance[num_covariance])");
  // Present in full but beyond any rcal message: the per-type limit.
  pose_measurement_t big = Pose6();
  big.num_covariance = 5000;
  big.covariance.assign(5000, 0.0);
  EXPECT_EQ(CheckAs<pose_measurement_t>(Encode(big)),
            "pose_measurement_t.num_covariance = 5000 exceeds the limit of 4096 "
            "(covariance[num_covariance])");
  big.num_covariance = 4096;
  big.covariance.assign(4096, 0.0);
  EXPECT_EQ(CheckAs<pose_measurement_t>(Encode(big)), "");

  std::vector<uint8_t> j = Encode(Joints());
  PutBe32(j, 16, 30000000);  // JOINTS num_joints = 3e7
  EXPECT_NE(CheckAs<joint_state_t>(j).find("joint_state_t.num_joints = 30000000 exceeds"),
            std::string::npos);
}

TEST(LcmSchema, BrokenStringsTruncationTrailingBytesAndOtherTypesAreRefused) {
  const std::vector<uint8_t> good = Encode(Joints());
  std::vector<uint8_t> b = good;
  PutBe32(b, 20, 0);  // names[0]'s length: 0 would make the decoder assign −1 bytes
  EXPECT_EQ(CheckAs<joint_state_t>(b),
            "joint_state_t.names: string length 0 is below 1 (it counts the terminating NUL)");
  b = good;
  PutBe32(b, 20, 1000);
  EXPECT_NE(CheckAs<joint_state_t>(b).find("joint_state_t.names: string length 1000 exceeds the"),
            std::string::npos);
  b = good;
  b[20 + 4 + 2] = 'x';  // "j1" without its NUL
  EXPECT_EQ(CheckAs<joint_state_t>(b), "joint_state_t.names: string length 3: no terminating NUL");
  // Every truncation is refused, and every added byte.
  for (size_t n = 0; n < good.size(); ++n) {
    const std::vector<uint8_t> cut(good.begin(), good.begin() + static_cast<long>(n));
    EXPECT_NE(CheckAs<joint_state_t>(cut), "") << n;
  }
  b = good;
  b.push_back(0);
  EXPECT_EQ(CheckAs<joint_state_t>(b), "joint_state_t: 1 bytes after the end of the message");
  // Another type's bytes: the fingerprint differs.
  EXPECT_NE(CheckAs<pose_measurement_t>(good).find("fingerprint"), std::string::npos);
  // A type without a schema, and generated code that does not match its schema.
  EXPECT_NE(CheckLcmMessage("other_t", 1, good.data(), good.size()).find("no schema"),
            std::string::npos);
  EXPECT_NE(CheckLcmMessage("joint_state_t", 1, good.data(), good.size()).find("fingerprints"),
            std::string::npos);
}

TEST(LcmSchema, NestedStructsTwoDimensionsConstantsAndCommentsAsLcmGenCompilesThem) {
  LcmSchema s;
  s.AddFile("package tst;\nstruct inner_t { int16_t k; string s; }\n", "inner.lcm");
  s.AddFile(R"(package tst;
/* block
   comment */
struct outer_t {
  const int32_t LIMIT = 5;
  int8_t n;
  int64_t m;
  double grid[n][3];  // trailing
  tst.inner_t one;
  inner_t many[m];
  boolean flags[2][n];
  float a, b;
  byte raw[4];
}
)",
            "outer.lcm");
  // lcm-gen 1.3.1 on these two files: tst::outer_t::getHash(), tst::inner_t::getHash().
  EXPECT_EQ(static_cast<uint64_t>(s.Fingerprint(*s.Find("outer_t"))), 0x037815cfa232cb35u);
  EXPECT_EQ(static_cast<uint64_t>(s.Fingerprint(*s.Find("inner_t"))), 0x6694506dfb15e061u);
  // Its generated encode() of n = 2, m = 1, grid {{1,2,3},{4,5,6}}, one {7, "ab"},
  // many {{-1, ""}}, flags {{1,0},{0,1}}, a = 1, b = 2, raw {0,1,2,3}.
  const std::string hex =
      "037815cfa232cb350200000000000000013ff000000000000040000000000000004008000000000000401000"
      "000000000040140000000000004018000000000000000700000003616200ffff0000000100010000013f8000"
      "004000000000010203";
  std::vector<uint8_t> b;
  for (size_t i = 0; i + 1 < hex.size(); i += 2)
    b.push_back(static_cast<uint8_t>(std::stoi(hex.substr(i, 2), nullptr, 16)));
  ASSERT_EQ(b.size(), 97u);
  EXPECT_EQ(s.Check(*s.Find("outer_t"), b.data(), b.size()), "");
  b[8] = 0x80;  // n = −128
  EXPECT_EQ(s.Check(*s.Find("outer_t"), b.data(), b.size()),
            "outer_t.n = -128 is negative (grid[n])");
  b[8] = 2;
  b[8 + 1 + 7] = 2;  // m = 2: the second inner_t is not there
  EXPECT_NE(s.Check(*s.Find("outer_t"), b.data(), b.size()).find("outer_t.many: "),
            std::string::npos);
}

TEST(LcmSchema, SyntaxErrorsNameTheFileAndLine) {
  LcmSchema s;
  EXPECT_THROW(s.AddFile("struct a_t { int32_t n; double x[m]; }", "a.lcm"), std::runtime_error);
  try {
    s.AddFile("package p;\nstruct a_t {\n  double x[n];\n}", "a.lcm");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("a.lcm:3"), std::string::npos) << e.what();
  }
  EXPECT_THROW(s.AddFile("struct a_t { int32_t n }", "b.lcm"), std::runtime_error);
  EXPECT_THROW(s.AddFile("struct a_t { double n; double x[n]; }", "c.lcm"), std::runtime_error);
  EXPECT_THROW(s.AddFile("struct a_t { int32_t n; /* open", "d.lcm"), std::runtime_error);
}

// Through the transport: refused bytes reach the error handler naming channel, type and field,
// and never the typed handler (the old code decoded them: 2^28 + 6 read past the buffer, −1 threw
// length_error, counted only as "do not decode").
TEST(LcmSchema, SubscribeRefusesBeforeDecodingWithTheReason) {
  LcmTransport t("memq://");
  int delivered = 0;
  std::vector<std::string> errors;
  t.Subscribe<pose_measurement_t>(
      "POSE_MEASUREMENT", [&](const pose_measurement_t&) { ++delivered; },
      [&](const std::string& e) { errors.push_back(e); });
  std::vector<uint8_t> b = Encode(Pose6());
  PutBe32(b, kNumJointsAt, (int64_t{1} << 28) + 6);
  ASSERT_TRUE(t.PublishRaw("POSE_MEASUREMENT", b.data(), static_cast<int>(b.size())));
  PutBe32(b, kNumJointsAt, -1);
  ASSERT_TRUE(t.PublishRaw("POSE_MEASUREMENT", b.data(), static_cast<int>(b.size())));
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_EQ(delivered, 0);
  ASSERT_EQ(errors.size(), 2u);
  EXPECT_EQ(errors[0],
            "channel POSE_MEASUREMENT: pose_measurement_t.num_joints = 268435462 exceeds the 428 "
            "bytes left (q[num_joints])");
  EXPECT_EQ(errors[1],
            "channel POSE_MEASUREMENT: pose_measurement_t.num_joints = -1 is negative "
            "(q[num_joints])");
  b = Encode(Pose6());
  ASSERT_TRUE(t.PublishRaw("POSE_MEASUREMENT", b.data(), static_cast<int>(b.size())));
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_EQ(delivered, 1);
}

}  // namespace
}  // namespace rcal::transport
