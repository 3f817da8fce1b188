// Shared by the service mains: a stop flag set by SIGINT/SIGTERM and repository-relative paths.
#pragma once

#include <csignal>
#include <string>

namespace rcal::services {

/// Installs SIGINT/SIGTERM handlers that set the flag StopRequested() reads.
void InstallStopHandlers();
/// True once SIGINT or SIGTERM arrived.
bool StopRequested();

/// `path` if it exists as given (relative to the working directory), else the same path under
/// the repository the binary was built from (so `config/robots/grb3016.yaml` works anywhere).
std::string RepoPath(const std::string& path);

/// Monotonic wall clock [µs] (for pacing and the supervisor only; filters use message utime).
long long MonotonicMicros();

}  // namespace rcal::services
