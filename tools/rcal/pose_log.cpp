#include "pose_log.hpp"

#include <spdlog/spdlog.h>
#include <array>
#include <cmath>
#include <fstream>
#include <limits>

#include <cstdio>
#include <stdexcept>

#include "rcal/geometry/so3.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/lcm_schema.hpp"

namespace rcal::tool {

bool IsLcmLog(const std::filesystem::path& path) {
  return io::IsLcmLogFile(path);
}

void CheckLogGaps(const std::string& path, const io::LcmLogStats& stats, bool allow_gaps) {
  std::printf("%s: %s\n", path.c_str(), stats.Summary().c_str());
  for (const auto& r : stats.reasons) std::printf("  %s\n", r.c_str());
  std::fflush(stdout);
  if (!stats.lost()) return;
  if (!allow_gaps)
    throw std::runtime_error(path + ": the log lost data (" + stats.Summary() +
                             "); --allow-gaps goes on with what could be read");
  spdlog::warn("{}: the log lost data ({}); going on with what could be read (--allow-gaps)", path,
               stats.Summary());
}

PoseLog ReadPoseLog(const std::filesystem::path& path, const kinematics::KinematicModel& model,
                    const std::string& channel) {
  io::LcmLogReader reader(path);  // throws naming the file
  PoseLog out;
  int64_t last_utime = std::numeric_limits<int64_t>::min();
  const auto skip = [&](const std::string& why) {
    ++out.skipped;
    if (out.first_skip_reason.empty())
      out.first_skip_reason = "event " + std::to_string(out.events) + ": " + why;
  };
  while (const auto e = reader.Next()) {
    if (e->channel != channel) continue;
    ++out.events;
    pose_measurement_t msg;
    // Checked against the schema before the generated decoder allocates (num_joints = 2^28 + 6).
    if (const std::string why =
            transport::DecodePoseMeasurement(e->data.data(), e->data.size(), &msg);
        !why.empty()) {
      reader.Skip(*e, "does not decode as pose_measurement_t: " + why);
      skip("does not decode as pose_measurement_t: " + why);
      continue;
    }
    std::string error;
    // Invalid values (not finite, wrong dimension, not for this robot) are refused as
    // ekf_identifier refuses them: counted here, not a loss of the log's.
    auto z = transport::FromMessage(msg, &error, &model);
    if (z) error = kinematics::Validate(model, *z);
    std::optional<kinematics::EffectContext> context;
    if (z && error.empty()) {
      context = transport::ContextFromMessage(msg, &error);
      if (!context) z.reset();
    }
    if (!error.empty()) {
      skip(error);
      continue;
    }
    if (msg.utime <= last_utime) {
      skip("utime " + std::to_string(msg.utime) + " not after the previous pose");
      continue;
    }
    last_utime = msg.utime;
    out.poses.push_back({std::move(*z), msg.utime, msg.pose_index, std::move(*context)});
  }
  out.log = reader.stats();
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
    // The pose's context as logged: the cell's time when it carries one (what ekf_identifier's
    // thermal-by-time effect reads), else the sensor time; temperature, payload, approach
    // direction (absent when not known).
    s.time =
        std::isfinite(p.context.time_s) ? p.context.time_s : static_cast<double>(p.utime) * 1e-6;
    s.temperature = p.context.temperature_c;
    s.payload = p.context.payload_kg;
    s.dq_sign = p.context.dq_sign;
    s.row = static_cast<int>(d.samples.size()) + 1;  // the k-th pose read from the log
    d.has_orientation = d.has_orientation && s.has_orientation;
    d.samples.push_back(std::move(s));
  }
  return d;
}

}  // namespace rcal::tool
