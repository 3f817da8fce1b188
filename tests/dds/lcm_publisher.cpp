// rcal_dds_test_publisher: the LCM side of the bridge tests, a separate process standing in for
// the ekf_identifier and the filters. Publishes test_messages.hpp's version V every 100 ms (wall
// clock, pacing only): KINEMATIC_PARAMS (robot --robot-id), CALIBRATION_STATUS, then the k-th
// ORIENTATION + TOOL_POSITION (k = 0, 1, ...), until SIGINT/SIGTERM/SIGKILL; with --ins, on
// INS_ORIENTATION + INS_TOOL_POSITION instead (aided_ins's channels).
//
//   rcal_dds_test_publisher --lcm-url URL --version V [--robot-id ID] [--ins 1]
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "rcal/services/common.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"
#include "test_messages.hpp"

int main(int argc, char** argv) {
  std::string url, robot_id = "robot_a";
  int version = 1;
  bool ins = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--lcm-url")
      url = argv[i + 1];
    else if (k == "--version")
      version = std::atoi(argv[i + 1]);
    else if (k == "--robot-id")
      robot_id = argv[i + 1];
    else if (k == "--ins")
      ins = std::atoi(argv[i + 1]) != 0;
    else
      return 2;
  }
  namespace ch = rcal::transport::channels;
  using namespace rcal::dds::testing;
  rcal::services::InstallStopHandlers();
  rcal::transport::LcmTransport t(url);
  for (int k = 0; !rcal::services::StopRequested(); ++k) {
    t.Publish(ch::kKinematicParams, TestParams(version, robot_id));
    t.Publish(ch::kCalibrationStatus, TestStatus(version));
    t.Publish(ins ? ch::kInsOrientation : ch::kOrientation, TestOrientation(version, k));
    t.Publish(ins ? ch::kInsToolPosition : ch::kToolPosition, TestToolPosition(version, k));
    usleep(100'000);
  }
  return 0;
}
