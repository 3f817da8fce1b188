// The supervisor end to end, started and stopped as a user does (deploy/rcal-up, deploy/rcal-down)
// on a table of three real processes, inside a private network namespace on a non-default port:
// all start; a SIGKILLed one is restarted (SUPERVISOR_STATE shows the restart, its exit −9 and a
// new pid); rcal-down stops them one at a time in reverse table order and every pid is gone.
#include <cerrno>
#include <fstream>
#include <iterator>
#include <map>

#include "netns.hpp"
#include "rcal/supervisor_state_t.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal {
namespace {

using namespace integration;
constexpr const char* kUrl = "udpm://239.255.76.67:7714?ttl=0";  // not the default port
const std::vector<std::string> kNames = {"orientation_kf", "position_kf", "ik_corrector"};

struct StateListener {
  transport::LcmTransport t{kUrl};
  std::vector<supervisor_state_t> states;
  StateListener() {
    t.Subscribe<supervisor_state_t>(transport::channels::kSupervisorState,
                                    [this](const supervisor_state_t& m) { states.push_back(m); });
  }
  bool WaitFor(const std::function<bool(const supervisor_state_t&)>& done) {
    return Until([&] { return !states.empty() && done(states.back()); },
                 [this] { t.HandleTimeout(100); });
  }
};

int Index(const supervisor_state_t& s, const std::string& name) {
  for (int i = 0; i < s.num_processes; ++i)
    if (s.names[i] == name) return i;
  return -1;
}

bool AllRunning(const supervisor_state_t& s) {
  if (s.num_processes != static_cast<int>(kNames.size())) return false;
  for (int i = 0; i < s.num_processes; ++i)
    if (s.states[i] != "running" || s.pids[i] <= 0) return false;
  return true;
}

class Supervisor : public ProcessFixture {};

TEST_F(Supervisor, RestartsAKilledProcessAndRcalDownStopsAllInReverseOrder) {
  RCAL_IN_NAMESPACE("Supervisor.RestartsAKilledProcessAndRcalDownStopsAllInReverseOrder");
  const fs::path config = dir_ / "processes.yaml";
  std::ofstream(config) << "schema: rcal.processes/1\n"
                        << "lcm_url: " << kUrl << "\n"
                        << "log_dir: " << (dir_ / "log").string() << "\n"
                        << "policy:\n  backoff_initial: 0.2\n  stop_timeout: 5\n"
                        << "processes:\n"
                        << "  - name: orientation_kf\n    command: [orientation_kf, --earth, enu]\n"
                        << "  - name: position_kf\n    command: [position_kf, --earth, enu]\n"
                        << "  - name: ik_corrector\n"
                        << "    command: [ik_corrector, --cell, config/cells/grb3016_poses.yaml]\n";
  const std::string env = "RCAL_BUILD_DIR=" RCAL_BINARY_DIR " RCAL_RUN_DIR=" + dir_.string();
  StateListener l;
  ASSERT_EQ(std::system(
                (env + " " RCAL_SOURCE_DIR "/deploy/rcal-up --config " + config.string()).c_str()),
            0);
  ASSERT_TRUE(l.WaitFor(AllRunning)) << "not all running; see " << dir_;
  const supervisor_state_t up = l.states.back();
  for (const auto& name : kNames) EXPECT_GE(Index(up, name), 0) << name;

  // SIGKILL position_kf (its own process group): restarted with a new pid.
  const int ip = Index(up, "position_kf");
  const int old_pid = up.pids[ip];
  ASSERT_EQ(kill(old_pid, SIGKILL), 0);
  ASSERT_TRUE(l.WaitFor([&](const supervisor_state_t& s) {
    return AllRunning(s) && s.restarts[ip] >= 1 && s.pids[ip] != old_pid;
  }));
  const supervisor_state_t restarted = l.states.back();
  EXPECT_EQ(restarted.restarts[ip], 1);
  EXPECT_EQ(restarted.last_exit[ip], -SIGKILL);
  for (const auto& name : {"orientation_kf", "ik_corrector"}) {
    const int i = Index(restarted, name);
    EXPECT_EQ(restarted.restarts[i], 0) << name;
    EXPECT_EQ(restarted.pids[i], up.pids[i]) << name;
  }

  // rcal-down: returns once the supervisor has exited.
  const size_t before_down = l.states.size();
  ASSERT_EQ(std::system((env + " " RCAL_SOURCE_DIR "/deploy/rcal-down").c_str()), 0);
  for (int i = 0; i < 20; ++i) l.t.HandleTimeout(10);  // the last states already sent
  ASSERT_GT(l.states.size(), before_down);
  const supervisor_state_t& last = l.states.back();
  for (int i = 0; i < last.num_processes; ++i) {
    EXPECT_EQ(last.states[i], "stopped") << last.names[i];
    EXPECT_EQ(last.pids[i], 0) << last.names[i];
  }
  // Order: the first state message in which each process is no longer running.
  std::map<std::string, size_t> first_down;
  for (size_t k = before_down; k < l.states.size(); ++k)
    for (int i = 0; i < l.states[k].num_processes; ++i)
      if (l.states[k].states[i] != "running") first_down.emplace(l.states[k].names[i], k);
  ASSERT_EQ(first_down.size(), 3u);
  // Two processes that stop within one SUPERVISOR_STATE period show up stopped in the same
  // message, so the messages can only say "never out of order"; the supervisor's own log says
  // the order exactly.
  EXPECT_LE(first_down["ik_corrector"], first_down["position_kf"]);
  EXPECT_LE(first_down["position_kf"], first_down["orientation_kf"]);
  std::ifstream log_in(dir_ / "supervisor.log");
  const std::string log_text((std::istreambuf_iterator<char>(log_in)), {});
  const size_t stopping = log_text.find("stopping");
  ASSERT_NE(stopping, std::string::npos) << log_text;
  const size_t s_ik = log_text.find("SIGINT ik_corrector", stopping);
  const size_t s_pos = log_text.find("SIGINT position_kf", stopping);
  const size_t s_ori = log_text.find("SIGINT orientation_kf", stopping);
  ASSERT_NE(s_ori, std::string::npos) << log_text;
  EXPECT_LT(s_ik, s_pos) << log_text;
  EXPECT_LT(s_pos, s_ori) << log_text;
  // Every process the supervisor ran is gone.
  for (int i = 0; i < restarted.num_processes; ++i) {
    errno = 0;
    EXPECT_EQ(kill(restarted.pids[i], 0), -1) << restarted.names[i] << " still alive";
    EXPECT_EQ(errno, ESRCH);
  }
  EXPECT_FALSE(fs::exists(dir_ / "supervisor.pid"));
}

}  // namespace
}  // namespace rcal
