// Shared by the service mains: a stop flag set by SIGINT/SIGTERM and repository-relative paths.
#pragma once

#include <csignal>
#include <functional>
#include <string>

namespace rcal::services {

/// Installs SIGINT/SIGTERM handlers that set the flag StopRequested() reads.
void InstallStopHandlers();
/// True once SIGINT or SIGTERM arrived.
bool StopRequested();

/// Serves incoming messages until SIGINT/SIGTERM: `handle(timeout_ms)` is the transport's
/// HandleTimeout (negative on error). Returns 0 after a requested stop, 1 (logged) on a transport
/// error; EINTR from the stop signal is not an error.
int ServeUntilStopped(const std::function<int(int)>& handle);

/// `path` if it exists as given (relative to the working directory), else the same path under
/// the repository the binary was built from (so `config/robots/grb3016.yaml` works anywhere).
std::string RepoPath(const std::string& path);

/// Monotonic wall clock [µs] (for pacing and the supervisor only; filters use message utime).
long long MonotonicMicros();

}  // namespace rcal::services
