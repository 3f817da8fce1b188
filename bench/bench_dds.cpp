// Publish-to-receive latency over Cyclone DDS on loopback (config/cyclonedds-loopback.xml unless
// CYCLONEDDS_URI says otherwise), with rcal's types and QoS:
//   - BM_DdsLatency*: a writer and a reader on two participants of this process; each iteration
//     writes one sample and blocks (waitset) until the reader has taken it: one-way latency.
//     Cyclone delivers between entities of one process without the network, so this is the
//     floor.
//   - BM_DdsRoundTrip*: a second process (this program, re-executed with --pong) echoes every
//     sample back on a second topic; each iteration is one round trip through loopback UDP with
//     serialisation both ways. One-way publish-to-receive ≈ half of it.
//   - BM_ConvertKinematicParamsToDds: the LCM → DDS conversion alone.
//
//   ./build/bench/bench_dds        (DDS domain 231: never the pipeline's domain)
#include <benchmark/benchmark.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "rcal/dds/convert.hpp"
#include "rcal/dds/dds_common.hpp"

namespace {

using namespace rcal::dds;
constexpr dds_domainid_t kDomain = 231;

rcal::kinematic_params_t Params(int n) {
  rcal::kinematic_params_t m;
  m.utime = 1'700'000'000'123'456;
  m.robot_id = "grb3016";
  m.model_id = "grb3016:00c0ffee12345678";
  m.num_params = n;
  for (int i = 0; i < n; ++i) {
    std::string name = "p";
    name += std::to_string(i);
    m.names.push_back(name);
    m.values.push_back(1e-3 * i / 3.0);
    m.sigmas.push_back(1e-6 * (i + 1));
    m.identified.push_back(i % 5 != 4);
  }
  m.poses_used = 50;
  m.num_effect_params = 0;
  return m;
}

rcal::tool_position_estimate_t Position() {
  rcal::tool_position_estimate_t m{};
  m.utime = 1'700'000'000'123'456;
  for (int i = 0; i < 3; ++i) m.p[i] = 0.5 + i;
  for (int i = 0; i < 36; ++i) m.covariance[i] = 1e-8 * (i % 7 == 0);
  return m;
}

// Writer and reader of one topic on two participants, matched before timing starts.
template <typename T>
struct Link {
  EntityGuard pub, sub;
  dds_entity_t writer = 0, reader = 0, waitset = 0;

  Link(const char* topic, dds_qos_t* qos)
      : pub(dds_create_participant(kDomain, nullptr, nullptr)),
        sub(dds_create_participant(kDomain, nullptr, nullptr)) {
    if (pub.get() < 0 || sub.get() < 0) throw std::runtime_error("dds_create_participant");
    const dds_entity_t tw = dds_create_topic(pub.get(), Descriptor<T>(), topic, qos, nullptr);
    const dds_entity_t tr = dds_create_topic(sub.get(), Descriptor<T>(), topic, qos, nullptr);
    writer = dds_create_writer(pub.get(), tw, qos, nullptr);
    reader = dds_create_reader(sub.get(), tr, qos, nullptr);
    dds_delete_qos(qos);
    waitset = dds_create_waitset(sub.get());
    const dds_entity_t cond = dds_create_readcondition(reader, DDS_ANY_STATE);
    dds_waitset_attach(waitset, cond, 0);
    // Wait (guarded) until the writer sees the reader.
    dds_publication_matched_status_t st{};
    for (int i = 0; i < 1000 && st.current_count == 0; ++i) {
      dds_get_publication_matched_status(writer, &st);
      if (st.current_count == 0) dds_sleepfor(DDS_MSECS(10));
    }
    if (st.current_count == 0) throw std::runtime_error("writer and reader did not match");
  }

