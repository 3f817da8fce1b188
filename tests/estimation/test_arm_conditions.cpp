// ArmConditionsHistory: which report stands for a still window that ended at t (sample and hold,
// never a later report, never one older than max_age), bounded, in time order.
#include "rcal/estimation/arm_conditions.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace rcal::estimation {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(ArmConditions, TheNewestReportAtOrBeforeTheWindowsEndStandsForItWhileRecent) {
  ArmConditionsHistory h(10.0);
  EXPECT_FALSE(h.At(0.0));  // never reported
  h.Add({0.0, 20.0, 0.0});
  h.Add({5.0, 21.5, 5.0});
  h.Add({12.0, kNaN, 10.0});  // the temperature sensor failed: not measured
  EXPECT_FALSE(h.At(-0.5));   // before any report
  EXPECT_EQ(h.At(0.0)->temperature_c, 20.0);
  EXPECT_EQ(h.At(4.999)->temperature_c, 20.0);
  EXPECT_EQ(h.At(5.0)->payload_kg, 5.0);  // a report at the window's end is the window's
  EXPECT_EQ(h.At(11.9)->temperature_c, 21.5);
  const auto r = h.At(16.0);
  ASSERT_TRUE(r);
  EXPECT_TRUE(std::isnan(r->temperature_c));
  EXPECT_EQ(r->payload_kg, 10.0);
  EXPECT_EQ(h.At(22.0)->t, 12.0);  // exactly max_age old
  EXPECT_FALSE(h.At(22.001));      // the controller went quiet: no longer stands
  h.Clear();
  EXPECT_FALSE(h.At(16.0));
}

