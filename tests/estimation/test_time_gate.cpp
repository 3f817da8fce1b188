// The time gate against hand-worked sample sequences: every verdict and counter is the number
// the rules of time_gate.hpp give for that sequence.
#include "rcal/estimation/time_gate.hpp"

#include <gtest/gtest.h>

#include <vector>

namespace rcal::estimation {
namespace {

constexpr int64_t kPeriod = 10'000;     // 100 Hz [µs]
constexpr int64_t kPoison = 1LL << 62;  // the time of issue 11
using V = TimeVerdict;

TEST(TimeGate, AcceptsAnIncreasingStreamAndCountsNothingElse) {
  TimeGate g;
  for (int k = 0; k < 100; ++k) EXPECT_EQ(g.Offer(k * kPeriod), V::kAccepted);
  EXPECT_EQ(g.counters().accepted, 100);
  EXPECT_EQ(g.counters().gap_samples, 0);
  EXPECT_EQ(g.period_us(), kPeriod);
  EXPECT_EQ(*g.last(), 99 * kPeriod);
}

TEST(TimeGate, AFarFutureSampleIsRefusedAndNeverBecomesTheLastTime) {
  TimeGate g;
  for (int k = 0; k < 10; ++k) g.Offer(k * kPeriod);
  EXPECT_EQ(g.Offer(kPoison), V::kBeyondHorizon);
  EXPECT_EQ(*g.last(), 9 * kPeriod);
  // The stream goes on as if the poison never came.
  for (int k = 10; k < 20; ++k) EXPECT_EQ(g.Offer(k * kPeriod), V::kAccepted) << k;
  EXPECT_EQ(g.counters().beyond_horizon, 1);
  EXPECT_EQ(g.counters().resyncs, 0);
  EXPECT_NE(g.Reason(V::kBeyondHorizon, kPoison, "imu_sample.utime").find("imu_sample.utime"),
            std::string::npos);
}

TEST(TimeGate, TheHorizonIsInclusive) {
  TimeGateSettings s;
  s.horizon_us = 1000;
  TimeGate g(s);
  g.Offer(0);
  EXPECT_EQ(g.Offer(1000), V::kAccepted);
  EXPECT_EQ(g.Offer(2001), V::kBeyondHorizon);
}

TEST(TimeGate, TheCeilingGuardsTheFirstSample) {
  TimeGateSettings s;
  s.ceiling_us = 1'000'000;
  TimeGate g(s);
  EXPECT_EQ(g.Offer(kPoison), V::kBeyondHorizon);  // no reference yet: the ceiling decides
  EXPECT_FALSE(g.last());
  EXPECT_EQ(g.Offer(5), V::kAccepted);
  EXPECT_EQ(*g.last(), 5);
  // Many samples beyond the ceiling never re-synchronise the source.
  for (int k = 0; k < 20; ++k) EXPECT_EQ(g.Offer(kPoison + k), V::kBeyondHorizon);
  EXPECT_EQ(*g.last(), 5);
  EXPECT_EQ(g.counters().beyond_horizon, 21);
}

TEST(TimeGate, HostCeilingIsADayAheadOfNow) {
  // 2026-ish epoch µs: between 2020 and 2100, plus a day.
  const int64_t c = HostCeilingUs();
  EXPECT_GT(c, 1'577'836'800'000'000LL + 86'400'000'000LL);
  EXPECT_LT(c, 4'102'444'800'000'000LL);
  EXPECT_LT(c, kPoison);
}

TEST(TimeGate, ExactDuplicatesAreCountedApart) {
  TimeGate g;
  g.Offer(0);
  g.Offer(kPeriod);
  EXPECT_EQ(g.Offer(kPeriod), V::kDuplicate);
  EXPECT_EQ(g.Offer(kPeriod), V::kDuplicate);
  EXPECT_EQ(g.Offer(kPeriod / 2), V::kOutOfOrder);
  EXPECT_EQ(g.counters().duplicates, 2);
  EXPECT_EQ(g.counters().out_of_order, 1);
  EXPECT_EQ(g.counters().accepted, 2);
}

TEST(TimeGate, ARestartedDriverIsResynchronisedAfterNConsistentSamples) {
  TimeGateSettings s;
  s.resync_samples = 5;
  TimeGate g(s);
  for (int k = 0; k < 1000; ++k) g.Offer(5'000'000 + k * kPeriod);
  // The driver starts over at 0: 4 refused, the 5th re-synchronises and is used.
  std::vector<V> got;
  for (int k = 0; k < 8; ++k) got.push_back(g.Offer(k * kPeriod));
  EXPECT_EQ(got, (std::vector<V>{V::kOutOfOrder, V::kOutOfOrder, V::kOutOfOrder, V::kOutOfOrder,
                                 V::kResynchronised, V::kAccepted, V::kAccepted, V::kAccepted}));
  EXPECT_EQ(*g.last(), 7 * kPeriod);
  EXPECT_EQ(g.counters().resyncs, 1);
  EXPECT_EQ(g.counters().out_of_order, 4);
  EXPECT_EQ(g.counters().gap_samples, 0);  // the jump is not a gap
}

// Found by the poison integration test on a loaded machine: the test resends every POSITION, and
// when it was descheduled its resends of 19.91–19.95 s arrived together after 19.96 s had been
// accepted. Five increasing, mutually consistent out-of-order samples re-synchronised the
// stream 10 ms back in time and restarted the filter (a window lost). Late data just below the
// last time is never a new time base.
TEST(TimeGate, ABurstOfLateResendsDoesNotPullTheStreamBack) {
  TimeGate g;  // resync_samples 5, resync_min_jump_back_us 1 s
  for (int k = 0; k <= 1996; ++k) g.Offer(k * kPeriod);
  for (int k = 1991; k <= 1995; ++k) EXPECT_EQ(g.Offer(k * kPeriod), V::kOutOfOrder) << k;
  EXPECT_EQ(g.counters().resyncs, 0);
  EXPECT_EQ(*g.last(), 1996 * kPeriod);
  EXPECT_EQ(g.Offer(1997 * kPeriod), V::kAccepted);
}

TEST(TimeGate, AnInconsistentRunDoesNotResynchronise) {
  TimeGateSettings s;
  s.resync_samples = 3;
  TimeGate g(s);
  for (int k = 0; k < 10; ++k) g.Offer(1'000'000'000 + k * kPeriod);
  // Old samples going backwards, or duplicates of each other, are no new time base.
  EXPECT_EQ(g.Offer(300), V::kOutOfOrder);
  EXPECT_EQ(g.Offer(200), V::kOutOfOrder);
  EXPECT_EQ(g.Offer(100), V::kOutOfOrder);
  EXPECT_EQ(g.Offer(100), V::kOutOfOrder);
  EXPECT_EQ(g.counters().resyncs, 0);
  EXPECT_EQ(*g.last(), 1'000'000'000 + 9 * kPeriod);
}

TEST(TimeGate, APauseLongerThanTheHorizonResynchronisesForward) {
  TimeGateSettings s;
  s.resync_samples = 3;
  TimeGate g(s);
  g.Offer(0);
  const int64_t later = 60'000'000;  // 60 s later, horizon 10 s
  EXPECT_EQ(g.Offer(later), V::kBeyondHorizon);
  EXPECT_EQ(g.Offer(later + kPeriod), V::kBeyondHorizon);
  EXPECT_EQ(g.Offer(later + 2 * kPeriod), V::kResynchronised);
  EXPECT_EQ(g.Offer(later + 3 * kPeriod), V::kAccepted);
}

TEST(TimeGate, GapsCountTheMissingSamples) {
  TimeGate g;
  for (int k : {0, 1, 2, 5, 6, 10}) g.Offer(k * kPeriod);  // 3, 4 and 7, 8, 9 missing
  EXPECT_EQ(g.counters().gap_samples, 5);
  // µs jitter of a 100 Hz stream is no gap.
  TimeGate j;
  for (int64_t u : {0, 10'000, 19'999, 30'001, 40'000}) j.Offer(u);
  EXPECT_EQ(j.counters().gap_samples, 0);
}

TEST(TimeGate, RestoreTakesATrustedTimeBase) {
  TimeGate g;
  g.Restore(1000);
  EXPECT_EQ(g.Offer(1000), V::kDuplicate);
  EXPECT_EQ(g.Offer(2000), V::kAccepted);
  EXPECT_EQ(g.counters().accepted, 1);
}

TEST(TimeGate, ExtremeTimesDoNotOverflow) {
  TimeGate g;
  g.Offer(std::numeric_limits<int64_t>::min());
  EXPECT_EQ(g.Offer(std::numeric_limits<int64_t>::max()), V::kBeyondHorizon);
  EXPECT_EQ(*g.last(), std::numeric_limits<int64_t>::min());
}

}  // namespace
}  // namespace rcal::estimation
