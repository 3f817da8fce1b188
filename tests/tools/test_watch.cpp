// `rcal watch` (tools/rcal/cmd_watch.cpp) as a user runs it, inside a private network namespace:
// the test publishes an identifier's KINEMATIC_PARAMS and CALIBRATION_STATUS after each pose and
// reads the lines rcal watch prints. With --cell it listens on the cell's channels, and a
// positions-only cell prints no orientation residual (the status message carries 0 there: it
// printed "0.000 mrad").
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>
#include <thread>

#include "../integration/netns.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal {
namespace {

namespace fs = std::filesystem;
constexpr const char* kUrl = "udpm://239.255.76.67:7744?ttl=0";

std::string Read(const fs::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), {}};
}

// Runs `rcal watch --poses 2 ARGS` while publishing two poses' messages on `params_channel` and
// `status_channel` (RMS residuals 0.05 mm and 1.234 mrad); returns its exit code and its output.
std::pair<int, std::string> Watch(const fs::path& dir, const std::string& name,
                                  const std::vector<std::string>& args,
                                  const std::string& params_channel,
                                  const std::string& status_channel) {
  std::vector<std::string> argv = {RCAL_EXE,  "watch", "--lcm-url", kUrl,
                                   "--poses", "2",     "--idle",    "20"};
  argv.insert(argv.end(), args.begin(), args.end());
  const fs::path out = dir / (name + ".out");
  const pid_t pid = integration::Spawn(argv, out, dir / (name + ".err"));
  transport::LcmTransport t(kUrl);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  // Until it has printed both poses and exited (it starts listening at some point: repeat).
  while (integration::Running(pid) && std::chrono::steady_clock::now() < deadline) {
    for (int k = 1; k <= 2 && integration::Running(pid); ++k)
      for (int repeat = 0; repeat < 5; ++repeat) {
        kinematic_params_t p{};
        p.utime = 1'000'000 * k;
        p.robot_id = "test";
        p.model_id = "test";
        p.poses_used = k;
        p.num_params = 1;
        p.names = {"a1"};
        p.values = {1e-4 * k};
        p.sigmas = {1e-5};
        p.identified = {true};
        calibration_status_t s{};
        s.utime = p.utime;
        s.poses_accepted = k;
        s.rms_position_residual = 5e-5;
        s.rms_orientation_residual = 1.234e-3;
        t.Publish(params_channel, p);
        t.Publish(status_channel, s);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
  }
  if (integration::Running(pid)) kill(-pid, SIGKILL);
  const int rc = integration::Wait(pid);
  return {rc, Read(out) + Read(dir / (name + ".err"))};
}

TEST(RcalWatch, ThePositionsOnlyCellPrintsNoOrientationResidualOnItsChannels) {
  RCAL_IN_NAMESPACE("RcalWatch.ThePositionsOnlyCellPrintsNoOrientationResidualOnItsChannels");
  const fs::path dir = fs::temp_directory_path() / ("rcal_watch_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  // The UR10 cell (positions only), on channels of its own.
  std::string text = Read(RCAL_SOURCE_DIR "/config/cells/ur10.yaml");
  const std::string from = "../robots/ur10.urdf";
  ASSERT_NE(text.find(from), std::string::npos);
  text.replace(text.find(from), from.size(), RCAL_SOURCE_DIR "/config/robots/ur10.urdf");
  text += "channels: {kinematic_params: KP_W, calibration_status: CS_W}\n";
  std::ofstream(dir / "ur10.yaml") << text;
  auto [rc, out] = Watch(dir, "ur10", {"--cell", (dir / "ur10.yaml").string()}, "KP_W", "CS_W");
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("pose   2"), std::string::npos) << out;
  EXPECT_NE(out.find("RMS residual  0.050 mm (positions only)"), std::string::npos) << out;
  EXPECT_EQ(out.find("mrad  rejected"), std::string::npos) << out;
  // The demo's cell measures orientation: its residual is printed.
  std::tie(rc, out) = Watch(dir, "grb3016", {"--cell", "config/cells/grb3016.yaml"},
                            "KINEMATIC_PARAMS", "CALIBRATION_STATUS");
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("RMS residual  0.050 mm  1.234 mrad  rejected 0"), std::string::npos) << out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rcal
