// A reader of LCM event logs (what lcm-logger and rcal's logger write) that survives damaged
// files and says what it lost. Pure C++: it returns raw events; decoding is the caller's.
//
// The format (LCM's eventlog.c): events back to back, each
//   sync word 0xEDA1DA01 (u32) | event number (i64) | timestamp [µs] (i64) |
//   channel length (i32) | data length (i32) | channel bytes | data bytes,   all big-endian.
//
// Why our own: liblcm 1.3.1's lcm::LogFile trusts the lengths. A data length of 0x7fffffff makes it
// calloc(datalen + 1) = calloc(negative), then read into NULL (SIGSEGV); one flipped bit in a
// length makes it swallow the following events as data and resume at some later sync word,
// silently (10 of 50 poses read, exit 0).
//
// This reader accepts a frame only when its lengths are plausible (channel 1..max bytes of
// printable ASCII, data within the limit and the bytes left in the file) and the frame is followed
// by the next sync word or the end of the file. A frame whose lengths run over the start of a
// plausible next frame is broken: the reader resynchronises there. Bytes between frames are
// skipped up to the next sync word. Everything skipped is counted (LcmLogStats).
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace rcal::io {

/// The sync word that starts every event.
inline constexpr uint32_t kLcmLogSync = 0xEDA1DA01u;
/// Bytes of an event's header: sync, event number, timestamp, channel length, data length.
inline constexpr int64_t kLcmLogHeaderBytes = 28;

struct LcmLogLimits {
  int64_t max_channel_bytes = 256;     ///< LCM's own channel names are at most 63 bytes
  int64_t max_event_bytes = 64 << 20;  ///< rcal's messages are a few kB; LCM's at most ~64 MB
};

/// One event as logged.
struct LcmLogEvent {
  int64_t event_number = 0;  ///< as written (lcm-logger: 0, 1, 2, ...)
  int64_t timestamp_us = 0;  ///< receive time the logger wrote [µs]
  std::string channel;
  std::vector<uint8_t> data;
  int64_t offset = 0;  ///< of its sync word in the file [bytes]
};

/// What a read of a log met.
struct LcmLogStats {
  int64_t events_read = 0;       ///< intact frames returned by Next()
  int64_t events_skipped = 0;    ///< intact frames the caller refused (Skip): undecodable, invalid
  int64_t broken_frames = 0;     ///< places where the reader lost the frame and resynchronised
  int64_t bytes_unreadable = 0;  ///< bytes in no intact frame (broken frames, garbage, a cut tail)
  std::vector<std::string> reasons;  ///< the first kMaxReasons skips and breaks, with offsets
  static constexpr size_t kMaxReasons = 5;

  /// True when anything was lost: a skipped event, a broken frame or an unreadable byte.
  bool lost() const { return events_skipped > 0 || broken_frames > 0 || bytes_unreadable > 0; }
  /// One line: "events read 50, skipped 1, broken frames 1, bytes unreadable 89".
  std::string Summary() const;
  /// Adds a reason if fewer than kMaxReasons are kept.
  void Note(const std::string& reason);
};

class LcmLogReader {
 public:
  /// Opens a log file. Throws std::runtime_error naming the file when it cannot be opened.
  explicit LcmLogReader(const std::filesystem::path& path, LcmLogLimits limits = {});
  /// Reads a log held in memory (fuzzing, tests).
  explicit LcmLogReader(std::vector<uint8_t> bytes, LcmLogLimits limits = {});
  ~LcmLogReader();
  LcmLogReader(const LcmLogReader&) = delete;
  LcmLogReader& operator=(const LcmLogReader&) = delete;

  /// The next intact event, or nullopt at the end of the log. Never throws on damaged content;
  /// throws std::runtime_error naming the file on an I/O error.
  std::optional<LcmLogEvent> Next();
  /// The caller refuses the event Next() returned last (counted in events_skipped, with `reason`).
  void Skip(const LcmLogEvent& event, const std::string& reason);

  const LcmLogStats& stats() const { return stats_; }
  const std::string& name() const { return name_; }

 private:
  struct Header {
    int64_t event_number, timestamp_us, channel_bytes, data_bytes;
  };
  bool Read(int64_t offset, int64_t n, void* out);
  bool SyncAt(int64_t offset);
  std::optional<Header> ReadHeader(int64_t offset);
  std::string Implausible(int64_t offset, const Header& h);
  int64_t FindSync(int64_t from, int64_t to);
  void Lose(int64_t from, int64_t to, const std::string& why);

  std::string name_;
  LcmLogLimits limits_;
  std::vector<uint8_t> memory_;
  std::unique_ptr<std::ifstream> file_;
  int64_t size_ = 0;
  int64_t pos_ = 0;
  LcmLogStats stats_;
};

/// True when the file starts with the sync word of an LCM event log.
bool IsLcmLogFile(const std::filesystem::path& path);

}  // namespace rcal::io
