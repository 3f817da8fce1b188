// The Transport over LCM (udpm:// multicast on the machine, memq:// inside one process).
#pragma once

#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <string>
#include <vector>

#include "rcal/transport/transport.hpp"

namespace rcal::transport {

/// The pipeline's default: multicast that never leaves the machine (ttl=0).
inline constexpr const char* kDefaultLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

/// Messages LCM may hold per subscription between two HandleTimeout calls. LCM's own default is
/// 30 and it drops the rest silently: at the fast replays' 2 kHz per sensor channel that is 15 ms
/// of a process not being scheduled (a loaded machine), and one lost IMU or JOINTS sample changes
/// a still window. 5000 holds 2.5 s at 2 kHz (LCM grows its receive buffers as needed; a few MB
/// at most). A subscriber of every channel (the logger) needs more: kAllChannelsQueueCapacity.
inline constexpr int kDefaultQueueCapacity = 5000;
/// For one subscription to every channel (~6.5 kHz in the fast replays): 15 s of them.
inline constexpr int kAllChannelsQueueCapacity = 100000;

/// The LCM URL to use: `url` if not empty, else the environment variable RCAL_LCM_URL if set and
/// not empty, else kDefaultLcmUrl.
std::string ResolveLcmUrl(const std::string& url = "");

class LcmTransport final : public Transport {
 public:
  /// Opens LCM on ResolveLcmUrl(url). Throws std::runtime_error naming the URL if LCM cannot
  /// start (e.g. no multicast route).
  /// `queue_capacity`: kDefaultQueueCapacity unless a test needs LCM's own behaviour.
  explicit LcmTransport(const std::string& url = "", int queue_capacity = kDefaultQueueCapacity);
  ~LcmTransport() override;
  LcmTransport(const LcmTransport&) = delete;
  LcmTransport& operator=(const LcmTransport&) = delete;

  bool PublishRaw(const std::string& channel, const void* data, int size) override;
  void SubscribeRaw(const std::string& channel, RawHandler handler) override;
  int HandleTimeout(int timeout_ms) override;
  /// Datagrams the kernel dropped at this transport's receive socket (its SO_MEMINFO drop
  /// count; Linux). LCM opens that socket at the first subscription; before, and for memq://,
  /// 0. Messages LCM itself drops from a full subscription queue (queue_capacity) cannot be
  /// told: LCM 1.3.1 counts them nowhere.
  int64_t Dropped() const override;
  /// The receive socket's file descriptor, or -1 (not subscribed yet, or not udpm://).
  int receive_socket() const { return recv_fd_; }

  const std::string& url() const { return url_; }
  /// The underlying LCM instance (for lcm::LogFile-free helpers such as getFileno()).
  lcm::LCM& lcm() { return lcm_; }

 private:
  struct Slot {
    RawHandler handler;
    void Handle(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      handler(channel, rbuf->data, static_cast<int>(rbuf->data_size));
    }
  };
  std::string url_;
  int queue_capacity_;
  lcm::LCM lcm_;
  std::vector<std::unique_ptr<Slot>> slots_;
  int recv_fd_ = -1;
};

}  // namespace rcal::transport
