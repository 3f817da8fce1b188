// The online identification (what ekf_identifier and `rcal calibrate --log` run) against the
// offline experiment of the same cell: pose by pose it reaches RunOnline's parameters bit for bit;
// restored mid-guess or mid-run it ends where an uninterrupted run ends; bad poses are refused
// naming the field and change nothing.
#include "rcal/cell/online_identification.hpp"

#include <gtest/gtest.h>

#include <limits>

#include "rcal/io/robot_urdf.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::cell {
namespace {

const io::LoadedRobot& Grb3016() {
  static const io::LoadedRobot robot = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  return robot;
}

struct CellRun {
  Cell cell;
  Windows w;
};

const CellRun& Cal20() {
  static const CellRun run = [] {
    CellRun r{MakeCell(Grb3016().spec, 3), {}};
    RunSettings rs;
    rs.seed = 3;
    rs.num_cal = 20;
    rs.num_test = 0;
    r.w = SimulateWindows(r.cell, rs);
    return r;
  }();
  return run;
}

TimedPose At(const kinematics::PoseMeasurement& z, int k) {
  return {z, 1'000'000 * (k + 1), k};
}

OnlineIdentificationSettings CellSettings() {
  OnlineIdentificationSettings s;
  s.cell_seed = 3;
  return s;
}

TEST(OnlineIdentification, CellModeReachesTheOfflineRunBitForBit) {
  const CellRun& r = Cal20();
  ASSERT_EQ(r.w.cal.size(), 20u);
  OnlineIdentification id(Grb3016().spec, Grb3016().model, CellSettings());
  EXPECT_EQ(id.base(), r.cell.base);
  int held = 0, updates = 0;
  for (int k = 0; k < 20; ++k) {
    const auto out = id.Add(At(r.w.cal[k], k));
    EXPECT_TRUE(out.rejected.empty()) << out.rejected;
    held += out.held;
    updates += static_cast<int>(out.updates.size());
    EXPECT_EQ(out.started, k == 5);  // the sixth pose completes the guess
  }
  EXPECT_EQ(held, 6);
  EXPECT_EQ(updates, 20);
  const OnlineResult offline = RunOnline(r.cell, r.w.cal, {});
  EXPECT_EQ(id.ekf().x(), offline.x);
  EXPECT_EQ(id.ekf().accepted(), offline.accepted);
  EXPECT_EQ(id.last_pose_index(), 19);
}

TEST(OnlineIdentification, RestoredDuringTheGuessOrAfterEndsAsAnUninterruptedRun) {
  const CellRun& r = Cal20();
  OnlineIdentification ref(Grb3016().spec, Grb3016().model, CellSettings());
  for (int k = 0; k < 20; ++k) ref.Add(At(r.w.cal[k], k));
  for (const int stop : {3, 12}) {  // 3: three poses held; 12: the EKF running
    OnlineIdentification a(Grb3016().spec, Grb3016().model, CellSettings());
    for (int k = 0; k < stop; ++k) a.Add(At(r.w.cal[k], k));
    EXPECT_EQ(a.started(), stop >= 6);
    EXPECT_EQ(a.held().size(), stop >= 6 ? 0u : static_cast<size_t>(stop));
    OnlineIdentification b(Grb3016().spec, Grb3016().model, CellSettings());
    b.Restore(a.ekf().Checkpoint(), a.held(), a.last_utime(), a.last_pose_index());
    // The last pose again (a replay after the restart): refused by time, nothing changes.
    const auto again = b.Add(At(r.w.cal[stop - 1], stop - 1));
    EXPECT_NE(again.rejected.find("pose_measurement.utime"), std::string::npos) << again.rejected;
    for (int k = stop; k < 20; ++k) b.Add(At(r.w.cal[k], k));
    EXPECT_EQ(b.ekf().x(), ref.ekf().x()) << "stopped after " << stop;
  }
  // Held poses cannot be restored into an identification without a cell.
  OnlineIdentification generic(Grb3016().spec, Grb3016().model, {});
  OnlineIdentification a(Grb3016().spec, Grb3016().model, CellSettings());
  a.Add(At(r.w.cal[0], 0));
  EXPECT_THROW(generic.Restore(generic.ekf().Checkpoint(), a.held(), 1, 0), std::runtime_error);
}

TEST(OnlineIdentification, BadPosesAreRefusedNamingTheFieldAndChangeNothing) {
  const CellRun& r = Cal20();
  OnlineIdentification id(Grb3016().spec, Grb3016().model, CellSettings());
  for (int k = 0; k < 8; ++k) id.Add(At(r.w.cal[k], k));
  const Eigen::VectorXd x = id.ekf().x();
  auto nan = At(r.w.cal[8], 8);
  nan.z.q(2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(id.Add(nan).rejected, "q: not finite");
  auto short_q = At(r.w.cal[8], 8);
  short_q.z.q.conservativeResize(5);
  EXPECT_NE(id.Add(short_q).rejected.find("q: 5 joints"), std::string::npos);
  auto early = At(r.w.cal[8], 2);  // sensor time before the last pose
  EXPECT_NE(id.Add(early).rejected.find("not after the last pose"), std::string::npos);
  EXPECT_EQ(id.ekf().x(), x);
  EXPECT_EQ(id.last_pose_index(), 7);
  EXPECT_THROW(OnlineIdentification(Grb3016().spec, Grb3016().model, {1, 3, 0, false}),
               std::invalid_argument);
}

// Without a cell: the robot file's model on its identifiable set, the EKF from the first pose.
TEST(OnlineIdentification, GenericModeUsesTheIdentifiableSetAndStartsAtOnce) {
  OnlineIdentification id(Grb3016().spec, Grb3016().model, {});
  EXPECT_TRUE(id.started());
  EXPECT_EQ(id.model().num_params(), Grb3016().model.num_params());
  EXPECT_EQ(id.base().size(), 25u);  // GRB3016 with the D–H tool, full poses
  sim::Rng rng(9);
  const auto& m = id.model();
  const auto ms = sim::MeasurePoses(m, sim::Table3Errors(m), sim::SampleJoints(m, 3, rng), {}, rng);
  const auto out = id.Add(At(ms[0], 0));
  EXPECT_FALSE(out.held);
  ASSERT_EQ(out.updates.size(), 1u);
  EXPECT_TRUE(out.updates[0].result.accepted);
  EXPECT_GT(out.updates[0].max_step_sigma, 0.0);
}

}  // namespace
}  // namespace rcal::cell
