// The LCM log reader (libs/io/src/lcm_log.cpp) on logs written by liblcm's own writer
// (lcm::LogFile, what lcm-logger uses), intact and with the damage fuzzing found: a flipped length
// bit, datalen = 0x7fffffff, a cut tail, garbage between events. Each test asserts exactly which
// events come back (by the payload the writer was given) and what is counted as lost.
#include "rcal/io/lcm_log.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <lcm/lcm-cpp.hpp>
#include <string>
#include <vector>

#include "io_test_util.hpp"

namespace rcal::io {
namespace {

namespace fs = std::filesystem;

constexpr int kEvents = 10;

// Event i: channel "A" (even) or "CHANNEL_B" (odd), timestamp 1000 + i, data of 20 + 7i bytes
// whose first byte is i.
std::vector<uint8_t> Payload(int i) {
  std::vector<uint8_t> d(static_cast<size_t>(20 + 7 * i));
  for (size_t k = 0; k < d.size(); ++k) d[k] = static_cast<uint8_t>(i + 3 * k);
  d[0] = static_cast<uint8_t>(i);
  return d;
}
std::string ChannelOf(int i) {
  return i % 2 == 0 ? "A" : "CHANNEL_B";
}
int64_t FrameBytes(int i) {
  return kLcmLogHeaderBytes + static_cast<int64_t>(ChannelOf(i).size()) +
         static_cast<int64_t>(Payload(i).size());
}
int64_t OffsetOf(int i) {
  int64_t o = 0;
  for (int k = 0; k < i; ++k) o += FrameBytes(k);
  return o;
}

std::vector<uint8_t> WriteLog() {
  const testing::ScratchDir scratch;  // the running test's own (ctest runs them side by side)
  const fs::path path = scratch / "written.lcmlog";
  {
    lcm::LogFile log(path.string(), "w");
    EXPECT_TRUE(log.good());
    for (int i = 0; i < kEvents; ++i) {
      std::vector<uint8_t> d = Payload(i);
      lcm::LogEvent e;
      e.eventnum = i;
      e.timestamp = 1000 + i;
      e.channel = ChannelOf(i);
      e.datalen = static_cast<int32_t>(d.size());
      e.data = d.data();
      EXPECT_EQ(log.writeEvent(&e), 0);
    }
  }
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
  EXPECT_EQ(static_cast<int64_t>(bytes.size()), OffsetOf(kEvents));  // the layout above
  return bytes;
}

void PutBe32(std::vector<uint8_t>& b, int64_t at, uint32_t v) {
  for (int k = 0; k < 4; ++k)
    b[static_cast<size_t>(at + k)] = static_cast<uint8_t>(v >> (24 - 8 * k));
}
constexpr int64_t kDataLenAt = 24;  // in the header

// The events read, by the index in their payload's first byte; every one checked bit-exact
// (`shift`: bytes inserted before the first event).
std::vector<int> ReadAll(LcmLogReader& r, int64_t shift = 0) {
  std::vector<int> got;
  while (auto e = r.Next()) {
    const int i = e->data.empty() ? -1 : e->data[0];
    got.push_back(i);
    if (i < 0 || i >= kEvents) continue;
    EXPECT_EQ(e->channel, ChannelOf(i));
    EXPECT_EQ(e->timestamp_us, 1000 + i);
    EXPECT_EQ(e->offset, OffsetOf(i) + shift);
    if (e->data != Payload(i)) got.back() = 100 + i;  // damaged content: marked
  }
  return got;
}

std::vector<int> Except(std::initializer_list<int> lost) {
  std::vector<int> v;
  for (int i = 0; i < kEvents; ++i)
    if (std::find(lost.begin(), lost.end(), i) == lost.end()) v.push_back(i);
  return v;
}

TEST(LcmLog, AnIntactLogIsReadBitExactFromAFileAndFromMemory) {
  const std::vector<uint8_t> bytes = WriteLog();
  const testing::ScratchDir scratch;
  const fs::path path = scratch / "intact.lcmlog";
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), static_cast<long>(bytes.size()));
  EXPECT_TRUE(IsLcmLogFile(path));
  LcmLogReader file(path);
  EXPECT_EQ(ReadAll(file), Except({}));
  EXPECT_FALSE(file.stats().lost());
  EXPECT_EQ(file.stats().events_read, kEvents);
  EXPECT_EQ(file.stats().Summary(),
            "events read 10, skipped 0, broken frames 0, bytes unreadable 0");
  LcmLogReader memory(bytes);
  EXPECT_EQ(ReadAll(memory), Except({}));
  EXPECT_FALSE(memory.stats().lost());
  EXPECT_THROW(LcmLogReader(fs::temp_directory_path() / "rcal_no_such.lcmlog"), std::runtime_error);
}

