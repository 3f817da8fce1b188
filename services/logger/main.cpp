// logger: records every channel to LCM event logs (readable by lcm-logplayer and lcm-logger's
// tools), starting a new file when one reaches --max-bytes, and writes every KINEMATIC_PARAMS to a
// readable CSV history beside the log that holds its event (utime, poses_used, then value and σ
// of each parameter, then of each effect parameter of an identifier run with --effects):
// `<prefix>.NNNN.lcmlog` and `<prefix>.NNNN.kinematic_params.csv` (log_files.hpp). Event timestamps
// are the receive time (as lcm-logger's); the messages keep their sensor utime.
//
// Runs and restarts: each start of the logger (a new run, or the supervisor running the same
// command line after a crash or SIGKILL) takes the next number, one past the highest-numbered
// file of either kind in --dir (a name whose NNNN is not a number or too large is skipped with a
// warning), so a run never appends to an earlier run's files and its files are the newest.
// Earlier files are never reopened for writing, so the earlier log keeps every event written
// before a kill (each event is flushed to the file as it is written, so at most the event being
// written when the process died is cut short; lcm-logplayer and lcm::LogFile readers stop at it).
// A CSV row cut short by a kill (no final newline) is removed from the highest-numbered CSV at
// start (the only part of a file ever rewritten), and each row goes to the file in one write.
//
// Losses: the logger records every message it receives, duplicates included (the log is the
// bus's record), and counts in HEALTH gaps the POSE_MEASUREMENT pose_index values that never
// arrived (a step of more than one; a step back is a restarted still_window). HEALTH's time is
// the KINEMATIC_PARAMS and POSE_MEASUREMENT utimes that pass a time gate (a far-future utime
// never schedules the heartbeat).
//
// --cell FILE: the cell's channel names for KINEMATIC_PARAMS (the CSV) and POSE_MEASUREMENT (the
// gap count); every channel is recorded whatever its name.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "log_files.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

int main(int argc, char** argv) {
  using namespace rcal;
  std::string dir = "log", prefix = "rcal", lcm_url;
  long long max_bytes = 256LL << 20;
  CLI::App app{
      "logger: records every LCM channel to rotating event logs (<dir>/<prefix>.NNNN.lcmlog) and "
      "the KINEMATIC_PARAMS history beside each (<dir>/<prefix>.NNNN.kinematic_params.csv); each "
      "start takes the next NNNN."};
  app.add_option("--dir", dir, "output directory")->capture_default_str();
  app.add_option("--prefix", prefix, "log file prefix")->capture_default_str();
  app.add_option("--max-bytes", max_bytes, "start a new log file beyond this size [bytes]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  std::string cell_path;
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): its KINEMATIC_PARAMS and POSE_MEASUREMENT "
                 "channel names");
  CLI11_PARSE(app, argc, argv);

  try {
    io::CellChannels channels;
    if (!cell_path.empty()) channels = io::LoadCellSpec(services::RepoPath(cell_path)).channels;
    services::InstallStopHandlers();
    std::filesystem::create_directories(dir);
    // One subscription to every channel: a queue for seconds of the whole bus (a logger that
    // falls behind under load must catch up, not drop events).
    transport::LcmTransport t(lcm_url, transport::kAllChannelsQueueCapacity);
    transport::Health health("logger");
    // Only for the heartbeat's time: an hour's horizon (poses and estimates are sparse), no
    // gap count from time, and its refusals are not the logger's (it records every message).
    estimation::TimeGateSettings beat_time;
    beat_time.horizon_us = 3'600'000'000LL;
    beat_time.resync_samples = 3;
    beat_time.gap_factor = 0.0;
    estimation::TimeGate beat_gate(beat_time);
    auto beat = [&](int64_t utime) {
      beat_gate.SetCeiling(estimation::HostCeilingUs());
      if (estimation::Usable(beat_gate.Offer(utime))) health.Tick(utime, t);
    };
    std::optional<int32_t> last_pose_index;
    logger::LogFiles files(dir, prefix);
    long long bytes = 0;
    int64_t event = 0;
    std::unique_ptr<lcm::LogFile> log;
    auto open_current = [&] {
      const auto path = files.log_path();
      log = std::make_unique<lcm::LogFile>(path.string(), "w");
      if (!log->good()) throw std::runtime_error(path.string() + ": cannot write");
      bytes = 0;
      spdlog::info("logging to {} (parameters to {})", path.string(), files.csv_path().string());
    };
    open_current();
    t.SubscribeRaw(".*", [&](const std::string& channel, const void* data, int size) {
      health.Received();
      if (bytes > 0 && bytes + size > max_bytes) {
        files.Next();
        open_current();
      }
      lcm::LogEvent ev;
      ev.eventnum = event++;
      ev.timestamp = std::chrono::duration_cast<std::chrono::microseconds>(
                         std::chrono::system_clock::now().time_since_epoch())
                         .count();
      ev.channel = channel;
      ev.datalen = size;
      ev.data = const_cast<void*>(data);
      if (log->writeEvent(&ev) != 0 || std::fflush(log->getFilePtr()) != 0)
        health.Error("log write failed");
      bytes += size + static_cast<long long>(channel.size()) + 28;
    });
    t.Subscribe<kinematic_params_t>(
        channels.kinematic_params,
        [&](const kinematic_params_t& m) {
          std::string header = "utime,poses_used";
          for (const auto& n : m.names) header += "," + n + ",sigma_" + n;
          // An identifier run with --effects: its effect parameters after the geometric ones.
          for (const auto& n : m.effect_names) header += "," + n + ",sigma_" + n;
          std::ostringstream row;
          row.precision(17);
          row << m.utime << "," << m.poses_used;
          for (int i = 0; i < m.num_params; ++i) row << "," << m.values[i] << "," << m.sigmas[i];
          for (int i = 0; i < m.num_effect_params; ++i)
            row << "," << m.effect_values[i] << "," << m.effect_sigmas[i];
          row << "\n";
          if (!files.AppendParams(header + "\n", row.str())) health.Error("CSV write failed");
          beat(m.utime);
        },
        [&](const std::string& e) { health.Rejected(e); });
    t.Subscribe<pose_measurement_t>(
        channels.pose_measurement,
        [&](const pose_measurement_t& m) {
          if (last_pose_index && m.pose_index > *last_pose_index + 1) {
            health.Gap(m.pose_index - *last_pose_index - 1);
            spdlog::warn("POSE_MEASUREMENT: pose_index {} after {}: {} lost", m.pose_index,
                         *last_pose_index, m.pose_index - *last_pose_index - 1);
          }
          // A duplicate keeps the sequence where it is.
          if (!last_pose_index || m.pose_index != *last_pose_index) last_pose_index = m.pose_index;
          beat(m.utime);
        },
        [&](const std::string& e) { health.Rejected(e); });
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    health.Final(t);
    spdlog::info("stopped after {} events", event);
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
