// sensor_acquisition's raw-stream replay source on a small CSV written here: IMU every row with
// utime from t_s, magnetometer scaled to tesla, position decimated on file time and skipped where
// NaN, order IMU before POSITION within a row, missing columns named.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "rcal/io/robot_urdf.hpp"
#include "sources.hpp"

namespace rcal::sensors {
namespace {

namespace fs = std::filesystem;

fs::path WriteCsv(const std::string& name, const std::string& text) {
  const fs::path p = fs::temp_directory_path() / (name + std::to_string(::getpid()) + ".csv");
  std::ofstream(p) << text;
  return p;
}

TEST(RawCsvReplaySource, ImuEveryRowPositionDecimatedOnFileTime) {
  std::string csv =
      "# comment\nt_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,pos_x,"
      "pos_y,pos_z,other\n";
  for (int k = 0; k < 12; ++k) {
    const double t = 0.01 * k;
    const std::string pos = k == 5 ? "nan,nan,nan" : std::to_string(k) + ",2,3";
    csv += std::to_string(t) + ",0.1,0.2,0.3,0,0,9.81,20,0,-40," + pos + ",7\n";
  }
  const fs::path p = WriteCsv("replay_src", csv);
  RawCsvReplaySettings s;
  s.position_rate = 25;  // every 0.04 s of file time
  s.utime_offset = 1000;
  RawCsvReplaySource src(p.string(), s);
  std::vector<SensorEvent> events;
  while (auto e = src.Next(0)) events.push_back(*e);
  EXPECT_TRUE(src.Finished());
  int imu = 0;
  std::vector<int64_t> pos_utimes;
  int64_t last = -1;
  for (size_t i = 0; i < events.size(); ++i) {
    EXPECT_GE(Utime(events[i]), last);
    last = Utime(events[i]);
    if (const auto* s_imu = std::get_if<transport::ImuSample>(&events[i])) {
      EXPECT_EQ(s_imu->utime, 10'000 * imu + 1000);
      EXPECT_TRUE(s_imu->has_mag);
      EXPECT_DOUBLE_EQ(s_imu->m_B(0), 20e-6);
      EXPECT_DOUBLE_EQ(s_imu->m_B(2), -40e-6);
      EXPECT_DOUBLE_EQ(s_imu->f_B(2), 9.81);
      ++imu;
    } else {
      const auto& ps = std::get<transport::PositionSample>(events[i]);
      // Follows the IMU sample of its row.
      ASSERT_GT(i, 0u);
      EXPECT_EQ(Utime(events[i - 1]), ps.utime);
      EXPECT_DOUBLE_EQ(ps.covariance(0, 0), 1e-6);
      pos_utimes.push_back(ps.utime);
    }
  }
  EXPECT_EQ(imu, 12);
  // Rows 0, 4, 8 (t = 0, 0.04, 0.08); row 5 is NaN but not due anyway.
  EXPECT_EQ(pos_utimes, (std::vector<int64_t>{1000, 41'000, 81'000}));
  fs::remove(p);
}

TEST(RawCsvReplaySource, HiddenMarkerDelaysThePositionToTheNextFiniteRow) {
  std::string csv = "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z,pos_x,pos_y,pos_z\n";
  for (int k = 0; k < 6; ++k)
    csv += std::to_string(0.01 * k) + ",0,0,0,0,0,9.8,1,1,1," +
           (k == 2 ? std::string("nan,nan,nan") : std::string("1,2,3")) + "\n";
  const fs::path p = WriteCsv("replay_nan", csv);
  RawCsvReplaySettings s;
  s.position_rate = 50;  // every 0.02 s on the schedule 0, 0.02, 0.04: rows 0, 2 (hidden → 3), 4
  RawCsvReplaySource src(p.string(), s);
  std::vector<int64_t> pos;
  while (auto e = src.Next(0))
    if (std::holds_alternative<transport::PositionSample>(*e)) pos.push_back(Utime(*e));
  EXPECT_EQ(pos, (std::vector<int64_t>{0, 30'000, 40'000}));
  fs::remove(p);
}

TEST(RawCsvReplaySource, MissingColumnIsNamed) {
  const fs::path p = WriteCsv("replay_bad", "t_s,gyr_x,gyr_y\n0,1,2\n");
  try {
    RawCsvReplaySource src(p.string(), {});
    FAIL() << "no error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("gyr_z"), std::string::npos) << e.what();
  }
  fs::remove(p);
}

TEST(RawCsvReplaySource, TheBroadTrialReplaysAtTwentyHertzPosition) {
  RawCsvReplaySource src(RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv", {});
  int64_t imu = 0, pos = 0;
  while (auto e = src.Next(0)) (std::holds_alternative<transport::ImuSample>(*e) ? imu : pos)++;
  EXPECT_EQ(imu, 18634);
  EXPECT_NEAR(static_cast<double>(pos) / imu, 0.2, 0.01);
}

TEST(PoseDatasetReplaySource, JointsThenPosePerCalibrationRowWithTheNoiseCovariance) {
  const fs::path p = WriteCsv("replay_poses",
                              "# three poses\nq1,q2,q3,x,y,z,set\n"
                              "0.1,0.2,0.3,1,2,3,cal\n"
                              "0.4,0.5,0.6,4,5,6,test\n"
                              "0.7,0.8,0.9,7,8,9,cal\n");
  EXPECT_FALSE(IsRawStreamCsv(p.string()));
  PoseDatasetReplaySettings s;
  s.rate = 4;
  s.start_utime = 500;
  s.position_sigma = 2e-3;
  PoseDatasetReplaySource src(p.string(), s);
  std::vector<SensorEvent> events;
  while (auto e = src.Next(0)) events.push_back(*e);
  ASSERT_EQ(events.size(), 4u);  // the test row is skipped
  const auto& j0 = std::get<joint_state_t>(events[0]);
  const auto& z0 = std::get<pose_measurement_t>(events[1]);
  const auto& z1 = std::get<pose_measurement_t>(events[3]);
  EXPECT_EQ(j0.utime, 500);
  EXPECT_EQ(j0.q, (std::vector<double>{0.1, 0.2, 0.3}));
  EXPECT_EQ(z0.utime, 500);
  EXPECT_EQ(z1.utime, 250'500);
  EXPECT_EQ(z1.pose_index, 1);
  EXPECT_EQ(z1.q, (std::vector<double>{0.7, 0.8, 0.9}));
  EXPECT_DOUBLE_EQ(z1.p[2], 9);
  EXPECT_FALSE(z1.has_orientation);
  ASSERT_EQ(z1.dimension, 3);
  EXPECT_DOUBLE_EQ(z1.covariance[0], 4e-6);
  EXPECT_DOUBLE_EQ(z1.covariance[1], 0);
  EXPECT_DOUBLE_EQ(z1.covariance[8], 4e-6);
  fs::remove(p);
}

TEST(PoseDatasetReplaySource, WithARobotARowItCannotHaveProducedRefusesTheFile) {
  // The replay published any finite joint value: a q2 of 10 rad on the GRB3016 went out as
  // JOINTS and POSE_MEASUREMENT.
  const auto robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  const std::string header = "q1,q2,q3,q4,q5,q6,x,y,z\n";
  const fs::path bad = WriteCsv("replay_bad", header +
                                                  "0.1,0.2,0.3,0.1,0.2,0.3,0.5,0.1,0.4\n"
                                                  "0.1,10,0.3,0.1,0.2,0.3,0.5,0.1,0.4\n");
  PoseDatasetReplaySettings s;
  s.model = &robot.model;
  try {
    PoseDatasetReplaySource src(bad.string(), s);
    ADD_FAILURE() << "accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("column 'q2'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("beyond its limits"), std::string::npos) << e.what();
  }
  // Without the robot it cannot be told (and is published, with a warning from the process).
  s.model = nullptr;
  EXPECT_NO_THROW(PoseDatasetReplaySource(bad.string(), s));
  // A row of the wrong joint count for the robot.
  const fs::path five = WriteCsv("replay_five", "q1,q2,q3,q4,q5,x,y,z\n0,0,0,0,0,0.5,0,0.4\n");
  s.model = &robot.model;
  EXPECT_THROW(PoseDatasetReplaySource(five.string(), s), std::runtime_error);
  fs::remove(bad);
  fs::remove(five);
}

TEST(PoseDatasetReplaySource, TheBroadTrialIsARawStream) {
  EXPECT_TRUE(IsRawStreamCsv(RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv"));
}

// sensor_acquisition --checkpoint: the sim source's resume point survives a save and load; a
// missing file means "start the programme"; another programme's file is an error naming the key;
// a malformed one names the key.
TEST(SimCheckpoint, RoundTripAndProgrammeCheck) {
  const fs::path dir = fs::temp_directory_path() / ("sim_ckpt_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const SimProgramme prog{"sensors", 1, 20, 20, 1'000'000, 100.0};
  EXPECT_FALSE(LoadSimCheckpoint(dir / "sa.json", prog).has_value());
  SaveSimCheckpoint(dir / "sa.json", {prog, 1234, 13'340'000, false});
  const auto back = LoadSimCheckpoint(dir / "sa.json", prog);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->next_tick, 1234);
  EXPECT_EQ(back->next_utime, 13'340'000);
  EXPECT_FALSE(back->finished);
  EXPECT_EQ(back->programme.level, "sensors");
  EXPECT_EQ(back->programme.rate, 100.0);
  auto error_of = [&](const SimProgramme& other) -> std::string {
    try {
      LoadSimCheckpoint(dir / "sa.json", other);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "";
  };
  SimProgramme other = prog;
  other.seed = 2;
  EXPECT_NE(error_of(other).find("seed"), std::string::npos) << error_of(other);
  other = prog;
  other.poses = 50;
  EXPECT_NE(error_of(other).find("poses"), std::string::npos) << error_of(other);
  other = prog;
  other.level = "poses";
  EXPECT_NE(error_of(other).find("level"), std::string::npos) << error_of(other);
  other = prog;
  other.start_utime = 0;
  EXPECT_NE(error_of(other).find("start_utime"), std::string::npos) << error_of(other);
  // Written atomically: no temporary file is left beside it.
  int files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1);
  fs::remove_all(dir);
}

TEST(SimCheckpoint, MalformedTextNamesTheKey) {
  EXPECT_THROW(ParseSimCheckpoint("not json"), std::runtime_error);
  try {
    ParseSimCheckpoint(R"({"schema": "rcal.sensor_acquisition_checkpoint/1", "level": "sensors",
                          "seed": 1, "poses": 20, "test_poses": 20, "start_utime": 0,
                          "rate": 100, "next_utime": 0, "finished": false})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("next_tick"), std::string::npos) << e.what();
  }
  try {
    ParseSimCheckpoint(R"({"schema": "rcal.sensor_acquisition_checkpoint/1", "level": 3})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("level"), std::string::npos) << e.what();
  }
  try {
    ParseSimCheckpoint(R"({"schema": "other/1"})");
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("schema"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace rcal::sensors