TEST(LcmLog, AFlippedLengthBitLosesThatEventOnly) {
  std::vector<uint8_t> b = WriteLog();
  // Event 3's data length 41 + 256: it runs over event 4 (liblcm resumes at a later sync word).
  b[static_cast<size_t>(OffsetOf(3) + kDataLenAt + 2)] ^= 0x01;
  LcmLogReader r(b);
  EXPECT_EQ(ReadAll(r), Except({3}));
  EXPECT_EQ(r.stats().broken_frames, 1);
  EXPECT_EQ(r.stats().bytes_unreadable, FrameBytes(3));
  EXPECT_TRUE(r.stats().lost());
  ASSERT_FALSE(r.stats().reasons.empty());
  EXPECT_NE(r.stats().reasons[0].find("offset " + std::to_string(OffsetOf(4))), std::string::npos)
      << r.stats().reasons[0];

  // The top bit: negative.
  b = WriteLog();
  b[static_cast<size_t>(OffsetOf(6) + kDataLenAt)] ^= 0x80;
  LcmLogReader neg(b);
  EXPECT_EQ(ReadAll(neg), Except({6}));
  EXPECT_EQ(neg.stats().bytes_unreadable, FrameBytes(6));

  // A bit that shortens it (41 -> 33): the event comes back short (its decode will refuse it),
  // its last 8 bytes are unreadable.
  b = WriteLog();
  b[static_cast<size_t>(OffsetOf(3) + kDataLenAt + 3)] ^= 0x08;
  LcmLogReader shorter(b);
  EXPECT_EQ(ReadAll(shorter), (std::vector<int>{0, 1, 2, 103, 4, 5, 6, 7, 8, 9}));
  EXPECT_EQ(shorter.stats().broken_frames, 1);
  EXPECT_EQ(shorter.stats().bytes_unreadable, 8);
}

TEST(LcmLog, DataLength0x7fffffffLosesThatEventOnly) {
  std::vector<uint8_t> b = WriteLog();
  PutBe32(b, OffsetOf(5) + kDataLenAt, 0x7fffffffu);
  LcmLogReader r(b);
  EXPECT_EQ(ReadAll(r), Except({5}));
  EXPECT_EQ(r.stats().broken_frames, 1);
  EXPECT_EQ(r.stats().bytes_unreadable, FrameBytes(5));
  // The same in the last event: nothing follows to resynchronise on.
  b = WriteLog();
  PutBe32(b, OffsetOf(9) + kDataLenAt, 0x7fffffffu);
  LcmLogReader last(b);
  EXPECT_EQ(ReadAll(last), Except({9}));
  EXPECT_EQ(last.stats().bytes_unreadable, FrameBytes(9));
  // A channel length of 0, and of 2^31 − 1.
  b = WriteLog();
  PutBe32(b, OffsetOf(2) + 20, 0);
  PutBe32(b, OffsetOf(7) + 20, 0x7fffffffu);
  LcmLogReader ch(b);
  EXPECT_EQ(ReadAll(ch), Except({2, 7}));
  EXPECT_EQ(ch.stats().broken_frames, 2);
  EXPECT_EQ(ch.stats().bytes_unreadable, FrameBytes(2) + FrameBytes(7));
}

TEST(LcmLog, ACutTailIsCountedAsUnreadable) {
  const std::vector<uint8_t> full = WriteLog();
  for (int64_t cut : {int64_t{1}, int64_t{10}, FrameBytes(9) - 1}) {
    const std::vector<uint8_t> b(full.begin(), full.end() - cut);
    LcmLogReader r(b);
    EXPECT_EQ(ReadAll(r), Except({9})) << cut;
    EXPECT_EQ(r.stats().broken_frames, 1) << cut;
    EXPECT_EQ(r.stats().bytes_unreadable, FrameBytes(9) - cut) << cut;
  }
  // Nothing, and less than a sync word.
  LcmLogReader empty(std::vector<uint8_t>{});
  EXPECT_FALSE(empty.Next().has_value());
  EXPECT_FALSE(empty.stats().lost());
  LcmLogReader three(std::vector<uint8_t>(full.begin(), full.begin() + 3));
  EXPECT_FALSE(three.Next().has_value());
  EXPECT_EQ(three.stats().bytes_unreadable, 3);
}

TEST(LcmLog, GarbageBetweenEventsIsSkippedAndEveryEventKept) {
  const std::vector<uint8_t> full = WriteLog();
  std::vector<uint8_t> b(full.begin(), full.begin() + OffsetOf(4));
  // 100 bytes of noise, then a sync word with nonsense lengths, then more noise.
  for (int k = 0; k < 100; ++k) b.push_back(static_cast<uint8_t>(k * 37 + 11));
  for (uint8_t c : {0xED, 0xA1, 0xDA, 0x01}) b.push_back(c);
  for (int k = 0; k < 30; ++k) b.push_back(0xFF);
  const int64_t garbage = 100 + 4 + 30;
  b.insert(b.end(), full.begin() + OffsetOf(4), full.end());
  LcmLogReader r(b);
  std::vector<int> got;
  while (auto e = r.Next()) got.push_back(e->data[0]);
  EXPECT_EQ(got, Except({}));
  EXPECT_EQ(r.stats().bytes_unreadable, garbage);
  EXPECT_EQ(r.stats().broken_frames, 2);  // the noise, then the false sync word
  // Garbage before the first event too.
  std::vector<uint8_t> lead = {1, 2, 3};
  lead.insert(lead.end(), full.begin(), full.end());
  LcmLogReader l(lead);
  EXPECT_EQ(ReadAll(l, 3), Except({}));
  EXPECT_EQ(l.stats().bytes_unreadable, 3);
}

TEST(LcmLog, SkippedEventsAreCountedWithTheirReason) {
  LcmLogReader r(WriteLog());
  while (auto e = r.Next())
    if (e->data[0] % 3 == 0) r.Skip(*e, "refused");
  EXPECT_EQ(r.stats().events_read, kEvents);
  EXPECT_EQ(r.stats().events_skipped, 4);  // 0, 3, 6, 9
  EXPECT_TRUE(r.stats().lost());
  ASSERT_EQ(r.stats().reasons.size(), 4u);
  EXPECT_EQ(r.stats().reasons[1],
            "event 3 (CHANNEL_B, offset " + std::to_string(OffsetOf(3)) + "): refused");
}

}  // namespace
}  // namespace rcal::io
