// The supervisor's policy core (procman and openpilot's manager are the models): which process to
// start, signal or kill, and when, as a deterministic function of events and time. No I/O: the
// caller (services/supervisor) forks, signals, reads heartbeats and feeds the results back.
//
// Per process:
//
//   kStopped ──Start──► kRunning ──exit──► kBackoff ──(t ≥ next_start)──► Start ─► kRunning
//                          │                  │
//                          │ stale heartbeat  └─ ≥ max_fast_crashes fast exits within
//                          ▼                     crash_window ─► kFailed (given up)
//                       kStopping ──(t ≥ deadline)──► Kill ──exit──► kBackoff
//
// - Backoff: the first restart waits backoff_initial, each later one backoff_factor times longer,
//   at most backoff_max; a run that lasted healthy_run resets it.
// - A fast crash is an exit after less than fast_crash of running. max_fast_crashes of them
//   within crash_window and the process is given up (kFailed), the others keep running.
// - Stale heartbeat: a process with heartbeat_timeout > 0 whose last heartbeat (or start, plus
//   startup_grace) is older than heartbeat_timeout is interrupted (SIGINT) and restarted.
// - Stopping a process: SIGINT to its process group, SIGKILL when it has not exited after
//   stop_timeout.
// - Order: StartAll starts the table in order (the logger first); Shutdown stops it in reverse
//   order, one process at a time, so the logger, first started, is stopped last and records the
//   others' last messages.
// Times are seconds on the caller's monotonic clock. The caller calls Tick regularly (≥ 10 Hz).
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace rcal::supervisor {

/// One row of the process table.
struct ProcessSpec {
  std::string name;               ///< unique; also the `process` field of its HEALTH messages
  std::vector<std::string> argv;  ///< program and arguments (argv[0] resolved by the caller)
  double heartbeat_timeout = 0;   ///< [s] restart when HEALTH is older; 0: not checked
};

/// Timing and give-up policy; defaults suit the pipeline.
struct Policy {
  double backoff_initial = 0.5;  ///< [s] wait before the first restart
  double backoff_factor = 2.0;   ///< each consecutive restart waits this much longer
  double backoff_max = 30.0;     ///< [s] longest wait
  double healthy_run = 30.0;     ///< [s] a run this long resets the backoff
  double fast_crash = 5.0;       ///< [s] an exit sooner than this after start is a fast crash
  int max_fast_crashes = 5;      ///< this many fast crashes within crash_window: give up
  double crash_window = 60.0;    ///< [s]
  double stop_timeout = 5.0;     ///< [s] from SIGINT to SIGKILL
  double startup_grace = 10.0;   ///< [s] after a start before heartbeats are checked
};

enum class State {
  kStopped,   ///< not running, not scheduled (before StartAll, after Shutdown)
  kRunning,   ///< started, pid known
  kBackoff,   ///< exited; restart scheduled
  kStopping,  ///< interrupted, waiting for the exit (SIGKILL at the deadline)
  kFailed,    ///< given up after repeated fast crashes
};

/// Short name of a state ("stopped", "running", "backoff", "stopping", "failed").
const char* ToString(State state);

/// What the caller must do.
struct Action {
  enum class Kind {
    kStart,      ///< fork/exec the process; report OnStarted or OnStartFailed
    kInterrupt,  ///< SIGINT to the process group of pid
    kKill,       ///< SIGKILL to the process group of pid
  };
  Kind kind;
  std::string name;
  int pid = 0;         ///< for kInterrupt and kKill
  std::string reason;  ///< why, in words (for the log)
  bool operator==(const Action&) const = default;
};

/// The state of one process, for SUPERVISOR_STATE and the log.
struct ProcessStatus {
  std::string name;
  State state = State::kStopped;
  int pid = 0;
  int restarts = 0;         ///< starts after the first
  int last_exit = 0;        ///< exit code, or −signal
  std::string last_reason;  ///< why it was last restarted, stopped or given up on
  double next_start = 0;    ///< [s] when kBackoff
  double backoff = 0;       ///< [s] the wait the next crash will get
};

class Supervisor {
 public:
  /// Throws std::invalid_argument on an empty table, an empty or duplicate name or empty argv.
  Supervisor(std::vector<ProcessSpec> table, Policy policy = {});

  /// Starts every process, in table order.
  std::vector<Action> StartAll(double t);
  /// The caller started `name` as `pid` (its own process group).
  void OnStarted(const std::string& name, int pid, double t);
  /// fork/exec failed: counted as an immediate crash.
  std::vector<Action> OnStartFailed(const std::string& name, const std::string& error, double t);
  /// A child exited. `exit` is the exit code, or −signal. Unknown pids are ignored.
  std::vector<Action> OnExited(int pid, int exit, double t);
  /// A HEALTH message from the process named `name` arrived at time t.
  void OnHeartbeat(const std::string& name, double t);
  /// Time passes: due restarts, stale heartbeats, SIGKILL deadlines, shutdown progress.
  std::vector<Action> Tick(double t);
  /// Stops everything in reverse table order, one at a time; no restarts from now on.
  std::vector<Action> Shutdown(double t);

  /// True after Shutdown once no process is running or stopping.
  bool Done() const;
  bool shutting_down() const { return shutting_down_; }
  const std::vector<ProcessSpec>& table() const { return table_; }
  const Policy& policy() const { return policy_; }
  /// One status per table row, in table order.
  std::vector<ProcessStatus> Status() const;
  /// The row named `name`; throws std::out_of_range when there is none.
  const ProcessStatus& status(const std::string& name) const;

 private:
  struct Entry {
    ProcessStatus status;
    double started_at = 0;
    double last_heartbeat = -1;        // < 0: none since the last start
    double kill_deadline = 0;          // kStopping: when SIGKILL is due
    bool killed = false;               // kStopping: SIGKILL sent
    std::vector<double> fast_crashes;  // times of recent fast crashes
  };
  int Find(const std::string& name) const;
  int FindPid(int pid) const;
  Action StartAction(Entry& e, const std::string& reason);
  void Interrupt(Entry& e, double t, const std::string& reason, std::vector<Action>& out);
  void Crashed(Entry& e, double t, int exit, const std::string& reason);
  void ContinueShutdown(double t, std::vector<Action>& out);

  std::vector<ProcessSpec> table_;
  Policy policy_;
  std::vector<Entry> entries_;
  bool shutting_down_ = false;
};

}  // namespace rcal::supervisor
