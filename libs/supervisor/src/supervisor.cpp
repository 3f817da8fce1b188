#include "rcal/supervisor/supervisor.hpp"

#include <algorithm>
#include <set>
#include <stdexcept>

namespace rcal::supervisor {

const char* ToString(State state) {
  switch (state) {
    case State::kStopped:
      return "stopped";
    case State::kRunning:
      return "running";
    case State::kBackoff:
      return "backoff";
    case State::kStopping:
      return "stopping";
    case State::kFailed:
      return "failed";
  }
  return "?";
}

Supervisor::Supervisor(std::vector<ProcessSpec> table, Policy policy)
    : table_(std::move(table)), policy_(policy) {
  if (table_.empty()) throw std::invalid_argument("supervisor: empty process table");
  std::set<std::string> names;
  for (size_t i = 0; i < table_.size(); ++i) {
    const auto& p = table_[i];
    const std::string where = "processes[" + std::to_string(i) + "]";
    if (p.name.empty()) throw std::invalid_argument(where + ".name: empty");
    if (!names.insert(p.name).second)
      throw std::invalid_argument(where + ".name: duplicate " + p.name);
    if (p.argv.empty() || p.argv[0].empty())
      throw std::invalid_argument(where + ".argv: empty (" + p.name + ")");
    Entry e;
    e.status.name = p.name;
    e.status.backoff = policy_.backoff_initial;
    entries_.push_back(e);
  }
}

int Supervisor::Find(const std::string& name) const {
  for (size_t i = 0; i < entries_.size(); ++i)
    if (entries_[i].status.name == name) return static_cast<int>(i);
  return -1;
}

int Supervisor::FindPid(int pid) const {
  if (pid <= 0) return -1;
  for (size_t i = 0; i < entries_.size(); ++i)
    if (entries_[i].status.pid == pid && (entries_[i].status.state == State::kRunning ||
                                          entries_[i].status.state == State::kStopping))
      return static_cast<int>(i);
  return -1;
}

Action Supervisor::StartAction(Entry& e, const std::string& reason) {
  e.status.state = State::kRunning;
  e.status.pid = 0;
  e.status.last_reason = reason;
  e.last_heartbeat = -1;
  e.killed = false;
  return {Action::Kind::kStart, e.status.name, 0, reason};
}

std::vector<Action> Supervisor::StartAll(double t) {
  std::vector<Action> out;
  if (shutting_down_) return out;
  for (auto& e : entries_) {
    if (e.status.state != State::kStopped) continue;
    e.started_at = t;
    out.push_back(StartAction(e, "start"));
  }
  return out;
}

void Supervisor::OnStarted(const std::string& name, int pid, double t) {
  const int i = Find(name);
  if (i < 0) return;
  Entry& e = entries_[i];
  e.status.pid = pid;
  e.started_at = t;
  e.last_heartbeat = -1;
}

std::vector<Action> Supervisor::OnStartFailed(const std::string& name, const std::string& error,
                                              double t) {
  std::vector<Action> out;
  const int i = Find(name);
  if (i < 0) return out;
  Entry& e = entries_[i];
  e.started_at = t;
  Crashed(e, t, 127, "start failed: " + error);
  if (shutting_down_) ContinueShutdown(t, out);
  return out;
}

void Supervisor::Crashed(Entry& e, double t, int exit, const std::string& reason) {
  auto& s = e.status;
  const double run = t - e.started_at;
  s.pid = 0;
  s.last_exit = exit;
  s.last_reason = reason;
  if (shutting_down_) {
    s.state = State::kStopped;
    return;
  }
  if (run >= policy_.healthy_run) {
    s.backoff = policy_.backoff_initial;
    e.fast_crashes.clear();
  }
  if (run < policy_.fast_crash) {
    e.fast_crashes.push_back(t);
    std::erase_if(e.fast_crashes, [&](double c) { return c < t - policy_.crash_window; });
    if (static_cast<int>(e.fast_crashes.size()) >= policy_.max_fast_crashes) {
      s.state = State::kFailed;
      s.last_reason = "gave up after " + std::to_string(e.fast_crashes.size()) +
                      " fast crashes within " + std::to_string(policy_.crash_window) +
                      " s (last: " + reason + ")";
      return;
    }
  }
  s.state = State::kBackoff;
  s.next_start = t + s.backoff;
  s.backoff = std::min(s.backoff * policy_.backoff_factor, policy_.backoff_max);
}

std::vector<Action> Supervisor::OnExited(int pid, int exit, double t) {
  std::vector<Action> out;
  const int i = FindPid(pid);
  if (i < 0) return out;
  Entry& e = entries_[i];
  std::string reason = exit >= 0 ? "exited with code " + std::to_string(exit)
                                 : "killed by signal " + std::to_string(-exit);
  if (e.status.state == State::kStopping && !shutting_down_)
    reason = e.status.last_reason + "; " + reason;  // the stale-heartbeat restart
  Crashed(e, t, exit, reason);
  if (shutting_down_) ContinueShutdown(t, out);
  return out;
}

void Supervisor::OnHeartbeat(const std::string& name, double t) {
  const int i = Find(name);
  if (i < 0) return;
  entries_[i].last_heartbeat = std::max(entries_[i].last_heartbeat, t);
}

void Supervisor::Interrupt(Entry& e, double t, const std::string& reason,
                           std::vector<Action>& out) {
  e.status.state = State::kStopping;
  e.status.last_reason = reason;
  e.kill_deadline = t + policy_.stop_timeout;
  e.killed = false;
  out.push_back({Action::Kind::kInterrupt, e.status.name, e.status.pid, reason});
}

std::vector<Action> Supervisor::Tick(double t) {
  std::vector<Action> out;
  for (size_t i = 0; i < entries_.size(); ++i) {
    Entry& e = entries_[i];
    auto& s = e.status;
    const ProcessSpec& spec = table_[i];
    if (s.state == State::kBackoff && !shutting_down_ && t >= s.next_start) {
      ++s.restarts;
      e.started_at = t;
      out.push_back(StartAction(e, "restart after: " + s.last_reason));
    } else if (s.state == State::kRunning && s.pid > 0 && spec.heartbeat_timeout > 0 &&
               !shutting_down_) {
      const double ref = std::max(e.last_heartbeat, e.started_at + policy_.startup_grace);
      if (t - ref > spec.heartbeat_timeout)
        Interrupt(e, t,
                  e.last_heartbeat < 0
                      ? "heartbeat stale: none since the start"
                      : "heartbeat stale: none for " + std::to_string(t - e.last_heartbeat) + " s",
                  out);
    } else if (s.state == State::kStopping && !e.killed && t >= e.kill_deadline) {
      e.killed = true;
      out.push_back({Action::Kind::kKill, s.name, s.pid,
                     "no exit " + std::to_string(policy_.stop_timeout) + " s after SIGINT"});
    }
  }
  if (shutting_down_) ContinueShutdown(t, out);
  return out;
}

std::vector<Action> Supervisor::Shutdown(double t) {
  std::vector<Action> out;
  shutting_down_ = true;
  ContinueShutdown(t, out);
  return out;
}

void Supervisor::ContinueShutdown(double t, std::vector<Action>& out) {
  for (auto& e : entries_)
    if (e.status.state == State::kBackoff) {
      e.status.state = State::kStopped;
      e.status.last_reason = "shutdown";
    }
  for (const auto& e : entries_)
    if (e.status.state == State::kStopping) return;  // one at a time
  for (auto it = entries_.rbegin(); it != entries_.rend(); ++it)
    if (it->status.state == State::kRunning) {
      Interrupt(*it, t, "shutdown", out);
      return;
    }
}

bool Supervisor::Done() const {
  if (!shutting_down_) return false;
  for (const auto& e : entries_)
    if (e.status.state == State::kRunning || e.status.state == State::kStopping) return false;
  return true;
}

std::vector<ProcessStatus> Supervisor::Status() const {
  std::vector<ProcessStatus> out;
  for (const auto& e : entries_) out.push_back(e.status);
  return out;
}

const ProcessStatus& Supervisor::status(const std::string& name) const {
  const int i = Find(name);
  if (i < 0) throw std::out_of_range("supervisor: no process " + name);
  return entries_[i].status;
}

}  // namespace rcal::supervisor
