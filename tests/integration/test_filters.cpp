// sensor_acquisition --source replay (a BROAD trial) → orientation_kf → position_kf as real
// processes over UDP multicast in a private namespace (non-default port), against the library
// filters run offline on the same file read independently: sample for sample, at two replay
// speeds (the filters run on sensor time, so speed must not matter). And: malformed and
// wrong-type messages on live channels are rejected, counted in HEALTH, and the processes keep
// running. The tracker-aided INS (aided_ins) on the same replay against the library.
#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <map>
#include <optional>

#include "netns.hpp"
#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/health_t.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/services/aided_ins_defaults.hpp"
#include "rcal/transport/aided_ins_node.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal {
namespace {

using namespace integration;
namespace ch = transport::channels;
using namespace std::chrono_literals;
// Not the default port. Socket buffers for 16× real time: every socket on the group receives
// every channel (~5 000 datagrams/s), and the kernel's default 212 kB held ~40 ms of them (one
// TOOL_POSITION of 3599 lost on a loaded machine).
constexpr const char* kUrl = "udpm://239.255.76.67:7713?ttl=0&recv_buf_size=8388608";
constexpr const char* kTrial = RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv";
constexpr int kRows = 3000;  // 30 s of the trial: rest, then the first rotations

// The offline reference: the trial read with io::CsvTable, utime = round(t_s·1e6), mag µT → T,
// position at 20 Hz from the first finite row, accelerometer before position at equal time.
// `orientation_from` [µs]: the orientation filter starts at that sample (a restarted
// orientation_kf); the position filter is run only from the start.
struct Offline {
  std::map<int64_t, orientation_estimate_t> orientation;
  std::vector<std::pair<int64_t, tool_position_estimate_t>> tool;  // in update order
  // `estimate_lever_arm`: the position filter estimates the IMU → marker lever arm, fed ω_B as
  // position_kf computes it (the gyro less the published orientation's bias).
  std::string trial = kTrial;  // the replayed file and its first `rows` rows
  int rows = kRows;
  // `guessed_frame`: a cell whose earth_from_world is a guess, for which position_kf takes W = E
  // with 1 rad² of doubt per axis until an identifier places the frame.
  explicit Offline(int64_t orientation_from = std::numeric_limits<int64_t>::min(),
                   bool estimate_lever_arm = false, std::string trial_file = kTrial,
                   int num_rows = kRows, bool guessed_frame = false)
      : trial(std::move(trial_file)), rows(num_rows) {
    const bool full = orientation_from == std::numeric_limits<int64_t>::min();
    const auto table = io::CsvTable::Load(trial);
    estimation::OrientationKfSettings os;
    os.earth = estimation::EarthFrame::kEnu;
    estimation::PositionKfSettings ps;
    ps.earth = estimation::EarthFrame::kEnu;
    ps.estimate_lever_arm = estimate_lever_arm;
    estimation::OrientationKf okf(os);
    // position_kf's default: the bank of DefaultBankModels.
    estimation::PositionKfBankSettings bs;
    bs.models = estimation::DefaultBankModels(ps);
    estimation::PositionKfBank pkf(bs);
    if (guessed_frame) {
      EXPECT_TRUE(
          pkf.SetWorldFromEarth(Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity()).ok());
    }
    double next_pos_t = -INFINITY;
    for (int k = 0; k < std::min(rows, table.rows()); ++k) {
      auto c = [&](const char* name) { return table.At(k, name); };
      const double t_s = c("t_s");
      const int64_t utime = std::llround(t_s * 1e6);
      const double t = transport::SensorSeconds(utime);
      const Eigen::Vector3d f(c("acc_x"), c("acc_y"), c("acc_z"));
      if (utime < orientation_from) continue;
      if (!okf.Update(t, {c("gyr_x"), c("gyr_y"), c("gyr_z")}, f,
                      1e-6 * Eigen::Vector3d(c("mag_x"), c("mag_y"), c("mag_z"))))
        continue;
      if (!okf.initialized()) continue;
      orientation[utime] = transport::ToOrientationEstimate(okf, utime);
      if (!full) continue;
      // The position KF sees the orientation as published (a unit quaternion → R).
      std::string error;
      const auto R = transport::RotationFromMessage(orientation[utime], &error);
      const double* b = orientation[utime].gyro_bias;
      const Eigen::Vector3d omega_B =
          Eigen::Vector3d(c("gyr_x"), c("gyr_y"), c("gyr_z")) - Eigen::Vector3d(b[0], b[1], b[2]);
      if (pkf.UpdateAccel(t, f, *R, omega_B) && pkf.initialized())
        tool.emplace_back(utime, transport::ToToolPositionEstimate(pkf, utime));
      const Eigen::Vector3d p(c("pos_x"), c("pos_y"), c("pos_z"));
      if (p.allFinite() && t_s >= next_pos_t - 1e-9) {
        next_pos_t = (std::isfinite(next_pos_t) ? next_pos_t : t_s) + 1.0 / 20;
        if (pkf.UpdatePosition(t, p))
          tool.emplace_back(utime, transport::ToToolPositionEstimate(pkf, utime));
      }
    }
  }
};

const Offline& Reference() {
  static const Offline o;
  return o;
}

struct Listener {
  transport::LcmTransport t{kUrl};
  std::map<int64_t, orientation_estimate_t> orientation;
  std::vector<std::pair<int64_t, tool_position_estimate_t>> tool;
  std::map<std::string, health_t> health;  // latest per process
  int duplicates = 0;
  std::chrono::steady_clock::time_point last_arrival = std::chrono::steady_clock::now();
  explicit Listener(const std::string& orientation_channel = ch::kOrientation,
                    const std::string& tool_position_channel = ch::kToolPosition) {
    t.Subscribe<orientation_estimate_t>(orientation_channel,
                                        [this](const orientation_estimate_t& m) {
                                          last_arrival = std::chrono::steady_clock::now();
                                          if (!orientation.emplace(m.utime, m).second) ++duplicates;
                                        });
    t.Subscribe<tool_position_estimate_t>(tool_position_channel,
                                          [this](const tool_position_estimate_t& m) {
                                            last_arrival = std::chrono::steady_clock::now();
                                            tool.emplace_back(m.utime, m);
                                          });
    t.Subscribe<health_t>(ch::kHealth, [this](const health_t& m) { health[m.process] = m; });
  }
  /// Losses counted on the way: datagrams the kernel dropped (at the listener and at the
  /// processes) and samples the processes refused (their latest HEALTH: after a clean stop, the
  /// final one).
  int64_t Counted() const {
    int64_t n = t.Dropped();
    for (const auto& [process, h] : health) n += h.dropped + h.rejected;
    return n;
  }
  std::string Counts() const {
    std::string s = "listener dropped " + std::to_string(t.Dropped());
    for (const auto& [process, h] : health)
      s += "; " + process + ": received " + std::to_string(h.received) + ", rejected " +
           std::to_string(h.rejected) + ", gaps " + std::to_string(h.gaps) + ", dropped " +
           std::to_string(h.dropped) + ", published " + std::to_string(h.published);
    return s;
  }
  bool WaitFor(const std::function<bool()>& done) {
    return Until(done, [this] { t.HandleTimeout(100); });
  }
};

std::vector<std::string> OrientationKfCmd() {
  return {RCAL_ORIENTATION_KF, "--earth", "enu", "--lcm-url", kUrl};
}
// position_kf's defaults: a position waits for the orientation stream unless it has been silent
// for a second of host time (a stalled replay's burst no longer outruns it, whatever the speed).
std::vector<std::string> PositionKfCmd() {
  return {RCAL_POSITION_KF, "--earth", "enu", "--lcm-url", kUrl};
}

class Filters : public ProcessFixture {
 protected:
  void ExpectReplayEqualsOffline(const Offline& ref, const std::vector<std::string>& pkf_cmd,
                                 const char* speed, const std::string& what,
                                 std::vector<std::pair<int64_t, tool_position_estimate_t>>* tool);
};

void ExpectSame(const double* a, const double* b, int n, const char* what, int64_t utime) {
  for (int i = 0; i < n; ++i)
    ASSERT_NEAR(a[i], b[i], 1e-12 * std::max(1.0, std::abs(b[i])))
        << what << "[" << i << "] at utime " << utime;
}

// Replays the trial at `speed` through orientation_kf and position_kf (`pkf_cmd`) as real
// processes and expects every estimate equal to `ref`'s (1e-12); `tool` receives the live
// TOOL_POSITION estimates. `what` tags the processes' logs.
void Filters::ExpectReplayEqualsOffline(
    const Offline& ref, const std::vector<std::string>& pkf_cmd, const char* speed,
    const std::string& what, std::vector<std::pair<int64_t, tool_position_estimate_t>>* tool) {
  // Equality needs every datagram. One the kernel dropped (a socket buffer full while its
  // reader was not scheduled: a loaded machine) is counted in HEALTH and at the listener, a
  // sample refused as late (orientation_kf silent for over a second) in HEALTH; such a run
  // proves nothing about the filters and is repeated. A shortfall nothing counted fails: the
  // processes are stopped first, so their final HEALTH has every count up to the end.
  constexpr int kAttempts = 3;
  for (int attempt = 1; attempt <= kAttempts; ++attempt) {
    const std::string tag = what + "_" + speed + "_" + std::to_string(attempt) + ".log";
    Listener l;
    const pid_t okf = Start(OrientationKfCmd(), "orientation_kf_" + tag);
    const pid_t pkf = Start(pkf_cmd, "position_kf_" + tag);
    // Both announce themselves (HEALTH at utime 0) once subscribed.
    ASSERT_TRUE(l.WaitFor(
        [&] { return l.health.count("orientation_kf") && l.health.count("position_kf"); }));
    const pid_t src = Start({RCAL_SENSOR_ACQUISITION, "--source", "replay", ref.trial, "--max-rows",
                             std::to_string(ref.rows), "--speed", speed, "--lcm-url", kUrl},
                            "sensor_acquisition_" + tag);
    const auto complete = [&] {
      return l.orientation.size() >= ref.orientation.size() && l.tool.size() >= ref.tool.size();
    };
    bool src_done = false;
    ASSERT_TRUE(l.WaitFor([&] {
      if (complete()) return true;
      if (!src_done && !Running(src)) {
        src_done = true;
        Reaped(src);
      }
      // The source has finished and nothing came for 3 s: whatever is missing is lost.
      return src_done && std::chrono::steady_clock::now() - l.last_arrival > 3s;
    }));
    if (!complete()) {
      EXPECT_EQ(Stop(okf), 0);
      EXPECT_EQ(Stop(pkf), 0);
      for (int i = 0; i < 10; ++i) l.t.HandleTimeout(20);  // their final HEALTH
      const std::string what = "orientations " + std::to_string(l.orientation.size()) + " of " +
                               std::to_string(ref.orientation.size()) + ", tool positions " +
                               std::to_string(l.tool.size()) + " of " +
                               std::to_string(ref.tool.size()) + "; " + l.Counts();
      ASSERT_GT(l.Counted(), 0) << "lost, and counted nowhere: " << what;
      std::printf("attempt %d at speed %s: losses counted, run repeated: %s\n", attempt, speed,
                  what.c_str());
      ASSERT_LT(attempt, kAttempts) << "every attempt lost datagrams: " << what;
      continue;
    }
    if (!src_done) {
      EXPECT_EQ(Wait(src), 0);
      Reaped(src);
    }
    // Nothing more than the reference.
    for (int i = 0; i < 5; ++i) l.t.HandleTimeout(20);
    EXPECT_EQ(l.duplicates, 0);
    ASSERT_EQ(l.orientation.size(), ref.orientation.size());
    for (const auto& [utime, r] : ref.orientation) {
      const auto it = l.orientation.find(utime);
      ASSERT_NE(it, l.orientation.end()) << "no ORIENTATION at utime " << utime;
      ExpectSame(it->second.q_EI, r.q_EI, 4, "q_EI", utime);
      ExpectSame(it->second.covariance, r.covariance, 9, "covariance", utime);
      ExpectSame(it->second.gyro_bias, r.gyro_bias, 3, "gyro_bias", utime);
    }
    ASSERT_EQ(l.tool.size(), ref.tool.size());
    for (size_t k = 0; k < ref.tool.size(); ++k) {
      ASSERT_EQ(l.tool[k].first, ref.tool[k].first) << "update " << k;
      ExpectSame(l.tool[k].second.p, ref.tool[k].second.p, 3, "p", ref.tool[k].first);
      ExpectSame(l.tool[k].second.v, ref.tool[k].second.v, 3, "v", ref.tool[k].first);
      ExpectSame(l.tool[k].second.covariance, ref.tool[k].second.covariance, 36, "covariance",
                 ref.tool[k].first);
    }
    EXPECT_EQ(Stop(okf), 0);
    EXPECT_EQ(Stop(pkf), 0);
    if (tool != nullptr) *tool = l.tool;
    break;
  }
}

TEST_F(Filters, ReplayMatchesOfflineFiltersAtTwoSpeeds) {
  RCAL_IN_NAMESPACE("Filters.ReplayMatchesOfflineFiltersAtTwoSpeeds");
  const Offline& ref = Reference();
  ASSERT_GT(ref.orientation.size(), 2000u);
  ASSERT_GT(ref.tool.size(), 2000u);
  for (const char* speed : {"4", "16"}) {
    SCOPED_TRACE(std::string("speed ") + speed);
    ASSERT_NO_FATAL_FAILURE(
        ExpectReplayEqualsOffline(ref, PositionKfCmd(), speed, "plain", nullptr));
  }
}

// The lever arm live (issue 17, item 2): position_kf --estimate-lever-arm on BROAD's fast-rotation
// trial (07, whole) is, estimate for estimate, the library filter estimating it with ω_B = the gyro
// less the published bias; between the 20 Hz position samples it follows the optical truth (every
// 100 Hz row) closer than the filter that takes the IMU at the marker, run on the same samples.
TEST_F(Filters, TheLeverArmIsEstimatedLiveAsTheLibraryDoes) {
  RCAL_IN_NAMESPACE("Filters.TheLeverArmIsEstimatedLiveAsTheLibraryDoes");
  constexpr const char* kFast = RCAL_SHARED_DIR "/data/broad/broad_07_100hz.csv";
  constexpr int kAll = 1'000'000;
  const Offline with_lever_arm(std::numeric_limits<int64_t>::min(), true, kFast, kAll);
  const Offline at_the_marker(std::numeric_limits<int64_t>::min(), false, kFast, kAll);
  std::vector<std::pair<int64_t, tool_position_estimate_t>> tool;
  std::vector<std::string> cmd = PositionKfCmd();
  cmd.push_back("--estimate-lever-arm");
  ASSERT_NO_FATAL_FAILURE(ExpectReplayEqualsOffline(with_lever_arm, cmd, "16", "lever_arm", &tool));
  // Against the optical truth at every row (the estimate after the row's last update).
  const auto table = io::CsvTable::Load(kFast);
  std::map<int64_t, Eigen::Vector3d> truth;
  for (int k = 0; k < table.rows(); ++k) {
    const Eigen::Vector3d p(table.At(k, "pos_x"), table.At(k, "pos_y"), table.At(k, "pos_z"));
    if (p.allFinite()) truth[std::llround(table.At(k, "t_s") * 1e6)] = p;
  }
  const auto rmse_mm = [&](const std::vector<std::pair<int64_t, tool_position_estimate_t>>& est) {
    std::map<int64_t, Eigen::Vector3d> last;
    for (const auto& [utime, m] : est) last[utime] = Eigen::Vector3d(m.p[0], m.p[1], m.p[2]);
    double ss = 0;
    int n = 0;
    for (const auto& [utime, p] : last) {
      const auto it = truth.find(utime);
      if (it == truth.end()) continue;
      ss += (p - it->second).squaredNorm();
      ++n;
    }
    return n > 0 ? 1e3 * std::sqrt(ss / n) : INFINITY;
  };
  const double with_mm = rmse_mm(tool), without_mm = rmse_mm(at_the_marker.tool);
  std::printf(
      "BROAD trial 07 (fast rotation), %zu rows: position RMSE against the optical truth %.3f mm "
      "live with the lever arm estimated, %.3f mm with the IMU taken at the marker\n",
      truth.size(), with_mm, without_mm);
  EXPECT_LT(with_mm, without_mm);
}

// SIGKILL orientation_kf mid-replay and start a new one (as the supervisor would): position_kf
// keeps running and publishing without rejecting anything; the restarted orientation_kf is,
// sample for sample (1e-12), the library filter started at the first sample it received
// (whenever the kill and restart landed); position_kf's final estimate agrees with the
// uninterrupted offline filter within their σ (it lost the accelerometer samples of the gap).
TEST_F(Filters, PositionKfSurvivesASigkilledOrientationKf) {
  RCAL_IN_NAMESPACE("Filters.PositionKfSurvivesASigkilledOrientationKf");
  const Offline& ref = Reference();
  Listener l;
  pid_t okf = Start(OrientationKfCmd(), "orientation_kf_1.log");
  const pid_t pkf = Start(PositionKfCmd(), "position_kf.log");
  ASSERT_TRUE(
      l.WaitFor([&] { return l.health.count("orientation_kf") && l.health.count("position_kf"); }));
  const pid_t src = Start({RCAL_SENSOR_ACQUISITION, "--source", "replay", kTrial, "--max-rows",
                           std::to_string(kRows), "--speed", "4", "--lcm-url", kUrl},
                          "sensor_acquisition.log");
  const int64_t kill_at = 10'000'000, last = ref.orientation.rbegin()->first;
  ASSERT_TRUE(l.WaitFor(
      [&] { return !l.orientation.empty() && l.orientation.rbegin()->first >= kill_at; }));
  kill(-okf, SIGKILL);
  EXPECT_EQ(Wait(okf), -SIGKILL);
  Reaped(okf);
  // What the killed process had published before it died is still in flight: take it in, so
  // that every estimate after `killed_after` is the restarted process's.
  for (int i = 0; i < 10; ++i) l.t.HandleTimeout(20);
  const int64_t killed_after = l.orientation.rbegin()->first;
  l.health.erase("orientation_kf");
  okf = Start(OrientationKfCmd(), "orientation_kf_2.log");
  ASSERT_TRUE(l.WaitFor([&] { return l.orientation.count(last) > 0; }));
  ASSERT_TRUE(l.WaitFor([&] { return !l.tool.empty() && l.tool.back().first >= last; }));
  EXPECT_EQ(Wait(src), 0);
  Reaped(src);
  for (int i = 0; i < 5; ++i) l.t.HandleTimeout(20);
  // The gap: the samples published while no orientation_kf ran have no estimate.
  EXPECT_LT(l.orientation.size(), ref.orientation.size());
  EXPECT_GT(l.orientation.size(), ref.orientation.size() / 2);
  // position_kf went on: estimates all along, nothing rejected, still running.
  size_t after_kill = 0;
  for (const auto& [utime, m] : l.tool) after_kill += utime > killed_after;
  EXPECT_GT(after_kill, 1000u);
  ASSERT_TRUE(l.WaitFor([&] { return l.health.count("position_kf") > 0; }));
  EXPECT_EQ(l.health["position_kf"].rejected, 0) << l.health["position_kf"].last_error;
  EXPECT_TRUE(Running(pkf));
  // Final estimates against the uninterrupted offline ones, within 3σ of both.
  const auto& p_live = l.tool.back().second;
  const auto& p_ref = ref.tool.back().second;
  for (int a = 0; a < 3; ++a) {
    const double var = p_live.covariance[6 * a + a] + p_ref.covariance[6 * a + a];
    EXPECT_LT(std::abs(p_live.p[a] - p_ref.p[a]), 3 * std::sqrt(var)) << "axis " << a;
  }
  // The restarted orientation_kf: exactly the library filter from its first sample on.
  const auto first = l.orientation.upper_bound(killed_after);
  ASSERT_NE(first, l.orientation.end());
  const Offline restarted(first->first);
  size_t compared = 0;
  for (auto it = first; it != l.orientation.end(); ++it) {
    const auto r = restarted.orientation.find(it->first);
    ASSERT_NE(r, restarted.orientation.end()) << "no offline estimate at " << it->first;
    ExpectSame(it->second.q_EI, r->second.q_EI, 4, "restarted q_EI", it->first);
    ExpectSame(it->second.covariance, r->second.covariance, 9, "restarted covariance", it->first);
    ++compared;
  }
  EXPECT_EQ(compared, restarted.orientation.size()) << "the restarted process lost estimates";
  std::printf("restarted orientation_kf from %lld us: %zu estimates equal to the library's\n",
              static_cast<long long>(first->first), compared);
  EXPECT_EQ(Stop(okf), 0);
  EXPECT_EQ(Stop(pkf), 0);
}

// --cell FILE: both filters take the IMU's earth frame, the position sensor's σ (its largest per
// axis), the lever arm (estimated) and the channels from the cell file, and the replay source its
// channels. A cell saying ENU,
// σ (0.5, 1, 0.2) mm and its own ORIENTATION/TOOL_POSITION channel names gives exactly the
// reference (ENU, 1 mm) on those channels; the defaults (NED, other channels) would give nothing
// there. A cell without an IMU is refused by both, naming the key.
TEST_F(Filters, TheCellFileGivesEarthFrameSigmaAndChannels) {
  RCAL_IN_NAMESPACE("Filters.TheCellFileGivesEarthFrameSigmaAndChannels");
  std::string text = io::ReadFile(RCAL_SOURCE_DIR "/config/cells/grb3016.yaml");
  auto replace = [&](const std::string& from, const std::string& to) {
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
  };
  replace("    earth: ned", "    earth: enu\n    to_marker: estimate");
  replace("../robots/grb3016.yaml", RCAL_SOURCE_DIR "/config/robots/grb3016.yaml");
  const auto sigma = text.find("    sigma: [");
  ASSERT_NE(sigma, std::string::npos);
  text.replace(sigma, text.find('\n', sigma) - sigma, "    sigma: [5e-4, 1e-3, 2e-4]");
  text +=
      "channels: {imu: IMU_C, position: POSITION_C, orientation: ORIENTATION_C, tool_position: "
      "TOOL_POSITION_C}\n";
  const std::string cell = (dir_ / "cell.yaml").string();
  io::AtomicWriteFile(cell, text);

  // position_kf estimates the lever arm the cell says to (sensors.imu.to_marker: estimate), and
  // doubts the earth frame the cell only guesses.
  const Offline ref(std::numeric_limits<int64_t>::min(), true, kTrial, kRows, true);
  Listener l("ORIENTATION_C", "TOOL_POSITION_C");
  const pid_t okf = Start({RCAL_ORIENTATION_KF, "--cell", cell, "--lcm-url", kUrl}, "okf.log");
  const pid_t pkf = Start({RCAL_POSITION_KF, "--cell", cell, "--lcm-url", kUrl}, "pkf.log");
  ASSERT_TRUE(
      l.WaitFor([&] { return l.health.count("orientation_kf") && l.health.count("position_kf"); }));
  constexpr int kCellRows = 1000;
  // The replay publishes on the cell's IMU and POSITION channels too.
  const pid_t src =
      Start({RCAL_SENSOR_ACQUISITION, "--source", "replay", kTrial, "--max-rows",
             std::to_string(kCellRows), "--speed", "4", "--cell", cell, "--lcm-url", kUrl},
            "sensor_acquisition.log");
  // Read while the replay runs (each HandleTimeout takes one message), until it has finished and
  // nothing came for a second.
  bool src_done = false;
  ASSERT_TRUE(l.WaitFor([&] {
    if (!src_done && !Running(src)) {
      src_done = true;
      Reaped(src);
    }
    return src_done && std::chrono::steady_clock::now() - l.last_arrival > 1s;
  }));
  ASSERT_GT(l.orientation.size(), 500u) << l.Counts();
  for (const auto& [utime, m] : l.orientation) {
    const auto r = ref.orientation.find(utime);
    ASSERT_NE(r, ref.orientation.end()) << utime;
    ExpectSame(m.q_EI, r->second.q_EI, 4, "q_EI", utime);
  }
  ASSERT_GT(l.tool.size(), 500u) << l.Counts();
  if (l.Counted() == 0) {
    ASSERT_LE(l.tool.size(), ref.tool.size());
    for (size_t k = 0; k < l.tool.size(); ++k) {
      ASSERT_EQ(l.tool[k].first, ref.tool[k].first) << "update " << k;
      ExpectSame(l.tool[k].second.p, ref.tool[k].second.p, 3, "p", ref.tool[k].first);
      ExpectSame(l.tool[k].second.covariance, ref.tool[k].second.covariance, 36, "covariance",
                 ref.tool[k].first);
    }
  } else {
    std::printf("losses counted (%s): tool sequence not compared\n", l.Counts().c_str());
  }
  EXPECT_EQ(Stop(okf), 0);
  EXPECT_EQ(Stop(pkf), 0);

  for (const char* exe : {RCAL_ORIENTATION_KF, RCAL_POSITION_KF}) {
    const std::string log = std::string("no_imu_") + std::filesystem::path(exe).filename().string();
    const pid_t p = Start(
        {exe, "--cell", RCAL_SOURCE_DIR "/config/cells/grb3016_poses.yaml", "--lcm-url", kUrl},
        log);
    EXPECT_EQ(Wait(p), 1) << exe;
    Reaped(p);
    EXPECT_NE(io::ReadFile((dir_ / log).string()).find("sensors.imu: absent"), std::string::npos)
        << exe;
  }
}

// The tracker-aided INS live: sensor_acquisition --source replay → aided_ins as real processes
// over UDP multicast, against the library run offline on the file read independently
// (estimation::StepAfterOrientationKf after each row, the 20 Hz position after it), at two replay
// speeds: every INS_ORIENTATION up to the tracker's last sample, equal to 1e-12. Later IMU samples
// wait for a tracker sample that never comes (the stream ended): none is published.
TEST_F(Filters, TheAidedInsReplayMatchesTheLibrary) {
  RCAL_IN_NAMESPACE("Filters.TheAidedInsReplayMatchesTheLibrary");
  std::map<int64_t, orientation_estimate_t> ref;
  int64_t last_position = 0;
  {
    const auto table = io::CsvTable::Load(kTrial);
    estimation::OrientationKfSettings os;
    os.earth = estimation::EarthFrame::kEnu;
    // aided_ins's defaults (fuse-loo --ins's choice), the process's earth frame.
    estimation::AidedInsSettings is = services::AidedInsProcessDefaults();
    is.earth = estimation::EarthFrame::kEnu;
    estimation::OrientationKf okf(os);
    estimation::AidedIns ins(is);
    double next_pos_t = -INFINITY;
    for (int k = 0; k < std::min(kRows, table.rows()); ++k) {
      auto c = [&](const char* name) { return table.At(k, name); };
      const double t_s = c("t_s");
      const int64_t utime = std::llround(t_s * 1e6);
      const double t = transport::SensorSeconds(utime);
      const Eigen::Vector3d gyro(c("gyr_x"), c("gyr_y"), c("gyr_z")),
          f(c("acc_x"), c("acc_y"), c("acc_z"));
      if (!okf.Update(t, gyro, f, 1e-6 * Eigen::Vector3d(c("mag_x"), c("mag_y"), c("mag_z"))))
        continue;
      ASSERT_TRUE(estimation::StepAfterOrientationKf(ins, okf, t, gyro, f, false));
      if (ins.initialized()) ref[utime] = transport::ToOrientationEstimate(ins, utime);
      const Eigen::Vector3d p(c("pos_x"), c("pos_y"), c("pos_z"));
      if (p.allFinite() && t_s >= next_pos_t - 1e-9) {
        next_pos_t = (std::isfinite(next_pos_t) ? next_pos_t : t_s) + 1.0 / 20;
        ASSERT_TRUE(ins.UpdatePosition(t, p));
        last_position = utime;
      }
    }
    ASSERT_GT(ins.counters().positions, 500);
  }
  size_t expected = 0;
  for (const auto& [utime, m] : ref) expected += utime <= last_position ? 1 : 0;
  ASSERT_GT(expected, 2000u);
  for (const char* speed : {"4", "16"}) {
    SCOPED_TRACE(std::string("speed ") + speed);
    constexpr int kAttempts = 3;
    for (int attempt = 1; attempt <= kAttempts; ++attempt) {
      const std::string tag = std::string(speed) + "_" + std::to_string(attempt) + ".log";
      Listener l(ch::kInsOrientation, ch::kInsToolPosition);
      const pid_t ins =
          Start({RCAL_AIDED_INS, "--earth", "enu", "--lcm-url", kUrl}, "aided_ins_" + tag);
      ASSERT_TRUE(l.WaitFor([&] { return l.health.count("aided_ins") > 0; }));
      const pid_t src = Start({RCAL_SENSOR_ACQUISITION, "--source", "replay", kTrial, "--max-rows",
                               std::to_string(kRows), "--speed", speed, "--lcm-url", kUrl},
                              "sensor_acquisition_ins_" + tag);
      bool src_done = false;
      ASSERT_TRUE(l.WaitFor([&] {
        if (l.orientation.size() >= expected) return true;
        if (!src_done && !Running(src)) {
          src_done = true;
          Reaped(src);
        }
        return src_done && std::chrono::steady_clock::now() - l.last_arrival > 3s;
      }));
      if (!src_done) {
        EXPECT_EQ(Wait(src), 0);
        Reaped(src);
      }
      for (int i = 0; i < 10; ++i) l.t.HandleTimeout(20);
      EXPECT_EQ(Stop(ins), 0);
      for (int i = 0; i < 10; ++i) l.t.HandleTimeout(20);  // its final HEALTH
      if (l.orientation.size() < expected) {
        const std::string what = "INS orientations " + std::to_string(l.orientation.size()) +
                                 " of " + std::to_string(expected) + "; " + l.Counts();
        ASSERT_GT(l.Counted(), 0) << "lost, and counted nowhere: " << what;
        std::printf("attempt %d: losses counted, run repeated: %s\n", attempt, what.c_str());
        ASSERT_LT(attempt, kAttempts) << "every attempt lost datagrams: " << what;
        continue;
      }
      EXPECT_EQ(l.duplicates, 0);
      EXPECT_EQ(l.orientation.size(), expected);
      for (const auto& [utime, m] : l.orientation) {
        const auto r = ref.find(utime);
        ASSERT_NE(r, ref.end()) << "an INS_ORIENTATION the library has not: " << utime;
        ASSERT_LE(utime, last_position);
        ExpectSame(m.q_EI, r->second.q_EI, 4, "q_EI", utime);
        ExpectSame(m.covariance, r->second.covariance, 9, "covariance", utime);
        ExpectSame(m.gyro_bias, r->second.gyro_bias, 3, "gyro_bias", utime);
      }
      // Its marker: one per update, at least one per IMU step it integrated.
      EXPECT_GT(l.tool.size(), expected);
      EXPECT_EQ(l.health["aided_ins"].rejected, 0) << l.health["aided_ins"].last_error;
      break;
    }
  }
}

imu_sample_t Imu(int64_t utime) {
  transport::ImuSample s;  // flat and still, ENU: f up, field north and down
  s.utime = utime;
  s.f_B = {0, 0, 9.81};
  s.has_mag = true;
  s.m_B = {0, 20e-6, -40e-6};
  return transport::ToMessage(s);
}

TEST_F(Filters, MalformedAndWrongTypeMessagesAreRejectedAndCounted) {
  RCAL_IN_NAMESPACE("Filters.MalformedAndWrongTypeMessagesAreRejectedAndCounted");
  Listener l;
  const pid_t okf = Start(OrientationKfCmd(), "orientation_kf.log");
  const pid_t pkf = Start(PositionKfCmd(), "position_kf.log");
  ASSERT_TRUE(
      l.WaitFor([&] { return l.health.count("orientation_kf") && l.health.count("position_kf"); }));
  // Good samples first: one heartbeat each at 1 s, no rejection yet.
  for (int64_t u = 1'000'000; u <= 1'050'000; u += 10'000) l.t.Publish(ch::kImu, Imu(u));
  ASSERT_TRUE(l.WaitFor([&] { return l.orientation.count(1'050'000) > 0; }));
  // Bad ones on IMU: garbage bytes, a HEALTH message (wrong type: its fingerprint differs),
  // a NaN gyro, a duplicate utime, a sample without magnetometer.
  const char garbage[] = "not an LCM message at all";
  l.t.PublishRaw(ch::kImu, garbage, sizeof garbage);
  health_t wrong;  // a well-formed message of another type
  wrong.utime = 1'060'000;
  wrong.process = "impostor";
  wrong.pid = 1;
  wrong.received = wrong.rejected = wrong.published = 0;
  l.t.Publish(ch::kImu, wrong);
  auto nan = Imu(1'060'000);
  nan.gyro[1] = NAN;
  l.t.Publish(ch::kImu, nan);
  l.t.Publish(ch::kImu, Imu(1'050'000));
  auto no_mag = Imu(1'070'000);
  no_mag.has_mag = false;
  l.t.Publish(ch::kImu, no_mag);
  // And on POSITION: garbage and a wrong type.
  l.t.PublishRaw(ch::kPosition, garbage, sizeof garbage);
  l.t.Publish(ch::kPosition, wrong);
  // Good samples again, past the next heartbeat (1 s of sensor time later).
  for (int64_t u = 2'000'000; u <= 2'100'000; u += 10'000) l.t.Publish(ch::kImu, Imu(u));
  ASSERT_TRUE(l.WaitFor([&] {
    return l.orientation.count(2'100'000) > 0 && l.health["orientation_kf"].utime >= 2'000'000 &&
           l.health["position_kf"].utime >= 2'000'000;
  }));
  const health_t& ho = l.health["orientation_kf"];
  EXPECT_EQ(ho.rejected, 5) << ho.last_error;
  EXPECT_EQ(ho.received, 6 + 5 + 1);  // the heartbeat at 2 s counts up to its own sample
  EXPECT_GT(ho.published, 6);
  // position_kf: 2 bad POSITION + garbage and wrong type on IMU + NaN + duplicate on IMU.
  // (The sample without magnetometer is fine for the accelerometer.)
  const health_t& hp = l.health["position_kf"];
  EXPECT_EQ(hp.rejected, 6) << hp.last_error;
  EXPECT_TRUE(Running(okf));
  EXPECT_TRUE(Running(pkf));
  EXPECT_EQ(Stop(okf), 0);
  EXPECT_EQ(Stop(pkf), 0);
}

}  // namespace
}  // namespace rcal
