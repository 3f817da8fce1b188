// The commands that read LCM logs (`rcal calibrate --log`, `calibrate LOG`, `analyze LOG`,
// `analyze LOG --imu`) on damaged logs written with lcm::LogFile (what lcm-logger writes): each
// prints what it read and lost, exits non-zero when anything was lost, and with --allow-gaps uses
// exactly the intact events. The damage is what fuzzing found: one flipped bit in an event's
// length (before: 10 of 50 poses used, exit 0), datalen = 0x7fffffff (SIGSEGV in liblcm's reader),
// num_joints = −1 in one event (the whole log refused) and 2^28 + 6 (SIGSEGV in the decoder).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>
#include <random>

#include "rcal/cell/online_identification.hpp"
#include "rcal/cell/sim_cell.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/sim/imu_stream.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<uint8_t>;

// A fresh folder per name and process: ctest runs this file's tests as parallel processes, and
// two of them sharing one folder removed each other's files (CI, stop 46).
fs::path TempDir(const std::string& name) {
  return testing::TempDir("test_log_gaps", name);
}

struct Result {
  int exit_code = -1;
  bool signalled = false;
  std::string output;
};

Result Rcal(const fs::path& dir, const std::string& args) {
  const fs::path out = dir / "output.txt";
  const std::string cmd = std::string(RCAL_EXE) + " " + args + " > " + out.string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  Result r;
  r.signalled = WIFSIGNALED(status) || (WIFEXITED(status) && WEXITSTATUS(status) >= 128);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(out);
  r.output.assign(std::istreambuf_iterator<char>(in), {});
  return r;
}

template <typename Msg>
void Write(lcm::LogFile& log, const std::string& channel, const Msg& m, int64_t utime) {
  Bytes buf(static_cast<size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  lcm::LogEvent e;
  e.eventnum = 0;
  e.timestamp = utime;
  e.channel = channel;
  e.datalen = static_cast<int32_t>(buf.size());
  e.data = buf.data();
  ASSERT_EQ(log.writeEvent(&e), 0);
}

Bytes ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes((std::istreambuf_iterator<char>(in)), {});
}
void WriteFile(const fs::path& p, const Bytes& b) {
  std::ofstream(p, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<long>(b.size()));
}

// Offsets of the events of an intact log, from its headers (big-endian channel and data lengths
// at bytes 20 and 24 of each 28-byte header).
std::vector<size_t> EventOffsets(const Bytes& b) {
  const auto be32 = [&](size_t at) {
    return (uint32_t{b[at]} << 24) | (uint32_t{b[at + 1]} << 16) | (uint32_t{b[at + 2]} << 8) |
           uint32_t{b[at + 3]};
  };
  std::vector<size_t> offsets;
  for (size_t at = 0; at + 28 <= b.size(); at += 28 + be32(at + 20) + be32(at + 24))
    offsets.push_back(at);
  return offsets;
}
size_t DataOffset(const Bytes& b, size_t event_at) {
  const size_t channel = (size_t{b[event_at + 20]} << 24) | (size_t{b[event_at + 21]} << 16) |
                         (size_t{b[event_at + 22]} << 8) | size_t{b[event_at + 23]};
  return event_at + 28 + channel;
}
void PutBe32(Bytes& b, size_t at, uint32_t v) {
  for (int k = 0; k < 4; ++k)
    b[at + static_cast<size_t>(k)] = static_cast<uint8_t>(v >> (24 - 8 * k));
}

// The damaged copies of a log of one channel: event k of `offsets`.
enum class Damage { kFlippedLengthBit, kDataLength0x7fffffff, kNumJointsMinus1, kNumJointsHuge };
Bytes Damaged(Bytes b, size_t k, Damage d) {
  const size_t at = EventOffsets(b).at(k);
  switch (d) {
    case Damage::kFlippedLengthBit:
      b[at + 24 + 2] ^= 0x02;  // data length + 512: runs over the next events
      break;
    case Damage::kDataLength0x7fffffff:
      PutBe32(b, at + 24, 0x7fffffffu);
      break;
    case Damage::kNumJointsMinus1:  // pose_measurement_t: fingerprint, utime, pose_index, marker_id
      PutBe32(b, DataOffset(b, at) + 24, 0xffffffffu);
      break;
    case Damage::kNumJointsHuge:
      PutBe32(b, DataOffset(b, at) + 24, (1u << 28) + 6);
      break;
  }
  return b;
}

constexpr const char* kRobot = RCAL_SOURCE_DIR "/config/robots/grb3016.yaml";