TEST(ArmConditions, SameTimeReplacesOlderIsRefusedAndTheHistoryIsBounded) {
  ArmConditionsHistory h(100.0, 3);
  h.Add({1.0, 20.0, 0.0});
  h.Add({1.0, 22.0, 1.0});  // a correction at the same time
  EXPECT_EQ(h.size(), 1u);
  EXPECT_EQ(h.At(1.0)->temperature_c, 22.0);
  EXPECT_THROW(h.Add({0.5, 20.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(h.Add({kNaN, 20.0, 0.0}), std::invalid_argument);
  for (int k = 2; k <= 6; ++k) h.Add({static_cast<double>(k), 20.0 + k, 0.0});
  EXPECT_EQ(h.size(), 3u);  // 4, 5, 6 kept
  EXPECT_FALSE(h.At(3.5));  // its report (3) was dropped: nothing older stands in
  EXPECT_EQ(h.At(4.5)->temperature_c, 24.0);
  EXPECT_THROW(ArmConditionsHistory{-1.0}, std::invalid_argument);
  EXPECT_THROW(ArmConditionsHistory{kNaN}, std::invalid_argument);
  EXPECT_THROW((ArmConditionsHistory{1.0, 0}), std::invalid_argument);
}

// A still window takes the report standing at its middle, not at its detected end (which lies in
// the next move), and names a payload change inside it: the pose was measured under two loads.
TEST(ArmConditions, AWindowTakesItsMiddlesReportAndNamesAPayloadChangeWithinIt) {
  ArmConditionsHistory h(10.0);
  for (int k = 0; k <= 20; ++k) {
    // 1 Hz reports: warming by 0.1 K/s; 5 kg picked at 7 s (reported then), placed at 15.004 s;
    // at 11 s the payload is not known (NaN); from 18 s a re-estimate 4 g off.
    const double t = k == 15 ? 15.004 : k;
    const double payload = k < 7 ? 0.0 : k < 15 ? (k == 11 ? kNaN : 5.0) : k < 18 ? 0.0 : 0.004;
    h.Add({t, 20.0 + 0.1 * t, payload});
  }
  // A window over the stop [2, 5.5] s ending 1 s into the move: no change; the temperature at
  // its middle (3.75 s: the 3 s report), not at its end (the 5 s report).
  auto w = h.ForWindow(2.0, 5.5);
  ASSERT_TRUE(w.standing);
  EXPECT_EQ(w.standing->t, 3.0);
  EXPECT_DOUBLE_EQ(w.standing->temperature_c, 20.3);
  EXPECT_FALSE(w.payload_change);
  // The pick reported at 7 s inside a window [5.2, 8] s: named, with the payload before it.
  w = h.ForWindow(5.2, 8.0);
  ASSERT_TRUE(w.payload_change);
  EXPECT_EQ(w.payload_change->t, 7.0);
  EXPECT_EQ(w.payload_change->payload_kg, 5.0);
  EXPECT_EQ(w.payload_before_kg, 0.0);
  // A report exactly at the window's start stands at its start: no change within it.
  EXPECT_FALSE(h.ForWindow(7.0, 9.0).payload_change);
  // Nor is the unknown payload at 11 s a change (5 → unknown → 5 kg).
  EXPECT_FALSE(h.ForWindow(10.5, 13.0).payload_change);
  // The place at 15.004 s: the window ending at 15.0 does not see it, the one ending at 15.004
  // does.
  EXPECT_FALSE(h.ForWindow(13.5, 15.0).payload_change);
  w = h.ForWindow(13.5, 15.004);
  ASSERT_TRUE(w.payload_change);
  EXPECT_EQ(w.payload_before_kg, 5.0);
  EXPECT_EQ(w.payload_change->payload_kg, 0.0);
  // 4 g is the same payload at the default tolerance, a change at a 1 g one.
  EXPECT_FALSE(h.ForWindow(16.5, 19.0).payload_change);
  EXPECT_TRUE(h.ForWindow(16.5, 19.0, 0.001).payload_change);
  // Before any report nothing stands and nothing changes; a window in a silence of the
  // controller (reports older than max_age at its middle) has none standing.
  EXPECT_FALSE(h.ForWindow(-3.0, -1.0).standing);
  EXPECT_FALSE(h.ForWindow(-3.0, -1.0).payload_change);
  EXPECT_FALSE(h.ForWindow(40.0, 42.0).standing);
  // A window that begins before the first report: the first report is not a change.
  ArmConditionsHistory late(10.0);
  late.Add({3.0, 20.0, 5.0});
  EXPECT_FALSE(late.ForWindow(1.0, 4.0).payload_change);
}

// A window may be decided once a report after its end has come: before that, a report still to
// come may fall inside it (the grasp made at the stop, reported late). The same window decided
// before and after that report: the change is seen only after.
TEST(ArmConditions, AWindowIsKnownOnceAReportAfterItsEndHasCome) {
  ArmConditionsHistory h(10.0);
  EXPECT_FALSE(h.ReportedPast(0.0));  // nothing yet
  h.Add({1.0, 20.0, 0.0});
  EXPECT_TRUE(h.ReportedPast(0.5));
  EXPECT_FALSE(h.ReportedPast(1.0));  // a report may still come at 1.0 (it would replace this)
  EXPECT_FALSE(h.ReportedPast(2.0));
  EXPECT_FALSE(h.ForWindow(1.2, 2.0).payload_change);  // decided too early: no change seen
  h.Add({1.5, 20.0, 10.0});                            // the grasp, reported late
  EXPECT_FALSE(h.ReportedPast(2.0));
  h.Add({2.5, 20.0, 10.0});
  EXPECT_TRUE(h.ReportedPast(2.0));
  const auto w = h.ForWindow(1.2, 2.0);
  ASSERT_TRUE(w.payload_change);
  EXPECT_EQ(w.payload_change->t, 1.5);
  h.Clear();  // a new time base: nothing known
  EXPECT_FALSE(h.ReportedPast(0.5));
}

// A controller reporting every 30 s, with reports standing for 60 s: its gate accepts each
// report (the sensors' 10 s horizon alone refuses nearly all of them), and still refuses one
// beyond the widened horizon.
TEST(ArmConditions, ASlowControllersReportsPassItsGate) {
  const TimeGateSettings sensors;  // horizon 10 s
  TimeGate slow(ArmConditionsGateSettings(sensors, 60.0)), plain(sensors);
  int refused_slow = 0, refused_plain = 0;
  for (int k = 0; k < 20; ++k) {
    const int64_t u = k * 30'000'000LL;
    refused_slow += !Usable(slow.Offer(u));
    refused_plain += !Usable(plain.Offer(u));
  }
  EXPECT_EQ(refused_slow, 0);
  EXPECT_GE(refused_plain, 15);
  EXPECT_EQ(slow.Offer(19 * 30'000'000LL + 61'000'000LL), TimeVerdict::kBeyondHorizon);
  // A max_age within the horizon leaves it as it is.
  EXPECT_EQ(ArmConditionsGateSettings(sensors, 5.0).horizon_us, sensors.horizon_us);
  EXPECT_EQ(ArmConditionsGateSettings(sensors, 60.0).horizon_us, 60'000'000);
}

}  // namespace
}  // namespace rcal::estimation
