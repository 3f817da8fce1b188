// Publish-to-receive latency over Cyclone DDS on loopback (config/cyclonedds-loopback.xml):
// a writer and a reader on two participants of one process, on rcal's topics with rcal's QoS.
// Each iteration writes one sample and blocks (waitset) until the reader has it, so the time per
// iteration is the one-way latency including serialisation, the loopback UDP hop and
// deserialisation. Also: the cost of the LCM → DDS conversion alone.
//
//   ./build/bench/bench_dds        (domain 231, loopback only, whatever CYCLONEDDS_URI says)
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <stdexcept>
#include <string>

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

}  // namespace

BENCHMARK_MAIN();