// The demo's kind of log: still windows of the simulated cell (seed 2) as POSE_MEASUREMENT.
class CalibrateLog : public ::testing::Test {
 protected:
  static constexpr int kPoses = 20;
  void SetUp() override {
    dir_ = TempDir("calibrate_log");
    const auto robot = io::LoadRobot(kRobot);
    const cell::Cell c = cell::MakeCell(robot.spec, 2);
    cell::RunSettings rs;
    rs.seed = 2;
    rs.num_cal = kPoses;
    rs.num_test = 0;
    const auto w = cell::SimulateWindows(c, rs);
    ASSERT_EQ(static_cast<int>(w.cal.size()), kPoses);
    {
      lcm::LogFile log((dir_ / "intact.lcmlog").string(), "w");
      for (int k = 0; k < kPoses; ++k)
        Write(log, transport::channels::kPoseMeasurement,
              transport::ToMessage(w.cal[k], 1'000'000 * (k + 1), k), 1'000'000 * (k + 1));
    }
    intact_ = ReadFile(dir_ / "intact.lcmlog");
    ASSERT_EQ(EventOffsets(intact_).size(), static_cast<size_t>(kPoses));
  }
  // `rcal calibrate --log LOG --cell config/cells/grb3016.yaml ARGS --json` (the demo cell file:
  // its set-up guessed from the log, whatever seed the simulator drew); the JSON when it exited 0.
  nlohmann::json Calibrate(const Bytes& log, const std::string& args, Result* r) {
    WriteFile(dir_ / "run.lcmlog", log);
    fs::remove(dir_ / "out.json");
    *r = Rcal(dir_, "calibrate --log " + (dir_ / "run.lcmlog").string() +
                        " --cell " RCAL_SOURCE_DIR "/config/cells/grb3016.yaml " + args +
                        " --json " + (dir_ / "out.json").string());
    if (r->exit_code != 0 || !fs::exists(dir_ / "out.json")) return {};
    return nlohmann::json::parse(std::ifstream(dir_ / "out.json"));
  }
  fs::path dir_;
  Bytes intact_;
};

