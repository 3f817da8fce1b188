// logger: records every channel to LCM event logs (readable by lcm-logplayer and lcm-logger's
// tools), starting a new file when one reaches --max-bytes, and appends every KINEMATIC_PARAMS
// to a readable CSV history (utime, poses_used, then value and σ of each parameter).
// Event timestamps are the receive time (as lcm-logger's); the messages keep their sensor utime.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <memory>

#include "rcal/kinematic_params_t.hpp"
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
    transport::LcmTransport t(lcm_url);
    transport::Health health("logger");
    int file_index = 0;
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
    std::ofstream csv(std::filesystem::path(dir) / "kinematic_params.csv", std::ios::app);
    bool csv_header =
        std::filesystem::file_size(std::filesystem::path(dir) / "kinematic_params.csv") > 0;
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
      if (log->writeEvent(&ev) != 0) health.Error("log write failed");
      bytes += size + static_cast<long long>(channel.size()) + 28;
    });
    t.Subscribe<kinematic_params_t>(
        transport::channels::kKinematicParams,
        [&](const kinematic_params_t& m) {
          if (!csv_header) {
            csv << "utime,poses_used";
            for (const auto& n : m.names)
              csv << "," << n << ","
                  << "sigma_" << n;
            csv << "\n";
            csv_header = true;
          }
          csv << m.utime << "," << m.poses_used;
          csv.precision(17);
          for (int i = 0; i < m.num_params; ++i) csv << "," << m.values[i] << "," << m.sigmas[i];
          csv << "\n" << std::flush;
          health.Tick(m.utime, t);
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
