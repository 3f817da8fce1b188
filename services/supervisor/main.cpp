// supervisor: starts the process table of config/processes.yaml and keeps it running, after the
// pure policy in libs/supervisor (restart with backoff, give up on repeated fast crashes, stale
// HEALTH, SIGINT then SIGKILL to each child's process group, logger first started and last
// stopped). Each child runs in its own process group with stdout/stderr appended to
// <log_dir>/<name>.log. Publishes SUPERVISOR_STATE at 1 Hz and on every change. SIGINT/SIGTERM
// stop the table cleanly; the supervisor exits when every child has exited.
//
// A command's program is taken as a path when it contains '/', else looked up as a service built
// beside this binary (<build>/services/NAME/NAME), else on PATH.
#include <fcntl.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <map>

#include "process_table.hpp"
#include "rcal/health_t.hpp"
#include "rcal/services/common.hpp"
#include "rcal/supervisor/supervisor.hpp"
#include "rcal/supervisor_state_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace fs = std::filesystem;

double Now() {
  return static_cast<double>(services::MonotonicMicros()) * 1e-6;
}

std::string ResolveProgram(const std::string& program, const fs::path& services_dir) {
  if (program.find('/') != std::string::npos) return services::RepoPath(program);
  const fs::path built = services_dir / program / program;
  if (fs::exists(built)) return built.string();
  return program;  // execvp searches PATH
}

pid_t StartChild(const supervisor::ProcessSpec& spec, const fs::path& services_dir,
                 const fs::path& log_dir, const std::string& lcm_url, std::string* error) {
  const fs::path log = log_dir / (spec.name + ".log");
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) {
    *error = log.string() + ": " + std::strerror(errno);
    return -1;
  }
  std::vector<std::string> argv = spec.argv;
  argv[0] = ResolveProgram(argv[0], services_dir);
  const pid_t pid = fork();
  if (pid < 0) {
    *error = std::string("fork: ") + std::strerror(errno);
    ::close(fd);
    return -1;
  }
  if (pid == 0) {
    setpgid(0, 0);
    dup2(fd, 1);
    dup2(fd, 2);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    if (!lcm_url.empty()) setenv("RCAL_LCM_URL", lcm_url.c_str(), 1);
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    execvp(args[0], args.data());
    std::fprintf(stderr, "supervisor: exec %s: %s\n", args[0], std::strerror(errno));
    _exit(127);
  }
  setpgid(pid, pid);  // also in the parent: no race with the first signal
  ::close(fd);
  return pid;
}

supervisor_state_t StateMessage(const supervisor::Supervisor& s) {
  supervisor_state_t m;
  m.utime = services::MonotonicMicros();
  for (const auto& st : s.Status()) {
    m.names.push_back(st.name);
    m.pids.push_back(st.pid);
    m.states.push_back(supervisor::ToString(st.state));
    m.restarts.push_back(st.restarts);
    m.last_exit.push_back(st.last_exit);
    m.reasons.push_back(st.last_reason);
  }
  m.num_processes = static_cast<int32_t>(m.names.size());
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  std::string config = "config/processes.yaml", lcm_url, log_dir, services_dir;
  CLI::App app{
      "supervisor: runs the pipeline's process table (config/processes.yaml), restarts what "
      "exits or stops sending HEALTH, publishes SUPERVISOR_STATE.\nSIGINT/SIGTERM: stops the "
      "table in reverse order (SIGINT, then SIGKILL after policy.stop_timeout)."};
  app.add_option("--config", config, "process table (schema rcal.processes/1)")
      ->capture_default_str();
  app.add_option("--lcm-url", lcm_url,
                 "LCM URL for the supervisor and its children "
                 "(default: the table's lcm_url, $RCAL_LCM_URL, built-in)");
  app.add_option("--log-dir", log_dir, "one <name>.log per process (default: the table's)");
  app.add_option("--services-dir", services_dir, "where the service binaries are built")
      ->default_str(RCAL_SERVICES_BINARY_DIR);
  CLI11_PARSE(app, argc, argv);
  if (services_dir.empty()) services_dir = RCAL_SERVICES_BINARY_DIR;

  try {
    const auto table = services::LoadProcessTable(services::RepoPath(config));
    if (lcm_url.empty()) lcm_url = table.lcm_url;
    lcm_url = transport::ResolveLcmUrl(lcm_url);
    if (log_dir.empty()) log_dir = table.log_dir;
    fs::create_directories(log_dir);
    services::InstallStopHandlers();

    transport::LcmTransport t(lcm_url);
    supervisor::Supervisor sup(table.processes, table.policy);
    t.Subscribe<rcal::health_t>(transport::channels::kHealth, [&](const rcal::health_t& h) {
      sup.OnHeartbeat(h.process, Now());
    });
    spdlog::info("supervisor: {} processes from {}, LCM {}, logs in {}", table.processes.size(),
                 config, lcm_url, log_dir);

    auto execute = [&](const std::vector<supervisor::Action>& actions, auto& self) -> void {
      for (const auto& a : actions) {
        switch (a.kind) {
          case supervisor::Action::Kind::kStart: {
            std::string error;
            const auto& spec = *std::find_if(sup.table().begin(), sup.table().end(),
                                             [&](const auto& p) { return p.name == a.name; });
            const pid_t pid = StartChild(spec, services_dir, log_dir, lcm_url, &error);
            if (pid > 0) {
              spdlog::info("start {} (pid {}): {}", a.name, pid, a.reason);
              sup.OnStarted(a.name, pid, Now());
            } else {
              spdlog::error("start {} failed: {}", a.name, error);
              self(sup.OnStartFailed(a.name, error, Now()), self);
            }
            break;
          }
          case supervisor::Action::Kind::kInterrupt:
            spdlog::info("SIGINT {} (pid {}): {}", a.name, a.pid, a.reason);
            if (a.pid > 0) kill(-a.pid, SIGINT);
            break;
          case supervisor::Action::Kind::kKill:
            spdlog::warn("SIGKILL {} (pid {}): {}", a.name, a.pid, a.reason);
            if (a.pid > 0) kill(-a.pid, SIGKILL);
            break;
        }
      }
    };

    execute(sup.StartAll(Now()), execute);
    double last_publish = -1;
    std::string last_states;
    while (true) {
      if (services::StopRequested() && !sup.shutting_down()) {
        spdlog::info("stopping");
        execute(sup.Shutdown(Now()), execute);
      }
      // Reap every exited child.
      int status = 0;
      pid_t pid;
      while ((pid = waitpid(-1, &status, WNOHANG)) > 0) {
        const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
        for (const auto& st : sup.Status())
          if (st.pid == pid) spdlog::info("{} (pid {}) exited: {}", st.name, pid, code);
        execute(sup.OnExited(pid, code, Now()), execute);
      }
      execute(sup.Tick(Now()), execute);

      auto msg = StateMessage(sup);
      std::string states;
      for (size_t i = 0; i < msg.states.size(); ++i)
        states += msg.states[i] + std::to_string(msg.pids[i]) + ",";
      if (states != last_states || Now() - last_publish >= 1.0) {
        t.Publish(transport::channels::kSupervisorState, msg);
        last_publish = Now();
        last_states = states;
      }
      if (sup.Done()) break;
      t.HandleTimeout(100);  // EINTR on signals is fine: the loop checks everything again
    }
    spdlog::info("all processes stopped");
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
