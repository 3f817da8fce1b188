// config/processes.yaml: the supervisor's process table (schema rcal.processes/1).
//
//   schema: rcal.processes/1          # required, exactly this
//   lcm_url: udpm://...?ttl=0          # optional: exported as RCAL_LCM_URL to every child
//   log_dir: log                       # optional: one <name>.log per process (default log)
//   policy:                            # optional, every key optional (supervisor::Policy)
//     backoff_initial: 0.5             # [s]
//     backoff_factor: 2
//     backoff_max: 30                  # [s]
//     healthy_run: 30                  # [s]
//     fast_crash: 5                    # [s]
//     max_fast_crashes: 5
//     crash_window: 60                 # [s]
//     stop_timeout: 5                  # [s] SIGINT → SIGKILL
//     startup_grace: 10                # [s]
//   processes:                         # required, started in this order, stopped in reverse
//     - name: logger                   # required, unique
//       command: [logger, --dir, log]  # required: program (a services/ name or a path) + args
//       heartbeat_timeout: 0           # optional [s]; 0: HEALTH not checked
//
// Unknown keys and wrong types are errors naming the key and the line.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "rcal/supervisor/supervisor.hpp"

namespace rcal::services {

struct ProcessTable {
  std::string lcm_url;  ///< empty: the children inherit RCAL_LCM_URL or the default
  std::string log_dir = "log";
  supervisor::Policy policy;
  std::vector<supervisor::ProcessSpec> processes;
};

/// Parses YAML text; `source` names the file in errors. Throws std::runtime_error
/// "SOURCE: KEY.PATH: what is wrong (line N)".
ProcessTable ParseProcessTable(const std::string& text, const std::string& source = "<text>");
/// Reads and parses a file.
ProcessTable LoadProcessTable(const std::filesystem::path& path);

}  // namespace rcal::services
