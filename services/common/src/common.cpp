#include "rcal/services/common.hpp"

#include <spdlog/spdlog.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>

namespace rcal::services {
namespace {
volatile std::sig_atomic_t g_stop = 0;
extern "C" void OnStopSignal(int) {
  g_stop = 1;
}
}  // namespace

void InstallStopHandlers() {
  struct sigaction sa {};
  sa.sa_handler = OnStopSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

bool StopRequested() {
  return g_stop != 0;
}

std::string RepoPath(const std::string& path) {
  if (path.empty() || std::filesystem::path(path).is_absolute() || std::filesystem::exists(path))
    return path;
  const auto in_repo = std::filesystem::path(RCAL_SOURCE_DIR) / path;
  return std::filesystem::exists(in_repo) ? in_repo.string() : path;
}

long long MonotonicMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

int ServeUntilStopped(const std::function<int(int)>& handle) {
  while (!StopRequested()) {
    if (handle(100) < 0 && errno != EINTR) {
      spdlog::error("LCM error: {}", std::strerror(errno));
      return 1;
    }
  }
  return 0;
}

}  // namespace rcal::services
