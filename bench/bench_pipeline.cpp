// The live pipeline's cost: end-to-end latency from a published IMU sample to its ORIENTATION
// estimate through rcal::transport::OrientationKfNode (encode, transport, decode, checks,
// OrientationKf::Update, encode, transport, decode), over memq:// and over UDP multicast
// (udpm, ttl=0, two LCM instances in this process, as two processes would use); and the highest
// sample rate OrientationKf and PositionKf sustain on one core (items_per_second). Input: a real
// IMU stream (BROAD trial 02, 100 Hz), looped with utime kept increasing.
//
// The udpm benchmark needs a multicast route: run it inside deploy/netns-run, e.g.
//   deploy/netns-run build/bench/bench_pipeline
// (it is skipped with an error message when LCM cannot open the URL).
#include <benchmark/benchmark.h>

#include <memory>
#include <optional>
#include <vector>

#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/estimation/position_kf.hpp"
#include "rcal/estimation/position_kf_bank.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/transport/aided_ins_node.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace ch = transport::channels;

struct Stream {
  std::vector<transport::ImuSample> imu;
  std::vector<Eigen::Vector3d> pos;  // NaN where hidden
  int64_t period_us = 10'000;
  Stream() {
    const auto table = io::CsvTable::Load(RCAL_SHARED_DIR "/data/broad/broad_02_100hz.csv");
    for (int k = 0; k < table.rows(); ++k) {
      auto c = [&](const char* n) { return table.At(k, n); };
      transport::ImuSample s;
      s.utime = std::llround(c("t_s") * 1e6);
      s.gyro_B = {c("gyr_x"), c("gyr_y"), c("gyr_z")};
      s.f_B = {c("acc_x"), c("acc_y"), c("acc_z")};
      s.has_mag = true;
      s.m_B = 1e-6 * Eigen::Vector3d(c("mag_x"), c("mag_y"), c("mag_z"));
      imu.push_back(s);
      pos.emplace_back(c("pos_x"), c("pos_y"), c("pos_z"));
    }
  }
  // Sample i of the endless loop (utime increasing across laps).
  transport::ImuSample At(int64_t i) const {
    const int64_t n = static_cast<int64_t>(imu.size());
    transport::ImuSample s = imu[i % n];
    s.utime += (i / n) * (imu.back().utime + period_us);
    return s;
  }
};

const Stream& Data() {
  static const Stream s;
  return s;
}

estimation::OrientationKfSettings Enu() {
  estimation::OrientationKfSettings s;
  s.earth = estimation::EarthFrame::kEnu;
  return s;
}

