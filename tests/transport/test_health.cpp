// The heartbeat schedule follows message time, not the wall clock.
#include <gtest/gtest.h>

#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

TEST(Health, BeatsOncePerSecondOfSensorTime) {
  Health h("proc");
  std::vector<int64_t> beats;
  // 10 Hz of sensor time over 3.05 s, with a 2 s gap in the middle.
  std::vector<int64_t> times;
  for (int64_t t = 0; t <= 1'000'000; t += 100'000) times.push_back(t);
  for (int64_t t = 3'050'000; t <= 4'000'000; t += 100'000) times.push_back(t);
  for (int64_t t : times)
    if (auto b = h.Tick(t)) beats.push_back(b->utime);
  // Independent truth: first sample, then the first sample at or after each whole second of the
  // schedule; the gap gives one beat, not a burst.
  EXPECT_EQ(beats, (std::vector<int64_t>{0, 1'000'000, 3'050'000}));
}

TEST(Health, ScheduleIsAnchoredToTheFirstBeat) {
  Health h("proc");
  std::vector<int64_t> beats;
  for (int64_t t : {500'000, 900'000, 1'499'999, 1'500'000, 2'600'000, 3'400'000, 3'500'000})
    if (auto b = h.Tick(t)) beats.push_back(b->utime);
  EXPECT_EQ(beats, (std::vector<int64_t>{500'000, 1'500'000, 2'600'000, 3'500'000}));
}

TEST(Health, ReplayStartingOverRestartsTheSchedule) {
  Health h("proc");
  int n = 0;
  for (int64_t t : {10'000'000, 11'000'000, 0, 500'000, 1'000'000})
    if (h.Tick(t)) ++n;
  EXPECT_EQ(n, 4);  // 10 s, 11 s, 0 (restart), 1 s
}

TEST(Health, CountsAndLastErrorArePublished) {
  LcmTransport t("memq://");
  std::vector<health_t> got;
  t.Subscribe<health_t>("HEALTH", [&](const health_t& m) { got.push_back(m); });
  Health h("ekf_identifier");
  h.Received();
  h.Received();
  h.Received();
  h.Rejected("pose_measurement.q: not finite");
  h.Published();
  h.Activity("converging");
  h.Activity("change_detected");  // the latest is what is said
  EXPECT_TRUE(h.Tick(42, t));
  EXPECT_FALSE(h.Tick(43, t));
  while (t.HandleTimeout(0) > 0) {
  }
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].utime, 42);
  EXPECT_EQ(got[0].process, "ekf_identifier");
  EXPECT_EQ(got[0].received, 3);
  EXPECT_EQ(got[0].rejected, 1);
  EXPECT_EQ(got[0].published, 2);  // one message plus this heartbeat
  EXPECT_EQ(got[0].last_error, "pose_measurement.q: not finite");
  EXPECT_EQ(got[0].activity, "change_detected");
  EXPECT_GT(got[0].pid, 0);
}

// A transport that loses messages below the process: Tick with it puts its count in the beat.
class LossyTransport final : public Transport {
 public:
  bool PublishRaw(const std::string& channel, const void* data, int size) override {
    return inner.PublishRaw(channel, data, size);
  }
  void SubscribeRaw(const std::string& channel, RawHandler handler) override {
    inner.SubscribeRaw(channel, std::move(handler));
  }
  int HandleTimeout(int timeout_ms) override { return inner.HandleTimeout(timeout_ms); }
  int64_t Dropped() const override { return dropped; }
  LcmTransport inner{"memq://"};
  int64_t dropped = 0;
};

TEST(Health, TheTransportsDropsAreInTheBeat) {
  LossyTransport t;
  std::vector<health_t> got;
  t.Subscribe<health_t>("HEALTH", [&](const health_t& m) { got.push_back(m); });
  Health h("still_window");
  t.dropped = 17;
  EXPECT_TRUE(h.Tick(0, t));
  t.dropped = 40;
  EXPECT_FALSE(h.Tick(500'000, t));  // no beat due: read at the next one
  EXPECT_EQ(h.dropped(), 17);
  EXPECT_TRUE(h.Tick(1'000'000, t));
  while (t.HandleTimeout(0) > 0) {
  }
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].dropped, 17);
  EXPECT_EQ(got[1].dropped, 40);
  EXPECT_EQ(h.Message(2'000'000).dropped, 40);
}

// A process that stops publishes its final counts at once, whatever the schedule: losses after
// the last scheduled beat (here 0.9 s of sensor time of them) are on record too.
TEST(Health, TheFinalBeatCarriesTheCountsUpToTheEnd) {
  LossyTransport t;
  std::vector<health_t> got;
  t.Subscribe<health_t>("HEALTH_C", [&](const health_t& m) { got.push_back(m); });
  Health h("position_kf");
  EXPECT_TRUE(h.Tick(1'000'000, t, "HEALTH_C"));
  h.Rejected("imu_sample.utime: late");
  h.Gap(3);
  t.dropped = 5;
  EXPECT_FALSE(h.Tick(1'900'000, t, "HEALTH_C"));  // none due
  EXPECT_TRUE(h.Final(t, "HEALTH_C"));
  while (t.HandleTimeout(0) > 0) {
  }
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[1].utime, 1'900'000);
  EXPECT_EQ(got[1].rejected, 1);
  EXPECT_EQ(got[1].gaps, 3);
  EXPECT_EQ(got[1].dropped, 5);
  EXPECT_EQ(got[1].published, 2);  // both beats
  EXPECT_EQ(got[1].last_error, "imu_sample.utime: late");
}

// The new counts (issue 11, item 6) reach the message: a gate's verdicts counted apart and in
// rejected, gaps from the gate, stale and filter resets.
TEST(Health, TimeGateVerdictsAndLossesAreCountedInTheMessage) {
  Health h("still_window");
  estimation::TimeGate g;
  for (int64_t u : {0, 10'000, 20'000, 50'000}) h.Gate(g, u, "imu_sample.utime");  // 2 missing
  EXPECT_EQ(h.Gate(g, 50'000, "imu_sample.utime"), estimation::TimeVerdict::kDuplicate);
  EXPECT_EQ(h.Gate(g, 40'000, "imu_sample.utime"), estimation::TimeVerdict::kOutOfOrder);
  EXPECT_EQ(h.Gate(g, int64_t{1} << 62, "imu_sample.utime"),
            estimation::TimeVerdict::kBeyondHorizon);
  EXPECT_NE(h.last_error().find("imu_sample.utime"), std::string::npos);
  h.Stale("kinematic_params: older");
  h.FilterReset("orientation_kf: state went non-finite");
  h.Gap(3);
  const health_t m = h.Message(50'000);
  EXPECT_EQ(m.rejected, 4);
  EXPECT_EQ(m.duplicates, 1);
  EXPECT_EQ(m.out_of_order, 1);
  EXPECT_EQ(m.out_of_horizon, 1);
  EXPECT_EQ(m.stale, 1);
  EXPECT_EQ(m.gaps, 2 + 3);
  EXPECT_EQ(m.filter_resets, 1);
  EXPECT_EQ(m.resyncs, 0);
  EXPECT_EQ(m.last_error, "orientation_kf: state went non-finite");
}

}  // namespace
}  // namespace rcal::transport
