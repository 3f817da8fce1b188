// LcmTransport over memq://: typed round trips, and bytes that are not the subscribed type are
// rejected through the error handler, never delivered; over udpm:// in a private network
// namespace: the subscription queue's capacity.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>

#include "../integration/netns.hpp"
#include "rcal/health_t.hpp"
#include "rcal/pose_measurement_t.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::transport {
namespace {

pose_measurement_t Sample() {
  pose_measurement_t m;
  m.utime = 123456789;
  m.pose_index = 7;
  m.marker_id = 0;
  m.num_joints = 2;
  m.q = {0.1, -0.2};
  m.p[0] = 1;
  m.p[1] = 2;
  m.p[2] = 3;
  m.has_orientation = false;
  m.q_EI[0] = 1;
  m.dimension = 3;
  m.num_covariance = 9;
  m.covariance = {1e-8, 0, 0, 0, 1e-8, 0, 0, 0, 1e-8};
  m.temperature_c = 21.5;
  m.payload_kg = 0;
  m.time_s = 12.0;
  m.dq_sign = {1, -1};
  return m;
}

TEST(LcmTransport, TypedRoundTripOverMemq) {
  LcmTransport t("memq://");
  std::vector<pose_measurement_t> got;
  int errors = 0;
  t.Subscribe<pose_measurement_t>(
      "POSE_MEASUREMENT", [&](const pose_measurement_t& m) { got.push_back(m); },
      [&](const std::string&) { ++errors; });
  ASSERT_TRUE(t.Publish("POSE_MEASUREMENT", Sample()));
  ASSERT_TRUE(t.Publish("OTHER", Sample()));  // not subscribed
  while (t.HandleTimeout(0) > 0) {
  }
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(errors, 0);
  EXPECT_EQ(got[0].utime, 123456789);
  EXPECT_EQ(got[0].pose_index, 7);
  EXPECT_EQ(got[0].q, (std::vector<double>{0.1, -0.2}));
  EXPECT_EQ(got[0].p[2], 3.0);
  EXPECT_EQ(got[0].covariance[4], 1e-8);
}

// A burst that arrives before the subscriber handles any of it is delivered whole: LCM's own
// per-subscription queue holds 30 and drops the rest silently (the control, with capacity 30).
// Over udpm (memq:// has no such queue), inside a private network namespace.
TEST(LcmTransport, ABurstOfAFewHundredMessagesIsQueuedNotDropped) {
  RCAL_IN_NAMESPACE("LcmTransport.ABurstOfAFewHundredMessagesIsQueuedNotDropped");
  constexpr int kBurst = 500;
  for (const int capacity : {30, kDefaultQueueCapacity}) {
    // A socket buffer that holds the whole burst (~1 kB of kernel memory per datagram), so that
    // only LCM's queue can drop.
    LcmTransport t("udpm://239.255.76.67:7751?ttl=0&recv_buf_size=2097152", capacity);
    int got = 0;
    t.Subscribe<pose_measurement_t>("POSE_MEASUREMENT", [&](const pose_measurement_t&) { ++got; });
    for (int k = 0; k < kBurst; ++k) ASSERT_TRUE(t.Publish("POSE_MEASUREMENT", Sample()));
    usleep(300'000);  // LCM's receive thread queues them meanwhile
    while (t.HandleTimeout(50) > 0) {
    }
    if (capacity < kBurst) {
      // LCM's own default: the queue's 30, and at most the one its receive thread had in hand.
      EXPECT_LE(got, capacity + 1);
    } else {
      EXPECT_EQ(got, kBurst);
    }
  }
}

// Datagrams the kernel drops at the receive socket are counted: a socket buffer of the kernel's
// minimum (~2 datagrams) and a burst sent faster than LCM's receive thread drains it lose some;
// every datagram sent is then either delivered or in Dropped(). The LCM queue holds the whole
// burst, so that the kernel is the only place to lose one.
TEST(LcmTransport, DatagramsTheKernelDropsAreCounted) {
  RCAL_IN_NAMESPACE("LcmTransport.DatagramsTheKernelDropsAreCounted");
  constexpr int kBurst = 20000;
  const std::string url = "udpm://239.255.76.67:7752?ttl=0&recv_buf_size=1";
  LcmTransport rx(url, kBurst);
  EXPECT_EQ(rx.receive_socket(), -1);
  EXPECT_EQ(rx.Dropped(), 0);
  int got = 0;
  rx.Subscribe<pose_measurement_t>("POSE_MEASUREMENT", [&](const pose_measurement_t&) { ++got; });
  ASSERT_GE(rx.receive_socket(), 0) << "the receive socket was not found";
  LcmTransport tx(url);
  pose_measurement_t m = Sample();
  m.num_joints = 100;  // ~1 kB: a datagram per message, a few per minimum buffer
  m.q.assign(100, 0.1);
  m.dq_sign.assign(100, 0);  // one per joint: the encoder reads num_joints of each
  for (int k = 0; k < kBurst; ++k) ASSERT_TRUE(tx.Publish("POSE_MEASUREMENT", m));
  usleep(300'000);
  while (rx.HandleTimeout(50) > 0) {
  }
  std::printf("%d of %d delivered, %lld dropped by the kernel\n", got, kBurst,
              static_cast<long long>(rx.Dropped()));
  EXPECT_GT(rx.Dropped(), 0) << "nothing was dropped: the test shows nothing";
  EXPECT_EQ(got + rx.Dropped(), kBurst) << got << " delivered, " << rx.Dropped() << " dropped";
}

TEST(LcmTransport, WrongTypeAndTruncatedBytesAreRejectedNotDelivered) {
  LcmTransport t("memq://");
  int delivered = 0;
  std::vector<std::string> errors;
  t.Subscribe<pose_measurement_t>(
      "POSE_MEASUREMENT", [&](const pose_measurement_t&) { ++delivered; },
      [&](const std::string& e) { errors.push_back(e); });
  health_t h;
  h.utime = 1;
  h.process = "x";
  ASSERT_TRUE(t.Publish("POSE_MEASUREMENT", h));  // another type: fingerprint differs
  const pose_measurement_t m = Sample();
  std::vector<uint8_t> bytes(m.getEncodedSize());
  m.encode(bytes.data(), 0, bytes.size());
  ASSERT_TRUE(t.PublishRaw("POSE_MEASUREMENT", bytes.data(), bytes.size() / 2));  // truncated
  ASSERT_TRUE(t.PublishRaw("POSE_MEASUREMENT", bytes.data(), 0));                 // empty
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_EQ(delivered, 0);
  ASSERT_EQ(errors.size(), 3u);
  EXPECT_NE(errors[0].find("POSE_MEASUREMENT"), std::string::npos) << errors[0];
  EXPECT_NE(errors[0].find("pose_measurement_t"), std::string::npos) << errors[0];
  // The transport still works afterwards.
  ASSERT_TRUE(t.Publish("POSE_MEASUREMENT", m));
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_EQ(delivered, 1);
}

TEST(LcmTransport, RegexSubscriptionSeesEveryChannel) {
  LcmTransport t("memq://");
  std::vector<std::string> channels;
  t.SubscribeRaw(".*", [&](const std::string& ch, const void*, int) { channels.push_back(ch); });
  t.Publish("A", Sample());
  t.Publish("B_LONGER", Sample());
  while (t.HandleTimeout(0) > 0) {
  }
  EXPECT_EQ(channels, (std::vector<std::string>{"A", "B_LONGER"}));
}

TEST(ResolveLcmUrl, ArgumentThenEnvironmentThenDefault) {
  ::unsetenv("RCAL_LCM_URL");
  EXPECT_EQ(ResolveLcmUrl(), "udpm://239.255.76.67:7667?ttl=0");
  ::setenv("RCAL_LCM_URL", "udpm://239.255.76.67:7799?ttl=0", 1);
  EXPECT_EQ(ResolveLcmUrl(), "udpm://239.255.76.67:7799?ttl=0");
  EXPECT_EQ(ResolveLcmUrl("memq://"), "memq://");
  ::setenv("RCAL_LCM_URL", "", 1);
  EXPECT_EQ(ResolveLcmUrl(), kDefaultLcmUrl);
  ::unsetenv("RCAL_LCM_URL");
}

}  // namespace
}  // namespace rcal::transport
