// logger: records every channel to LCM event logs (readable by lcm-logplayer and lcm-logger's
// tools), starting a new file when one reaches --max-bytes, and appends every KINEMATIC_PARAMS
// to a readable CSV history (utime, poses_used, then value and σ of each parameter).
// Event timestamps are the receive time (as lcm-logger's); the messages keep their sensor utime.
//
// Restarts (the supervisor runs the same command line after a crash or SIGKILL): earlier files
// are never reopened for writing. The new process starts the file after the highest-numbered
// `<prefix>.NNNN.lcmlog` in --dir (a name whose NNNN is not a number or too large is skipped with
// a warning, log_files.hpp), so the earlier file keeps every event written before the kill
// (each event is flushed to the file as it is written, so at most the event being written when
// the process died is cut short; lcm-logplayer and lcm::LogFile readers stop at it). The CSV is
// appended to; a row cut short by a kill (no final newline) is removed before the first new row
// (it is the only part of the file ever rewritten), and each row goes to the file in one write.
//
// Losses: the logger records every message it receives, duplicates included (the log is the
// bus's record), and counts in HEALTH gaps the POSE_MEASUREMENT pose_index values that never
// arrived (a step of more than one; a step back is a restarted still_window). HEALTH's time is
// the KINEMATIC_PARAMS and POSE_MEASUREMENT utimes that pass a time gate (a far-future utime
// never schedules the heartbeat).
#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "log_files.hpp"
#include "rcal/estimation/time_gate.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

namespace fs = std::filesystem;

// The CSV history, appended one whole row per write(2). A row cut short by a kill (the file does
// not end in a newline) is cut off at start.
class CsvHistory {
 public:
  explicit CsvHistory(const fs::path& path) : path_(path) {
    if (fs::exists(path)) {
      const auto size = fs::file_size(path);
      std::ifstream in(path, std::ios::binary);
      std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      if (text.size() != size) throw std::runtime_error(path.string() + ": cannot read");
      if (!text.empty() && text.back() != '\n') {
        const auto keep = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
        spdlog::warn("{}: removing a row cut short by a kill ({} bytes)", path.string(),
                     text.size() - keep);
        fs::resize_file(path, keep);
        text.resize(keep);
      }
      has_header_ = !text.empty();
    }
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd_ < 0) throw std::runtime_error(path.string() + ": " + std::strerror(errno));
  }
  ~CsvHistory() {
    if (fd_ >= 0) ::close(fd_);
  }
  CsvHistory(const CsvHistory&) = delete;
  CsvHistory& operator=(const CsvHistory&) = delete;
  bool has_header() const { return has_header_; }
  /// Appends `text` (whole lines). False on a write error.
  bool Append(const std::string& text, bool header) {
    size_t done = 0;
    while (done < text.size()) {
      const ssize_t n = ::write(fd_, text.data() + done, text.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      done += static_cast<size_t>(n);
    }
    if (header) has_header_ = true;
    return true;
  }

 private:
  fs::path path_;
  int fd_ = -1;
  bool has_header_ = false;
};

}  // namespace

int main(int argc, char** argv) {
  using namespace rcal;
  std::string dir = "log", prefix = "rcal", lcm_url;
  long long max_bytes = 256LL << 20;
  CLI::App app{
      "logger: records every LCM channel to rotating event logs (<dir>/<prefix>.NNNN.lcmlog) and "
      "the KINEMATIC_PARAMS history to <dir>/kinematic_params.csv."};
  app.add_option("--dir", dir, "output directory")->capture_default_str();
  app.add_option("--prefix", prefix, "log file prefix")->capture_default_str();
  app.add_option("--max-bytes", max_bytes, "start a new log file beyond this size [bytes]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  CLI11_PARSE(app, argc, argv);

  try {
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
    int file_index = logger::NextFileIndex(dir, prefix);
    long long bytes = 0;
    int64_t event = 0;
    std::unique_ptr<lcm::LogFile> log;
    auto open_next = [&] {
      char name[64];
      std::snprintf(name, sizeof name, ".%04d.lcmlog", file_index++);
      const auto path = std::filesystem::path(dir) / (prefix + name);
      log = std::make_unique<lcm::LogFile>(path.string(), "w");
      if (!log->good()) throw std::runtime_error(path.string() + ": cannot write");
      bytes = 0;
      spdlog::info("logging to {}", path.string());
    };
    open_next();
    CsvHistory csv(std::filesystem::path(dir) / "kinematic_params.csv");
    t.SubscribeRaw(".*", [&](const std::string& channel, const void* data, int size) {
      health.Received();
      if (bytes > 0 && bytes + size > max_bytes) open_next();
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
        transport::channels::kKinematicParams,
        [&](const kinematic_params_t& m) {
          if (!csv.has_header()) {
            std::string header = "utime,poses_used";
            for (const auto& n : m.names) header += "," + n + ",sigma_" + n;
            if (!csv.Append(header + "\n", true)) health.Error("CSV write failed");
          }
          std::ostringstream row;
          row.precision(17);
          row << m.utime << "," << m.poses_used;
          for (int i = 0; i < m.num_params; ++i) row << "," << m.values[i] << "," << m.sigmas[i];
          row << "\n";
          if (!csv.Append(row.str(), false)) health.Error("CSV write failed");
          beat(m.utime);
        },
        [&](const std::string& e) { health.Rejected(e); });
    t.Subscribe<pose_measurement_t>(
        transport::channels::kPoseMeasurement,
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
    spdlog::info("stopped after {} events", event);
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
