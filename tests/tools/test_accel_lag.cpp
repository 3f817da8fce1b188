// `rcal accel-lag LOG` (tools/rcal/cmd_accel_lag.cpp): the accelerometer's lag from a recorded run,
// as lcm-logger writes it (lcm::LogFile). The run is the analytic fast tool of
// tests/estimation/lagged_tool.hpp (its IMU 3 ms late and ~4 cm off the marker): IMU samples,
// the orientation estimate that follows each (the truth's, with the IMU's utime, as orientation_kf
// publishes it) and a 20 Hz tracker. The command must find the lag put in, print the cell line
// that takes it out, count what it refused and refuse a lossy log unless told otherwise.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "../estimation/lagged_tool.hpp"
#include "rcal/imu_sample_t.hpp"
#include "rcal/orientation_estimate_t.hpp"
#include "rcal/position_sample_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal_cli.hpp"

namespace rcal::tool {
namespace {

namespace fs = std::filesystem;
namespace ch = transport::channels;

template <class Msg>
void Write(lcm::LogFile& log, const char* channel, const Msg& m, int64_t utime) {
  std::vector<unsigned char> buf(static_cast<size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  lcm::LogEvent e{0, utime, channel, static_cast<int32_t>(buf.size()), buf.data()};
  ASSERT_EQ(log.writeEvent(&e), 0);
}

// The run as a log; with `garbage`, one IMU event that does not decode (a loss of the log's).
// The tracker's frame is turned by R_WE from the IMU's earth frame (ENU).
fs::path WriteRun(const fs::path& dir, bool with_orientation, bool garbage,
                  const Eigen::Matrix3d& R_WE = Eigen::Matrix3d::Identity()) {
  estimation::lagged::Truth truth;
  truth.R_WE = R_WE;
  const estimation::AccelLagData d = estimation::lagged::Record(truth, 2);
  const bool turned = !R_WE.isIdentity();
  const fs::path path = dir / (std::string(with_orientation ? "run" : "no_orientation") +
                               (garbage ? "_garbage" : "") + (turned ? "_turned" : "") + ".lcmlog");
  lcm::LogFile log(path.string(), "w");
  EXPECT_TRUE(log.good());
  size_t j = 0;
  for (size_t k = 0; k < d.t_imu.size(); ++k) {
    const int64_t utime = static_cast<int64_t>(std::llround(d.t_imu[k] * 1e6));
    transport::ImuSample s;
    s.utime = utime;
    s.gyro_B = d.omega_B[k];  // the truth's rate, zero bias
    s.f_B = d.f_B[k];
    Write(log, ch::kImu, transport::ToMessage(s), utime);
    if (with_orientation) {
      orientation_estimate_t o{};
      o.utime = utime;
      const Eigen::Quaterniond q(d.R_EB[k]);
      o.q_EI[0] = q.w(), o.q_EI[1] = q.x(), o.q_EI[2] = q.y(), o.q_EI[3] = q.z();
      Write(log, ch::kOrientation, o, utime);
    }
    if (j < d.t_position.size() && d.t_position[j] == d.t_imu[k]) {
      transport::PositionSample p;
      p.utime = utime;
      p.p = d.p_WM_W[j++];
      p.covariance = 1e-6 * Eigen::Matrix3d::Identity();
      Write(log, ch::kPosition, transport::ToMessage(p), utime);
    }
    if (garbage && k == 100) {
      std::vector<unsigned char> junk(7, 0xAB);
      lcm::LogEvent e{0, utime, ch::kImu, static_cast<int32_t>(junk.size()), junk.data()};
      EXPECT_EQ(log.writeEvent(&e), 0);
    }
  }
  return path;
}

TEST(RcalAccelLag, FindsTheLagOfARecordedRunAndPrintsTheCellLine) {
  const fs::path dir = testing::TempDir("accel_lag", "run");
  const fs::path log = WriteRun(dir, true, false);
  const testing::Result r = testing::RunRcal("accel-lag " + log.string() + " --earth enu --json " +
                                             (dir / "lag.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::printf("%s", r.output.c_str());
  const nlohmann::json j = testing::ReadJson(dir / "lag.json");
  EXPECT_NEAR(j.at("delay_s").get<double>(), 3e-3, 3e-4) << r.output;
  const std::vector<double> r_B = j.at("lever_arm_B_m");
  EXPECT_NEAR(r_B[0], 0.02, 5e-3);
  EXPECT_NEAR(r_B[1], -0.01, 5e-3);
  EXPECT_NEAR(r_B[2], 0.03, 5e-3);
  EXPECT_EQ(j.at("imu_samples").get<int>(), 6000);
  EXPECT_EQ(j.at("imu_without_orientation").get<int>(), 0);
  EXPECT_EQ(j.at("position_samples").get<int>(), 1200);
  EXPECT_NE(r.output.find("cell: sensors.imu.accel_delay: 0.00"), std::string::npos) << r.output;
}

// A log that lost an event is refused (the figure would rest on less than was recorded) unless
// --allow-gaps, and the event is counted either way.
// No cell to fix the tracker's frame, which is 115° from the earth frame: the command estimates it
// with the lag, prints it as q_WE and writes it to the JSON.
TEST(RcalAccelLag, WithoutACellTheTrackersFrameIsEstimated) {
  const fs::path dir = testing::TempDir("accel_lag", "frame");
  const Eigen::Matrix3d R_WE =
      Eigen::AngleAxisd(2.0, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const fs::path log = WriteRun(dir, true, false, R_WE);
  const testing::Result r = testing::RunRcal("accel-lag " + log.string() + " --earth enu --json " +
                                             (dir / "lag.json").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = testing::ReadJson(dir / "lag.json");
  EXPECT_TRUE(j.at("R_WE_estimated").get<bool>());
  const auto q = j.at("q_WE");
  const Eigen::Quaterniond q_WE(q[0].get<double>(), q[1].get<double>(), q[2].get<double>(),
                                q[3].get<double>());
  EXPECT_LT(q_WE.angularDistance(Eigen::Quaterniond(R_WE)), 0.2 * 3.141592653589793 / 180.0);
  EXPECT_NEAR(j.at("delay_s").get<double>(), 3e-3, 3e-4) << r.output;
  EXPECT_NE(r.output.find("position sensor's frame W from the IMU's earth frame E, estimated"),
            std::string::npos)
      << r.output;
}

TEST(RcalAccelLag, ALossyLogIsRefusedUnlessAllowed) {
  const fs::path dir = testing::TempDir("accel_lag", "garbage");
  const fs::path log = WriteRun(dir, true, true);
  const testing::Result refused = testing::RunRcal("accel-lag " + log.string() + " --earth enu");
  EXPECT_NE(refused.exit_code, 0) << refused.output;
  EXPECT_NE(refused.output.find("skipped 1"), std::string::npos) << refused.output;
  const testing::Result allowed =
      testing::RunRcal("accel-lag " + log.string() + " --earth enu --allow-gaps --json " +
                       (dir / "lag.json").string());
  ASSERT_EQ(allowed.exit_code, 0) << allowed.output;
  const nlohmann::json j = testing::ReadJson(dir / "lag.json");
  EXPECT_EQ(j.at("refused").at(ch::kImu).get<int>(), 1);
  EXPECT_NEAR(j.at("delay_s").get<double>(), 3e-3, 3e-4);
}

// Without the orientation estimates there is nothing to turn the accelerometer with: refused,
// saying what is missing.
TEST(RcalAccelLag, WithoutOrientationEstimatesNothingIsMeasured) {
  const fs::path dir = testing::TempDir("accel_lag", "no_orientation");
  const testing::Result r =
      testing::RunRcal("accel-lag " + WriteRun(dir, false, false).string() + " --earth enu");
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("0 IMU samples with their orientation (6000 without one)"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("fewer than three IMU samples"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace rcal::tool
