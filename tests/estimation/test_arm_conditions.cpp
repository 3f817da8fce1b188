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
