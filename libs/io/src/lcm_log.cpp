#include "rcal/io/lcm_log.hpp"

#include <algorithm>
#include <array>
#include <stdexcept>

namespace rcal::io {
namespace {

uint64_t Big(const uint8_t* p, int n) {
  uint64_t v = 0;
  for (int k = 0; k < n; ++k) v = (v << 8) | p[k];
  return v;
}

constexpr int64_t kScanChunk = 1 << 16;

}  // namespace

std::string LcmLogStats::Summary() const {
  return "events read " + std::to_string(events_read) + ", skipped " +
         std::to_string(events_skipped) + ", broken frames " + std::to_string(broken_frames) +
         ", bytes unreadable " + std::to_string(bytes_unreadable);
}

void LcmLogStats::Note(const std::string& reason) {
  if (reasons.size() < kMaxReasons) reasons.push_back(reason);
}

LcmLogReader::LcmLogReader(const std::filesystem::path& path, LcmLogLimits limits)
    : name_(path.string()), limits_(limits) {
  file_ = std::make_unique<std::ifstream>(path, std::ios::binary);
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (!*file_ || ec) throw std::runtime_error(name_ + ": cannot read the LCM log");
  size_ = static_cast<int64_t>(size);
}

LcmLogReader::LcmLogReader(std::vector<uint8_t> bytes, LcmLogLimits limits)
    : name_("(memory)"), limits_(limits), memory_(std::move(bytes)) {
  size_ = static_cast<int64_t>(memory_.size());
}

LcmLogReader::~LcmLogReader() = default;

bool LcmLogReader::Read(int64_t offset, int64_t n, void* out) {
  if (offset < 0 || n < 0 || n > size_ - offset) return false;
  if (n == 0) return true;
  if (!file_) {
    std::copy_n(memory_.begin() + offset, n, static_cast<uint8_t*>(out));
    return true;
  }
  file_->clear();
  file_->seekg(offset);
  if (!file_->read(static_cast<char*>(out), n))
    throw std::runtime_error(name_ + ": read error at offset " + std::to_string(offset));
  return true;
}

bool LcmLogReader::SyncAt(int64_t offset) {
  std::array<uint8_t, 4> b{};
  return Read(offset, 4, b.data()) && Big(b.data(), 4) == kLcmLogSync;
}

std::optional<LcmLogReader::Header> LcmLogReader::ReadHeader(int64_t offset) {
  std::array<uint8_t, kLcmLogHeaderBytes> b{};
  if (!Read(offset, kLcmLogHeaderBytes, b.data()) || Big(b.data(), 4) != kLcmLogSync)
    return std::nullopt;
  Header h{};
  h.event_number = static_cast<int64_t>(Big(b.data() + 4, 8));
  h.timestamp_us = static_cast<int64_t>(Big(b.data() + 12, 8));
  // Sign-extended: a negative length is as implausible as a huge one.
  h.channel_bytes = static_cast<int32_t>(static_cast<uint32_t>(Big(b.data() + 20, 4)));
  h.data_bytes = static_cast<int32_t>(static_cast<uint32_t>(Big(b.data() + 24, 4)));
  return h;
}

// "" when the frame at `offset` with header `h` could be an event: lengths within the limits and
// the file, the channel printable ASCII. Else why not.
std::string LcmLogReader::Implausible(int64_t offset, const Header& h) {
  const int64_t left = size_ - offset - kLcmLogHeaderBytes;
  if (h.channel_bytes < 1 || h.channel_bytes > limits_.max_channel_bytes)
    return "channel length " + std::to_string(h.channel_bytes) + " outside 1.." +
           std::to_string(limits_.max_channel_bytes);
  if (h.data_bytes < 0 || h.data_bytes > limits_.max_event_bytes)
    return "data length " + std::to_string(h.data_bytes) + " outside 0.." +
           std::to_string(limits_.max_event_bytes);
  if (h.channel_bytes + h.data_bytes > left)
    return "channel and data lengths " + std::to_string(h.channel_bytes) + " + " +
           std::to_string(h.data_bytes) + " exceed the " + std::to_string(left) +
           " bytes left in the file";
  std::string channel(static_cast<size_t>(h.channel_bytes), '\0');
  Read(offset + kLcmLogHeaderBytes, h.channel_bytes, channel.data());
  for (char c : channel)
    if (c < 0x20 || c > 0x7e) return "channel name is not printable ASCII";
  return {};
}

// The offset of the first sync word in [from, to), or `to`.
int64_t LcmLogReader::FindSync(int64_t from, int64_t to) {
  to = std::min(to, size_);
  std::vector<uint8_t> chunk;
  for (int64_t at = from; at + 4 <= to;) {
    const int64_t n = std::min(kScanChunk + 3, size_ - at);
    chunk.resize(static_cast<size_t>(n));
    Read(at, n, chunk.data());
    for (int64_t k = 0; k + 4 <= n && at + k < to; ++k)
      if (Big(chunk.data() + k, 4) == kLcmLogSync) return at + k;
    at += kScanChunk;
  }
  return to;
}

void LcmLogReader::Lose(int64_t from, int64_t to, const std::string& why) {
  ++stats_.broken_frames;
  stats_.bytes_unreadable += to - from;
  stats_.Note("offset " + std::to_string(from) + ": " + why + " (" + std::to_string(to - from) +
              " bytes unreadable)");
}

std::optional<LcmLogEvent> LcmLogReader::Next() {
  while (pos_ < size_) {
    if (!SyncAt(pos_)) {
      const int64_t next = FindSync(pos_ + 1, size_);
      Lose(pos_, next, "no event starts here");
      pos_ = next;
      continue;
    }
    const std::optional<Header> h = ReadHeader(pos_);
    if (!h) {
      Lose(pos_, size_, "event header cut short by the end of the file");
      pos_ = size_;
      break;
    }
    if (const std::string why = Implausible(pos_, *h); !why.empty()) {
      const int64_t next = FindSync(pos_ + 1, size_);
      Lose(pos_, next, "broken event: " + why);
      pos_ = next;
      continue;
    }
    const int64_t end = pos_ + kLcmLogHeaderBytes + h->channel_bytes + h->data_bytes;
    if (end != size_ && !SyncAt(end)) {
      // Not followed by an event: either this frame's length is wrong (it runs over the next
      // event, which then starts inside it) or bytes follow that are no event. Only a plausible
      // frame inside tells the first; then resynchronise there.
      bool resynced = false;
      for (int64_t at = FindSync(pos_ + 1, end); at < end; at = FindSync(at + 1, end)) {
        const std::optional<Header> inner = ReadHeader(at);
        if (inner && Implausible(at, *inner).empty()) {
          Lose(pos_, at,
               "broken event: its length runs over the event at offset " + std::to_string(at));
          pos_ = at;
          resynced = true;
          break;
        }
      }
      if (resynced) continue;
    }
    LcmLogEvent e;
    e.offset = pos_;
    e.event_number = h->event_number;
    e.timestamp_us = h->timestamp_us;
    e.channel.resize(static_cast<size_t>(h->channel_bytes));
    Read(pos_ + kLcmLogHeaderBytes, h->channel_bytes, e.channel.data());
    e.data.resize(static_cast<size_t>(h->data_bytes));
    Read(pos_ + kLcmLogHeaderBytes + h->channel_bytes, h->data_bytes, e.data.data());
    pos_ = end;
    ++stats_.events_read;
    return e;
  }
  return std::nullopt;
}

void LcmLogReader::Skip(const LcmLogEvent& event, const std::string& reason) {
  ++stats_.events_skipped;
  stats_.Note("event " + std::to_string(event.event_number) + " (" + event.channel + ", offset " +
              std::to_string(event.offset) + "): " + reason);
}

bool IsLcmLogFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<uint8_t, 4> b{};
  if (!in.read(reinterpret_cast<char*>(b.data()), b.size())) return false;
  return Big(b.data(), 4) == kLcmLogSync;
}

}  // namespace rcal::io
