// rcal_dds_echo: a separate DDS subscriber for the tests (Cyclone C API, nothing of the bridge
// but its topic names, QoS and generated types). Prints every sample it takes, one line each,
// fields as key=value with doubles in hex (%a, exact), and exits 0 after --count samples, 3 when
// the guard runs out first.
//
//   rcal_dds_echo --domain N --topic kinematic_params|calibration_status|tool_pose
//                 [--count N] [--guard SECONDS]
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "rcal/dds/convert.hpp"
#include "rcal/dds/dds_common.hpp"

namespace {

using namespace rcal::dds;

std::string Hex(const double* v, size_t n) {
  std::string s;
  char buf[64];
  for (size_t i = 0; i < n; ++i) {
    std::snprintf(buf, sizeof buf, "%s%a", i ? "," : "", v[i]);
    s += buf;
  }
  return s;
}

std::string Header(const std_msgs_msg_dds__Header_& h) {
  return "sec=" + std::to_string(h.stamp.sec) + " nanosec=" + std::to_string(h.stamp.nanosec) +
         " frame_id=" + std::string(h.frame_id ? h.frame_id : "");
}

void Print(const KinematicParams& d) {
  std::string names, identified;
  for (uint32_t i = 0; i < d.names._length; ++i) {
    if (i) names += ',';
    names += d.names._buffer[i];
  }
  for (uint32_t i = 0; i < d.identified._length; ++i) {
    if (i) identified += ',';
    identified += d.identified._buffer[i] ? '1' : '0';
  }
  std::printf(
      "kinematic_params %s robot_id=%s model_id=%s names=%s values=%s sigmas=%s "
      "identified=%s poses_used=%d\n",
      Header(d.header).c_str(), d.robot_id, d.model_id, names.c_str(),
      Hex(d.values._buffer, d.values._length).c_str(),
      Hex(d.sigmas._buffer, d.sigmas._length).c_str(), identified.c_str(), d.poses_used);
}

void Print(const CalibrationStatus& d) {
  std::printf(
      "calibration_status %s robot_id=%s poses_accepted=%d poses_rejected=%d "
      "condition_number=%a rms_position_residual=%a rms_orientation_residual=%a "
      "last_nis=%a relinearizations=%d converged=%d\n",
      Header(d.header).c_str(), d.robot_id, d.poses_accepted, d.poses_rejected, d.condition_number,
      d.rms_position_residual, d.rms_orientation_residual, d.last_nis, d.relinearizations,
      d.converged ? 1 : 0);
}

void Print(const ToolPose& d) {
  std::printf(
      "tool_pose %s robot_id=%s position=%s velocity=%s has_orientation=%d "
      "orientation=%s\n",
      Header(d.header).c_str(), d.robot_id, Hex(d.position, 3).c_str(), Hex(d.velocity, 3).c_str(),
      d.has_orientation ? 1 : 0, Hex(d.orientation, 4).c_str());
}

template <typename T>
int Echo(dds_entity_t participant, const char* topic_name, dds_qos_t* qos, int count,
         double guard_s) {
  const dds_entity_t topic =
      dds_create_topic(participant, Descriptor<T>(), topic_name, qos, nullptr);
  const dds_entity_t reader = dds_create_reader(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  if (topic < 0 || reader < 0) {
    std::fprintf(stderr, "rcal_dds_echo: cannot create the reader of %s\n", topic_name);
    return 1;
  }
  int taken = 0;
  const dds_time_t end = dds_time() + static_cast<dds_time_t>(guard_s * 1e9);
  while (taken < count) {
    if (dds_time() > end) {
      std::fprintf(stderr, "rcal_dds_echo: %d of %d samples before the guard\n", taken, count);
      return 3;
    }
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    const int n = dds_take(reader, samples, &info, 1, 1);
    if (n > 0 && info.valid_data) {
      Print(*static_cast<const T*>(samples[0]));
      std::fflush(stdout);
      ++taken;
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    if (n <= 0) dds_sleepfor(DDS_MSECS(10));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  int domain = 0, count = 1;
  double guard_s = 60;
  std::string topic;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--domain")
      domain = std::atoi(argv[i + 1]);
    else if (k == "--topic")
      topic = argv[i + 1];
    else if (k == "--count")
      count = std::atoi(argv[i + 1]);
    else if (k == "--guard")
      guard_s = std::atof(argv[i + 1]);
    else {
      std::fprintf(stderr, "rcal_dds_echo: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  try {
    EnsureCycloneConfig();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rcal_dds_echo: %s\n", e.what());
    return 1;
  }
  EntityGuard participant(
      dds_create_participant(static_cast<dds_domainid_t>(domain), nullptr, nullptr));
  if (participant.get() < 0) {
    std::fprintf(stderr, "rcal_dds_echo: dds_create_participant: %s\n",
                 dds_strretcode(participant.get()));
    return 1;
  }
  if (topic == "kinematic_params")
    return Echo<KinematicParams>(participant.get(), kKinematicParamsTopic, LatchedQos(), count,
                                 guard_s);
  if (topic == "calibration_status")
    return Echo<CalibrationStatus>(participant.get(), kCalibrationStatusTopic, LatchedQos(), count,
                                   guard_s);
  if (topic == "tool_pose")
    return Echo<ToolPose>(participant.get(), kToolPoseTopic, StreamQos(), count, guard_s);
  std::fprintf(stderr, "rcal_dds_echo: --topic kinematic_params|calibration_status|tool_pose\n");
  return 2;
}
