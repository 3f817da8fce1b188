// Typed publish/subscribe behind an abstract interface (after Drake's DrakeLcmInterface), so a
// process's adapter code is written once and runs over UDP multicast, memq:// in tests, or a log.
//
// Messages are LCM-generated types (anything with encode/decode/getEncodedSize). A message that
// fails to decode (truncated, wrong type: the LCM fingerprint differs) never reaches the typed
// handler: the error handler gets a reason naming the channel, and the process goes on. Before
// the generated decoder runs, the bytes are walked by the type's schema (lcm_schema.hpp): a length
// field that is negative, beyond the bytes present or beyond a sane limit is refused there, with a
// reason naming the channel, the type and the field (LCM 1.3.1's decoders allocate from such a
// field before checking it: 2 GB from a 422-byte message, then read past the buffer).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "rcal/transport/lcm_schema.hpp"

namespace rcal::transport {

/// Raw handler: channel, encoded bytes.
using RawHandler = std::function<void(const std::string& channel, const void* data, int size)>;
/// Called when a message on a subscribed channel cannot be decoded; `reason` names the channel.
using ErrorHandler = std::function<void(const std::string& reason)>;

class Transport {
 public:
  virtual ~Transport() = default;

  /// Publishes encoded bytes on `channel`. Returns false when the transport refused them.
  virtual bool PublishRaw(const std::string& channel, const void* data, int size) = 0;
  /// Calls `handler` for every message whose channel matches the regular expression `channel`
  /// (LCM semantics: the whole name must match; ".*" is every channel).
  virtual void SubscribeRaw(const std::string& channel, RawHandler handler) = 0;
  /// Waits up to `timeout_ms` for one message and dispatches it. Returns 1 when one was handled,
  /// 0 on timeout, negative on a transport error.
  virtual int HandleTimeout(int timeout_ms) = 0;
  /// Messages lost below the process since it started, as far as the transport can tell (over
  /// udpm://: datagrams the kernel dropped at the receive socket because its buffer was full);
  /// 0 where nothing can be lost or nothing can be told.
  virtual int64_t Dropped() const { return 0; }

  /// Encodes and publishes a typed message. Returns false on an encoding or transport failure.
  template <typename Msg>
  bool Publish(const std::string& channel, const Msg& msg) {
    const int size = msg.getEncodedSize();
    if (size < 0) return false;
    std::vector<uint8_t> buffer(static_cast<size_t>(size));
    if (msg.encode(buffer.data(), 0, size) != size) return false;
    return PublishRaw(channel, buffer.data(), size);
  }

  /// Subscribes a typed handler. Bytes that do not decode as `Msg`, or that CheckLcmMessage
  /// refuses, go to `on_error` (if given) with a reason naming the channel and the type (and the
  /// field at fault); `on_message` is not called. `Msg` must be a type of lcmtypes/.
  template <typename Msg>
  void Subscribe(const std::string& channel, std::function<void(const Msg&)> on_message,
                 ErrorHandler on_error = {}) {
    SubscribeRaw(channel, [on_message = std::move(on_message), on_error = std::move(on_error)](
                              const std::string& ch, const void* data, int size) {
      Msg msg;
      // Bounds first (DecodeLcm): the generated decoder allocates from length fields unchecked.
      const std::string refused = size < 0 ? std::string(Msg::getTypeName()) + ": negative size"
                                           : DecodeLcm(data, static_cast<size_t>(size), &msg);
      if (!refused.empty()) {
        if (on_error) on_error("channel " + ch + ": " + refused);
        return;
      }
      on_message(msg);
    });
  }
};

}  // namespace rcal::transport
