// rcal status: what the live pipeline says about itself. Listens on LCM for HEALTH heartbeats and
// SUPERVISOR_STATE for --wait seconds (wall clock: this is a viewer, not a filter) and prints one
// row per process: the supervisor's state, pid and restarts, and the process's latest counts
// (received, rejected, published), sensor time and last error.
#include <chrono>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>

#include "command.hpp"
#include "rcal/health_t.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/supervisor_state_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::tool {
namespace {

struct Options {
  std::string lcm_url;
  double wait_s = 1.0;
  std::string json_path;
};

int Run(const Options& o) {
  transport::LcmTransport t(o.lcm_url);
  std::map<std::string, health_t> health;
  std::optional<supervisor_state_t> state;
  t.Subscribe<health_t>(transport::channels::kHealth,
                        [&](const health_t& h) { health[h.process] = h; });
  t.Subscribe<supervisor_state_t>(transport::channels::kSupervisorState,
                                  [&](const supervisor_state_t& s) { state = s; });
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.wait_s);
  while (std::chrono::steady_clock::now() < end) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                          end - std::chrono::steady_clock::now())
                          .count();
    t.HandleTimeout(static_cast<int>(std::max<long long>(1, std::min<long long>(left, 100))));
  }

  // Rows: the supervisor's table order, then processes only heard from.
  std::vector<std::string> names;
  std::set<std::string> seen;
  if (state)
    for (const auto& n : state->names)
      if (seen.insert(n).second) names.push_back(n);
  for (const auto& [n, h] : health)
    if (seen.insert(n).second) names.push_back(n);

  std::printf("rcal status on %s (%.1f s): supervisor %s\n", t.url().c_str(), o.wait_s,
              state ? "heard" : "not heard");
  std::printf("%-20s %-9s %8s %8s %10s %10s %10s %14s  %-15s %s\n", "process", "state", "pid",
              "restarts", "received", "rejected", "published", "sensor time[s]", "activity",
              "last error");
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& n : names) {
    std::string st = "-", err;
    long long pid = 0, restarts = 0;
    if (state)
      for (int i = 0; i < state->num_processes; ++i)
        if (state->names[i] == n) {
          st = state->states[i];
          pid = state->pids[i];
          restarts = state->restarts[i];
          err = state->reasons[i];
        }
    const auto it = health.find(n);
    nlohmann::json row = {{"process", n}, {"state", st}, {"pid", pid}, {"restarts", restarts}};
    if (it != health.end()) {
      const health_t& h = it->second;
      if (!pid) pid = h.pid;
      err = h.last_error;
      std::printf("%-20s %-9s %8lld %8lld %10lld %10lld %10lld %14.3f  %-15s %s\n", n.c_str(),
                  st.c_str(), pid, restarts, static_cast<long long>(h.received),
                  static_cast<long long>(h.rejected), static_cast<long long>(h.published),
                  h.utime * 1e-6, h.activity.empty() ? "-" : h.activity.c_str(), err.c_str());
      row.update({{"pid", pid},
                  {"received", h.received},
                  {"rejected", h.rejected},
                  {"published", h.published},
                  {"sensor_time_s", h.utime * 1e-6},
                  {"activity", h.activity},
                  {"last_error", h.last_error}});
    } else {
      std::printf("%-20s %-9s %8lld %8lld %10s %10s %10s %14s  %-15s %s\n", n.c_str(), st.c_str(),
                  pid, restarts, "-", "-", "-", "-", "-", err.c_str());
      row["reason"] = err;
    }
    rows.push_back(row);
  }
  if (names.empty()) std::printf("(nothing heard: is the pipeline up, on this LCM URL?)\n");
  if (!o.json_path.empty())
    io::AtomicWriteFile(o.json_path, nlohmann::json{{"lcm_url", t.url()},
                                                    {"supervisor_heard", state.has_value()},
                                                    {"processes", rows}}
                                         .dump(2));
  return 0;
}

const RegisterCommand kStatus(
    "status", "Health of the live pipeline (HEALTH and SUPERVISOR_STATE heard on LCM)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--lcm-url", o->lcm_url,
                     "LCM URL (default $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0)");
      sub.add_option("--wait", o->wait_s, "how long to listen [s]")->capture_default_str();
      sub.add_option("--json", o->json_path, "also write the table here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