TEST_F(CalibrateLog, AnIntactLogSaysNothingWasLost) {
  Result r;
  const nlohmann::json j = Calibrate(intact_, "", &r);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("events read 20, skipped 0, broken frames 0, bytes unreadable 0"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(j.at("events"), kPoses);
  EXPECT_EQ(j.at("log_broken_frames"), 0);
}

TEST_F(CalibrateLog, EachDamageLosesOneEventSaysSoAndExitsNonZeroUnlessAllowed) {
  Result intact_run;
  const nlohmann::json all = Calibrate(intact_, "", &intact_run);
  ASSERT_EQ(intact_run.exit_code, 0) << intact_run.output;
  // The reference for "one pose lost": the intact log without event 7 (writer's bytes cut out).
  Bytes without7(intact_.begin(), intact_.begin() + static_cast<long>(EventOffsets(intact_)[7]));
  without7.insert(without7.end(), intact_.begin() + static_cast<long>(EventOffsets(intact_)[8]),
                  intact_.end());
  Result ref_run;
  const nlohmann::json ref = Calibrate(without7, "", &ref_run);
  ASSERT_EQ(ref_run.exit_code, 0) << ref_run.output;
  ASSERT_EQ(ref.at("events"), kPoses - 1);

  const struct {
    Damage damage;
    const char* summary;
    const char* reason;
  } cases[] = {
      {Damage::kFlippedLengthBit, "events read 19, skipped 0, broken frames 1", "broken event"},
      {Damage::kDataLength0x7fffffff, "events read 19, skipped 0, broken frames 1",
       "data length 2147483647"},
      {Damage::kNumJointsMinus1, "events read 20, skipped 1, broken frames 0",
       "pose_measurement_t.num_joints = -1 is negative"},
      {Damage::kNumJointsHuge, "events read 20, skipped 1, broken frames 0",
       "pose_measurement_t.num_joints = 268435462 exceeds"},
  };
  for (const auto& c : cases) {
    const Bytes bad = Damaged(intact_, 7, c.damage);
    Result r;
    Calibrate(bad, "", &r);
    EXPECT_FALSE(r.signalled) << c.summary << "\n" << r.output;
    EXPECT_NE(r.exit_code, 0) << c.summary << "\n" << r.output;
    EXPECT_NE(r.output.find(c.summary), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(c.reason), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("--allow-gaps"), std::string::npos) << r.output;
    // Allowed: exactly the other 19 poses, the same parameters as the log without event 7.
    const nlohmann::json j = Calibrate(bad, "--allow-gaps", &r);
    ASSERT_EQ(r.exit_code, 0) << c.summary << "\n" << r.output;
    EXPECT_EQ(j.at("poses_accepted"), ref.at("poses_accepted")) << c.summary;
    EXPECT_EQ(j.at("parameters"), ref.at("parameters")) << c.summary;
    EXPECT_NE(j.at("parameters"), all.at("parameters"));
  }
}

// A log of position-and-orientation poses for `calibrate LOG` and `analyze LOG` (the GRB3016 with
// the set-up frames those commands add).
TEST(LogGaps, CalibrateAndAnalyzeOfALogRefuseALossyLogUnlessAllowed) {
  io::RobotSpec spec = io::LoadRobot(kRobot).spec;
  spec.base = io::FrameSpec{};
  spec.markers = {io::MarkerSpec{}};
  spec.imu = io::FrameSpec{};
  spec.earth = io::FrameSpec{};
  const auto model = io::BuildModel(spec);
  sim::Rng rng(5);
  sim::PoseNoise noise;
  noise.position_sigma = 5e-5;
  noise.orientation_sigma = 2e-4;
  noise.orientation = true;
  Eigen::VectorXd x = sim::Table3Errors(model);
  x(model.FindParameter("base_x")) = 1.2;
  const int n = 40;
  const auto ms = sim::MeasurePoses(model, x, sim::SampleJoints(model, n, rng), noise, rng);
  const fs::path dir = TempDir("data");
  {
    lcm::LogFile log((dir / "intact.lcmlog").string(), "w");
    for (int k = 0; k < n; ++k)
      Write(log, transport::channels::kPoseMeasurement,
            transport::ToMessage(ms[k], 1'000'000 * (k + 1), k), 1'000'000 * (k + 1));
  }
  const Bytes intact = ReadFile(dir / "intact.lcmlog");
  const std::string log = (dir / "run.lcmlog").string();
  for (const char* command : {"calibrate", "analyze"}) {
    const std::string args = std::string(command) + " " + log + " --robot " + kRobot + " --out " +
                             (dir / "out").string();
    WriteFile(log, intact);
    Result r = Rcal(dir, args);
    EXPECT_EQ(r.exit_code, 0) << command << "\n" << r.output;
    EXPECT_NE(r.output.find("events read 40, skipped 0, broken frames 0, bytes unreadable 0"),
              std::string::npos)
        << r.output;
    for (Damage d : {Damage::kFlippedLengthBit, Damage::kNumJointsHuge}) {
      WriteFile(log, Damaged(intact, 12, d));
      r = Rcal(dir, args);
      EXPECT_FALSE(r.signalled) << command << "\n" << r.output;
      EXPECT_NE(r.exit_code, 0) << command << "\n" << r.output;
      EXPECT_NE(r.output.find("lost data"), std::string::npos) << r.output;
      r = Rcal(dir, args + " --allow-gaps");
      EXPECT_EQ(r.exit_code, 0) << command << "\n" << r.output;
    }
  }
}

TEST(LogGaps, AnalyzeImuOfALogRefusesALossyLogUnlessAllowed) {
  sim::ImuStreamSettings ss;
  ss.rest_s = 15.0;
  ss.motion_s = 15.0;
  std::mt19937_64 rng(3);
  const auto stream = sim::SimulateImuStream(ss, sim::ImuStreamEffects{}, rng);
  const fs::path dir = TempDir("imu");
  {
    lcm::LogFile log((dir / "intact.lcmlog").string(), "w");
    for (size_t k = 0; k < stream.size(); ++k) {
      imu_sample_t m{};
      m.utime = static_cast<int64_t>(std::llround(stream[k].t * 1e6)) + 1'000'000;
      for (int i = 0; i < 3; ++i) {
        m.gyro[i] = stream[k].gyro(i);
        m.accel[i] = stream[k].accel(i);
        m.mag[i] = stream[k].mag_uT(i) * 1e-6;
      }
      m.has_mag = true;
      Write(log, transport::channels::kImu, m, m.utime);
    }
  }
  const Bytes intact = ReadFile(dir / "intact.lcmlog");
  const size_t events = EventOffsets(intact).size();
  ASSERT_EQ(events, stream.size());
  const std::string log = (dir / "run.lcmlog").string();
  const std::string args = "analyze " + log + " --imu --out " + (dir / "out").string();
  WriteFile(log, intact);
  Result r = Rcal(dir, args);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // A flipped length bit, and a cut tail (the last event half written).
  Bytes bad = Damaged(intact, 500, Damage::kFlippedLengthBit);
  bad.resize(bad.size() - 30);
  WriteFile(log, bad);
  r = Rcal(dir, args);
  EXPECT_FALSE(r.signalled) << r.output;
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(
      r.output.find("events read " + std::to_string(events - 2) + ", skipped 0, broken frames 2"),
      std::string::npos)
      << r.output;
  r = Rcal(dir, args + " --allow-gaps");
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

}  // namespace
}  // namespace rcal::tool
