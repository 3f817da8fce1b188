#include "pose_log.hpp"

#include <array>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"

namespace rcal::tool {

bool IsLcmLog(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<unsigned char, 4> b{};
  if (!in.read(reinterpret_cast<char*>(b.data()), b.size())) return false;
  return b == std::array<unsigned char, 4>{0xED, 0xA1, 0xDA, 0x01};
}

PoseLog ReadPoseLog(const std::filesystem::path& path, const kinematics::KinematicModel& model,
                    const std::string& channel) {
  lcm::LogFile log(path.string(), "r");
  if (!log.good()) throw std::runtime_error(path.string() + ": cannot read the LCM log");
  PoseLog out;
  int64_t last_utime = std::numeric_limits<int64_t>::min();
  const auto skip = [&](const std::string& why) {
    ++out.skipped;
    if (out.first_skip_reason.empty())
      out.first_skip_reason = "event " + std::to_string(out.events) + ": " + why;
  };
  while (const lcm::LogEvent* e = log.readNextEvent()) {
    if (e->channel != channel) continue;
    ++out.events;
    pose_measurement_t msg;
    if (msg.decode(e->data, 0, e->datalen) < 0) {
      skip("does not decode as pose_measurement_t");
      continue;
    }
    std::string error;
    auto z = transport::FromMessage(msg, &error);
    if (z) error = kinematics::Validate(model, *z);
    if (!error.empty()) {
      skip(error);
      continue;
    }
    if (msg.utime <= last_utime) {
      skip("utime " + std::to_string(msg.utime) + " not after the previous pose");
      continue;
    }
    last_utime = msg.utime;
    out.poses.push_back({std::move(*z), msg.utime, msg.pose_index});
  }
  return out;
}

io::PoseDataset ToPoseDataset(const PoseLog& log, int num_joints) {
  io::PoseDataset d;
  d.num_joints = num_joints;
  d.has_orientation = !log.poses.empty();
  for (const auto& p : log.poses) {
    io::PoseSample s;
    s.q = p.measurement.q;
    s.p_WM_W = p.measurement.p_WM_W;
    s.has_orientation = p.measurement.has_orientation;
    if (s.has_orientation) {
      const Eigen::Quaterniond q(p.measurement.R_EI);
      s.q_EI_wxyz = Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
    }
    s.time = static_cast<double>(p.utime) * 1e-6;
    d.has_orientation = d.has_orientation && s.has_orientation;
    d.samples.push_back(std::move(s));
  }
  return d;
}

}  // namespace rcal::tool