// memq://: one LCM instance, the node and the client on it; each iteration publishes one IMU
// sample and dispatches until its ORIENTATION has reached the client.
void BM_ImuToOrientationLatency_memq(benchmark::State& state) {
  const Stream& d = Data();
  transport::LcmTransport t("memq://");
  transport::OrientationKfNode node(t, Enu());
  int64_t received_utime = -1;
  t.Subscribe<orientation_estimate_t>(
      ch::kOrientation, [&](const orientation_estimate_t& m) { received_utime = m.utime; });
  int64_t i = 0;
  for (int k = 0; k < 5; ++k, ++i) {  // initialise the filter
    t.Publish(ch::kImu, transport::ToMessage(d.At(i)));
    while (t.HandleTimeout(0) > 0) {
    }
  }
  for (auto _ : state) {
    const auto s = d.At(i++);
    t.Publish(ch::kImu, transport::ToMessage(s));
    while (received_utime != s.utime) t.HandleTimeout(0);
    while (t.HandleTimeout(0) > 0) {  // the heartbeat, when one was due
    }
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["rejected"] = static_cast<double>(node.health().rejected());
}
BENCHMARK(BM_ImuToOrientationLatency_memq)->Unit(benchmark::kMicrosecond);

// udpm: the client and the node on two LCM instances (two sockets, as two processes); each
// iteration: the client publishes an IMU sample, the node's instance receives and handles it and
// publishes the estimate, the client receives it. Real UDP multicast on loopback, ttl=0.
void BM_ImuToOrientationLatency_udpm(benchmark::State& state) {
  const Stream& d = Data();
  const std::string url = "udpm://239.255.76.67:7721?ttl=0";
  std::unique_ptr<transport::LcmTransport> client, server;
  try {
    client = std::make_unique<transport::LcmTransport>(url);
    server = std::make_unique<transport::LcmTransport>(url);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  transport::OrientationKfNode node(*server, Enu());
  int64_t received_utime = -1;
  client->Subscribe<orientation_estimate_t>(
      ch::kOrientation, [&](const orientation_estimate_t& m) { received_utime = m.utime; });
  int64_t i = 0;
  int64_t lost = 0;
  auto one = [&](const transport::ImuSample& s) {
    client->Publish(ch::kImu, transport::ToMessage(s));
    // The node handles the IMU sample (its own ORIENTATION/HEALTH are not subscribed there).
    for (int tries = 0; tries < 100 && node.health().received() <= i; ++tries)
      server->HandleTimeout(10);
    for (int tries = 0; tries < 100 && received_utime != s.utime; ++tries)
      client->HandleTimeout(10);
    if (received_utime != s.utime) ++lost;
  };
  for (int k = 0; k < 5; ++k, ++i) one(d.At(i));
  for (auto _ : state) {
    one(d.At(i));
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["lost"] = static_cast<double>(lost);
}
BENCHMARK(BM_ImuToOrientationLatency_udpm)->Unit(benchmark::kMicrosecond)->UseRealTime();

// OrientationKf alone: samples per second on one core.
void BM_OrientationKfRate(benchmark::State& state) {
  const Stream& d = Data();
  estimation::OrientationKf kf(Enu());
  int64_t i = 0;
  for (auto _ : state) {
    const auto s = d.At(i++);
    benchmark::DoNotOptimize(
        kf.Update(transport::SensorSeconds(s.utime), s.gyro_B, s.f_B, s.m_B).ok());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_OrientationKfRate);

// One accelerometer update per IMU sample plus the position sensor at 20 Hz (every 5th sample),
// with a fixed orientation, and the estimate read; items = IMU samples. F: a PositionKf or a
// PositionKfBank (the same calls).
template <typename F>
void RunPositionFilter(benchmark::State& state, F& filter) {
  const Stream& d = Data();
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  const int64_t n = static_cast<int64_t>(d.imu.size());
  int64_t i = 0;
  for (auto _ : state) {
    const auto s = d.At(i);
    const double t = transport::SensorSeconds(s.utime);
    benchmark::DoNotOptimize(filter.UpdateAccel(t, s.f_B, R).ok());
    if (i % 5 == 0 && d.pos[i % n].allFinite())
      benchmark::DoNotOptimize(filter.UpdatePosition(t, d.pos[i % n]).ok());
    benchmark::DoNotOptimize(filter.p_WM_W());
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}

// PositionKf alone (the paper's filter).
void BM_PositionKfRate(benchmark::State& state) {
  estimation::PositionKfSettings ps;
  ps.earth = estimation::EarthFrame::kEnu;
  estimation::PositionKf kf(ps);
  RunPositionFilter(state, kf);
}
BENCHMARK(BM_PositionKfRate);

// The bank rcal fuse runs (position_kf_bank.hpp: the paper's motion model and the
// accelerometer-driven one, both with the adaptive noise, weighed at each position sample).
void BM_PositionKfBankRate(benchmark::State& state) {
  estimation::PositionKfSettings base;
  base.earth = estimation::EarthFrame::kEnu;
  estimation::PositionKfBankSettings bs;
  bs.models = estimation::DefaultBankModels(base);
  estimation::PositionKfBank bank(bs);
  RunPositionFilter(state, bank);
}
BENCHMARK(BM_PositionKfBankRate);

// The tracker-aided INS (aided_ins.hpp, 21 error states, the frame known): the IMU and a
// magnetometer heading every sample, the position sensor at 20 Hz (every 5th); items = IMU samples.
void BM_AidedInsRate(benchmark::State& state) {
  const Stream& d = Data();
  estimation::AidedInsSettings is;
  is.earth = estimation::EarthFrame::kEnu;
  estimation::AidedIns ins(is);
  const int64_t n = static_cast<int64_t>(d.imu.size());
  int64_t i = 0;
  for (auto _ : state) {
    const auto s = d.At(i);
    const double t = transport::SensorSeconds(s.utime);
    benchmark::DoNotOptimize(ins.UpdateImu(t, s.gyro_B, s.f_B).ok());
    if (!ins.initialized())
      benchmark::DoNotOptimize(ins.UpdateHeading(t, Eigen::Vector4d(1, 0, 0, 0)).ok());
    else
      benchmark::DoNotOptimize(ins.UpdateMagnetometer(t, s.m_B).ok());
    if (i % 5 == 0 && d.pos[i % n].allFinite())
      benchmark::DoNotOptimize(ins.UpdatePosition(t, d.pos[i % n]).ok());
    benchmark::DoNotOptimize(ins.q_EB());
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_AidedInsRate);

// The whole orientation node without a transport: decode-free OnImu (checks, filter, encode and
// memq publish of the estimate): the highest IMU rate the orientation_kf process sustains.
void BM_OrientationNodeRate(benchmark::State& state) {
  const Stream& d = Data();
  transport::LcmTransport t("memq://");
  transport::OrientationKfNode node(t, Enu());
  int64_t i = 0;
  for (auto _ : state) {
    node.OnImu(transport::ToMessage(d.At(i++)));
    while (t.HandleTimeout(0) > 0) {  // drain what the node published (nobody subscribes)
    }
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_OrientationNodeRate);

// The tracker's sample at IMU sample i, every 5th (20 Hz at 100 Hz), as a POSITION message.
std::optional<position_sample_t> PositionMessage(const Stream& d, int64_t i) {
  const int64_t n = static_cast<int64_t>(d.imu.size());
  if (i % 5 != 0 || !d.pos[i % n].allFinite()) return std::nullopt;
  transport::PositionSample p;
  p.utime = d.At(i).utime;
  p.p = d.pos[i % n];
  p.covariance = 1e-6 * Eigen::Matrix3d::Identity();
  return transport::ToMessage(p);
}

// The position node without a transport: per IMU sample its IMU and ORIENTATION messages (the
// pairing by utime, the ordered flush, the accelerometer update, encode and publish), plus a
// POSITION message every 5th sample (20 Hz at 100 Hz IMU); items = IMU samples. position_kf's
// default filter: the bank of DefaultBankModels.
void BM_PositionNodeRate(benchmark::State& state) {
  const Stream& d = Data();
  transport::LcmTransport t("memq://");
  estimation::PositionKfSettings ps;
  ps.earth = estimation::EarthFrame::kEnu;
  estimation::PositionKfBankSettings bs;
  bs.models = estimation::DefaultBankModels(ps);
  transport::PositionKfNode node(t, bs, {});
  estimation::OrientationKf okf(Enu());
  const int64_t n = static_cast<int64_t>(d.imu.size());
  // Orientation messages precomputed (the orientation filter is not what is measured here).
  std::vector<orientation_estimate_t> ori;
  for (int64_t k = 0; k < n; ++k) {
    const auto s = d.At(k);
    (void)okf.Update(transport::SensorSeconds(s.utime), s.gyro_B, s.f_B, s.m_B);
    ori.push_back(transport::ToOrientationEstimate(okf, s.utime));
  }
  int64_t i = 0;
  for (auto _ : state) {
    const auto s = d.At(i);
    node.OnImu(transport::ToMessage(s));
    auto o = ori[i % n];
    o.utime = s.utime;
    node.OnOrientation(o);
    if (const auto p = PositionMessage(d, i)) node.OnPosition(*p);
    while (t.HandleTimeout(0) > 0) {
    }
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["rejected"] = static_cast<double>(node.health().rejected());
}
BENCHMARK(BM_PositionNodeRate);

// The tracker-aided INS node without a transport (aided_ins's): per IMU sample its IMU message
// (checks, the time gate, the orientation KF and the INS step, encode and publish of
// INS_ORIENTATION and INS_TOOL_POSITION), plus a POSITION message every 5th sample (20 Hz at
// 100 Hz IMU; the IMU samples wait for it, as live); items = IMU samples.
void BM_AidedInsNodeRate(benchmark::State& state) {
  const Stream& d = Data();
  transport::LcmTransport t("memq://");
  estimation::AidedInsSettings is;
  is.earth = estimation::EarthFrame::kEnu;
  transport::AidedInsNode node(t, Enu(), is, {});
  int64_t i = 0;
  for (auto _ : state) {
    node.OnImu(transport::ToMessage(d.At(i)));
    if (const auto p = PositionMessage(d, i)) node.OnPosition(*p);
    while (t.HandleTimeout(0) > 0) {
    }
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["rejected"] = static_cast<double>(node.health().rejected());
}
BENCHMARK(BM_AidedInsNodeRate);

}  // namespace

BENCHMARK_MAIN();
