// config/processes.dds.yaml (the process table with the DDS bridge) is a valid table for the
// supervisor: it parses with the supervisor's own parser, starts the bridge before the
// identifier, gives the bridge the identifier's cell file (so the robot id it expects is the one
// the identifier publishes: the cell's robot file's name), and
// every dds_bridge option in it is one the bridge accepts (checked by running `dds_bridge --help`).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "process_table.hpp"
#include "rcal/io/cell_yaml.hpp"

namespace {

std::string Output(const std::string& command) {
  std::string out;
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen(command.c_str(), "r"), pclose);
  std::array<char, 256> buf{};
  while (p && fgets(buf.data(), buf.size(), p.get())) out += buf.data();
  return out;
}

TEST(DdsProcessTable, StartsTheBridgeForTheIdentifiersRobot) {
  const auto table = rcal::services::LoadProcessTable(RCAL_SOURCE_DIR "/config/processes.dds.yaml");
  const auto& p = table.processes;
  auto find = [&](const std::string& name) {
    return std::find_if(p.begin(), p.end(), [&](const auto& s) { return s.name == name; });
  };
  const auto bridge = find("dds_bridge"), identifier = find("ekf_identifier");
  ASSERT_NE(bridge, p.end());
  ASSERT_NE(identifier, p.end());
  EXPECT_LT(bridge - p.begin(), identifier - p.begin());
  ASSERT_FALSE(bridge->argv.empty());
  EXPECT_EQ(bridge->argv[0], "dds_bridge");

  // The bridge's --cell is the identifier's (the robot id its KINEMATIC_PARAMS carry), and no
  // --robot-id overrides it.
  const auto& a = bridge->argv;
  const auto& b = identifier->argv;
  const auto cell_a = std::find(a.begin(), a.end(), "--cell");
  const auto cell_b = std::find(b.begin(), b.end(), "--cell");
  ASSERT_NE(cell_a, a.end());
  ASSERT_NE(cell_a + 1, a.end());
  ASSERT_NE(cell_b, b.end());
  ASSERT_NE(cell_b + 1, b.end());
  EXPECT_EQ(*(cell_a + 1), *(cell_b + 1));
  EXPECT_EQ(std::find(a.begin(), a.end(), "--robot-id"), a.end());
  EXPECT_EQ(rcal::io::LoadCell(RCAL_SOURCE_DIR "/" + *(cell_a + 1)).model.name(), "grb3016");

  const std::string help = Output(RCAL_DDS_BRIDGE " --help");
  for (const auto& arg : a) {
    if (arg.rfind("--", 0) == 0) {
      EXPECT_NE(help.find(arg), std::string::npos) << arg;
    }
  }
}

#if defined(RCAL_ROS2_INPUT) && defined(RCAL_ROS2_SIM_DRIVERS)
// config/processes.demo-ros2.yaml (deploy/demo --ros2): parses, every process of the cell is given
// the same cell file, the consumers start before the input and the drivers last, and every option
// is one the program accepts.
TEST(DdsProcessTable, TheRos2DemoRunsOneCellFromTheDriversIn) {
  const auto table =
      rcal::services::LoadProcessTable(RCAL_SOURCE_DIR "/config/processes.demo-ros2.yaml");
  const auto& p = table.processes;
  std::vector<std::string> names;
  for (const auto& s : p) names.push_back(s.name);
  EXPECT_EQ(names, (std::vector<std::string>{"logger", "ekf_identifier", "still_window",
                                             "dds_bridge", "ros2_input", "ros2_sim_drivers"}));
  const std::map<std::string, std::string> exe = {{"ekf_identifier", RCAL_EKF_IDENTIFIER_EXE},
                                                  {"still_window", RCAL_STILL_WINDOW_EXE},
                                                  {"dds_bridge", RCAL_DDS_BRIDGE},
                                                  {"ros2_input", RCAL_ROS2_INPUT},
                                                  {"ros2_sim_drivers", RCAL_ROS2_SIM_DRIVERS}};
  for (const auto& s : p) {
    const auto& a = s.argv;
    ASSERT_FALSE(a.empty());
    EXPECT_EQ(a[0], s.name);
    const auto cell = std::find(a.begin(), a.end(), "--cell");
    if (s.name != "ros2_sim_drivers") {
      ASSERT_NE(cell, a.end()) << s.name;
      EXPECT_EQ(*(cell + 1), "config/cells/grb3016.yaml") << s.name;
    } else {
      // The drivers simulate the cell the sim file names: the same one.
      const auto sim = std::find(a.begin(), a.end(), "--sim");
      ASSERT_NE(sim, a.end());
      EXPECT_EQ(*(sim + 1), "config/cells/grb3016.sim.yaml");
    }
    const auto it = exe.find(s.name);
    if (it == exe.end()) continue;
    const std::string help = Output(it->second + " --help");
    for (const auto& arg : a) {
      if (arg.rfind("--", 0) == 0) {
        EXPECT_NE(help.find(arg), std::string::npos) << s.name << " " << arg;
      }
    }
  }
}
#endif

}  // namespace