  // Writes `sample`, waits for it, takes it. False when it did not come (best-effort loss).
  bool RoundTrip(const T& sample) {
    dds_write(writer, &sample);
    if (dds_waitset_wait(waitset, nullptr, 0, DDS_SECS(1)) <= 0) return false;
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    const int n = dds_take(reader, samples, &info, 1, 1);
    if (n > 0) dds_return_loan(reader, samples, n);
    return n > 0;
  }
};

void BM_DdsLatencyKinematicParams(benchmark::State& state) {
  EnsureCycloneConfig();
  Link<KinematicParams> link(kKinematicParamsTopic, LatchedQos());
  std::string e;
  auto s = ToDds(Params(static_cast<int>(state.range(0))), &e);
  int64_t lost = 0;
  for (auto _ : state) lost += !link.RoundTrip(s->get());
  state.counters["lost"] = static_cast<double>(lost);
  state.SetLabel("reliable, transient-local, depth 1");
}
BENCHMARK(BM_DdsLatencyKinematicParams)->Arg(28)->Arg(200)->UseRealTime();

void BM_DdsLatencyToolPose(benchmark::State& state) {
  EnsureCycloneConfig();
  Link<ToolPose> link(kToolPoseTopic, StreamQos());
  std::string e;
  auto s = ToDds(Position(), nullptr, "grb3016", &e);
  int64_t lost = 0;
  for (auto _ : state) lost += !link.RoundTrip(s->get());
  state.counters["lost"] = static_cast<double>(lost);
  state.SetLabel("best-effort");
}
BENCHMARK(BM_DdsLatencyToolPose)->UseRealTime();

void BM_ConvertKinematicParamsToDds(benchmark::State& state) {
  const auto m = Params(static_cast<int>(state.range(0)));
  std::string e;
  for (auto _ : state) {
    auto s = ToDds(m, &e);
    benchmark::DoNotOptimize(s);
  }
}
BENCHMARK(BM_ConvertKinematicParamsToDds)->Arg(28)->Arg(200);

// ---- across processes
// ----------------------------------------------------------------------------

constexpr const char* kPing = "rt/rcal_bench/ping";
constexpr const char* kPong = "rt/rcal_bench/pong";

template <typename T>
dds_qos_t* QosOf() {
  return std::is_same_v<T, ToolPose> ? StreamQos() : LatchedQos();
}

// A reader of `from` and a writer of `to` on one participant, the reader behind a waitset.
template <typename T>
struct Ends {
  EntityGuard participant{dds_create_participant(kDomain, nullptr, nullptr)};
  dds_entity_t reader = 0, writer = 0, waitset = 0;
  Ends(const char* from, const char* to) {
    if (participant.get() < 0) throw std::runtime_error("dds_create_participant");
    dds_qos_t* qos = QosOf<T>();
    const dds_entity_t tf =
        dds_create_topic(participant.get(), Descriptor<T>(), from, qos, nullptr);
    const dds_entity_t tt = dds_create_topic(participant.get(), Descriptor<T>(), to, qos, nullptr);
    reader = dds_create_reader(participant.get(), tf, qos, nullptr);
    writer = dds_create_writer(participant.get(), tt, qos, nullptr);
    dds_delete_qos(qos);
    waitset = dds_create_waitset(participant.get());
    dds_waitset_attach(waitset, dds_create_readcondition(reader, DDS_ANY_STATE), 0);
  }
  // Waits for one sample (up to `timeout`), takes it and, when `echo`, writes it back.
  bool Receive(dds_duration_t timeout, bool echo) {
    if (dds_waitset_wait(waitset, nullptr, 0, timeout) <= 0) return false;
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    const int n = dds_take(reader, samples, &info, 1, 1);
    if (n <= 0) return false;
    if (echo && info.valid_data) dds_write(writer, samples[0]);
    dds_return_loan(reader, samples, n);
    return true;
  }
};

// The --pong process: echoes every sample on kPing back on kPong until killed.
template <typename T>
int Pong() {
  Ends<T> ends(kPing, kPong);
  for (;;) ends.Receive(DDS_SECS(1), true);
}

template <typename T>
void RoundTrip(benchmark::State& state, const char* type, const T& sample) {
  EnsureCycloneConfig();
  const pid_t child = fork();
  if (child == 0) {  // a fresh process image: no DDS state inherited
    char self[4096] = {};
    if (readlink("/proc/self/exe", self, sizeof self - 1) < 0) _exit(127);
    execl(self, self, "--pong", type, static_cast<char*>(nullptr));
    _exit(127);
  }
  {
    Ends<T> ends(kPong, kPing);
    dds_publication_matched_status_t pub{};
    dds_subscription_matched_status_t sub{};
    for (int i = 0; i < 1000 && (pub.current_count == 0 || sub.current_count == 0); ++i) {
      dds_get_publication_matched_status(ends.writer, &pub);
      dds_get_subscription_matched_status(ends.reader, &sub);
      dds_sleepfor(DDS_MSECS(10));
    }
    if (pub.current_count == 0 || sub.current_count == 0) {
      state.SkipWithError("the --pong process did not match");
    } else {
      int64_t lost = 0;
      for (auto _ : state) {
        dds_write(ends.writer, &sample);
        lost += !ends.Receive(DDS_SECS(1), false);
      }
      state.counters["lost"] = static_cast<double>(lost);
    }
  }
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
}

void BM_DdsRoundTripKinematicParams(benchmark::State& state) {
  std::string e;
  const auto s = ToDds(Params(static_cast<int>(state.range(0))), &e);
  RoundTrip(state, "kinematic_params", s->get());
  state.SetLabel("2 processes, reliable, transient-local, depth 1");
}
BENCHMARK(BM_DdsRoundTripKinematicParams)->Arg(28)->Arg(200)->UseRealTime();

void BM_DdsRoundTripToolPose(benchmark::State& state) {
  std::string e;
  const auto s = ToDds(Position(), nullptr, "grb3016", &e);
  RoundTrip(state, "tool_pose", s->get());
  state.SetLabel("2 processes, best-effort");
}
BENCHMARK(BM_DdsRoundTripToolPose)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "--pong") == 0) {
    EnsureCycloneConfig();
    if (std::strcmp(argv[2], "tool_pose") == 0) return Pong<ToolPose>();
    return Pong<KinematicParams>();
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
