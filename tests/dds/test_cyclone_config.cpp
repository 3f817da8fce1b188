// The Cyclone DDS configuration: the bridge's default binds to loopback only, even on a machine
// with a network card, and config/cyclonedds-network.xml (the one setting) opens it.
//
// Cyclone's own trace (Tracing/Verbosity config) says which interfaces it selected. The machine
// is a private network namespace with lo and a veth pair (10.9.9.1, 10.9.9.2) standing in for a
// network card; the control run without any configuration shows Cyclone would pick the card.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "process_helpers.hpp"
#include "rcal/dds/dds_common.hpp"

namespace rcal::dds {
namespace {

namespace fs = std::filesystem;

TEST(CycloneConfig, EnsureChoosesTheLoopbackFileOnlyWhenUnset) {
  const char* saved = std::getenv("CYCLONEDDS_URI");
  const std::string restore = saved ? saved : "";
  unsetenv("CYCLONEDDS_URI");
  const std::string uri = EnsureCycloneConfig();
  EXPECT_EQ(uri, LoopbackConfigUri());
  EXPECT_EQ(uri.rfind("file:///", 0), 0u) << uri;
  EXPECT_TRUE(fs::exists(uri.substr(7))) << uri;
  EXPECT_EQ(uri.substr(uri.size() - 30), "config/cyclonedds-loopback.xml");
  ASSERT_NE(std::getenv("CYCLONEDDS_URI"), nullptr);
  EXPECT_EQ(std::string(std::getenv("CYCLONEDDS_URI")), uri);

  setenv("CYCLONEDDS_URI", "", 1);  // empty counts as unset
  EXPECT_EQ(EnsureCycloneConfig(), uri);
  setenv("CYCLONEDDS_URI", "file:///elsewhere.xml", 1);  // the environment's choice stands
  EXPECT_EQ(EnsureCycloneConfig(), "file:///elsewhere.xml");
  EXPECT_EQ(std::string(std::getenv("CYCLONEDDS_URI")), "file:///elsewhere.xml");

  if (saved)
    setenv("CYCLONEDDS_URI", restore.c_str(), 1);
  else
    unsetenv("CYCLONEDDS_URI");
}

// Creates a participant (rcal_dds_echo, until its short guard) with CYCLONEDDS_URI = `uri` plus
// tracing; returns the "selected interfaces:" line of Cyclone's trace.
std::string SelectedInterfaces(const std::string& uri, const fs::path& dir,
                               const std::string& name) {
  const fs::path trace = dir / (name + ".trace");
  const std::string tracing = "<Tracing><Verbosity>config</Verbosity><OutputFile>" +
                              trace.string() + "</OutputFile></Tracing>";
  setenv("CYCLONEDDS_URI", (uri.empty() ? tracing : uri + "," + tracing).c_str(), 1);
  const pid_t p =
      testing::Spawn({RCAL_DDS_ECHO, "--domain", "5", "--topic", "tool_pose", "--guard", "0.2"},
                     dir / (name + ".out"), dir / (name + ".err"));
  testing::Wait(p);  // exits 3: nothing was published, as intended
  std::ifstream f(trace);
  for (std::string line; std::getline(f, line);)
    if (line.find("selected interfaces:") != std::string::npos) return line;
  ADD_FAILURE() << "no 'selected interfaces' in " << trace;
  return "";
}

TEST(CycloneConfig, LoopbackFileSelectsLoopbackEvenWithANetworkCard) {
  RCAL_IN_NAMESPACE("CycloneConfig.LoopbackFileSelectsLoopbackEvenWithANetworkCard");
  if (std::system("ip link add veth0 type veth peer name veth1 && "
                  "ip addr add 10.9.9.1/24 dev veth0 && ip addr add 10.9.9.2/24 dev veth1 && "
                  "ip link set veth0 up && ip link set veth1 up") != 0)
    RCAL_CANNOT_RUN_HERE("cannot create a veth pair in the namespace (ip link add ... type veth)");
  const fs::path dir = fs::temp_directory_path() / ("rcal_cyclone_cfg_" + std::to_string(getpid()));
  fs::create_directories(dir);

  // Control: without a configuration Cyclone takes the card.
  const std::string unconfigured = SelectedInterfaces("", dir, "default");
  EXPECT_EQ(unconfigured.find(" lo "), std::string::npos) << unconfigured;
  EXPECT_NE(unconfigured.find("veth"), std::string::npos) << unconfigured;

  const std::string loopback = SelectedInterfaces(LoopbackConfigUri(), dir, "loopback");
  EXPECT_NE(loopback.find("selected interfaces: lo "), std::string::npos) << loopback;
  EXPECT_EQ(loopback.find("veth"), std::string::npos) << loopback;

  const std::string network = SelectedInterfaces(
      "file://" RCAL_SOURCE_DIR "/config/cyclonedds-network.xml", dir, "network");
  EXPECT_NE(network.find("veth"), std::string::npos) << network;

  if (!HasFailure()) fs::remove_all(dir);
}

}  // namespace
}  // namespace rcal::dds
