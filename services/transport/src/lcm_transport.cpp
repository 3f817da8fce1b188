#include "rcal/transport/lcm_transport.hpp"

#include <dirent.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <cstdlib>
#include <set>
#include <stdexcept>

namespace rcal::transport {

std::string ResolveLcmUrl(const std::string& url) {
  if (!url.empty()) return url;
  if (const char* env = std::getenv("RCAL_LCM_URL"); env != nullptr && env[0] != '\0') return env;
  return kDefaultLcmUrl;
}

LcmTransport::LcmTransport(const std::string& url, int queue_capacity)
    : url_(ResolveLcmUrl(url)), queue_capacity_(queue_capacity), lcm_(url_) {
  if (!lcm_.good()) throw std::runtime_error("LCM could not start on " + url_);
}

LcmTransport::~LcmTransport() = default;

bool LcmTransport::PublishRaw(const std::string& channel, const void* data, int size) {
  return lcm_.publish(channel, data, static_cast<unsigned int>(size)) == 0;
}

namespace {

/// The process's open UDP sockets bound to a port (LCM's receive socket is bound to the group's
/// port; its send socket is not bound).
std::set<int> BoundUdpFds() {
  std::set<int> fds;
  DIR* dir = opendir("/proc/self/fd");
  if (dir == nullptr) return fds;
  while (const dirent* e = readdir(dir)) {
    char* end = nullptr;
    const int fd = static_cast<int>(std::strtol(e->d_name, &end, 10));
    if (end == e->d_name || *end != '\0') continue;
    int type = 0;
    socklen_t len = sizeof type;
    if (getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &len) != 0 || type != SOCK_DGRAM) continue;
    sockaddr_in addr{};
    len = sizeof addr;
    if (getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0 &&
        addr.sin_family == AF_INET && addr.sin_port != 0)
      fds.insert(fd);
  }
  closedir(dir);
  return fds;
}

}  // namespace

void LcmTransport::SubscribeRaw(const std::string& channel, RawHandler handler) {
  // udpm opens its receive socket at the first subscription: the bound UDP socket that appears
  // then is this transport's (what Dropped() reads).
  const bool first = slots_.empty() && url_.rfind("udpm://", 0) == 0;
  const std::set<int> before = first ? BoundUdpFds() : std::set<int>{};
  slots_.push_back(std::make_unique<Slot>(Slot{std::move(handler)}));
  lcm::Subscription* sub = lcm_.subscribe(channel, &Slot::Handle, slots_.back().get());
  if (sub != nullptr) sub->setQueueCapacity(queue_capacity_);
  if (first)
    for (const int fd : BoundUdpFds())
      if (!before.count(fd)) recv_fd_ = fd;
}

int64_t LcmTransport::Dropped() const {
  if (recv_fd_ < 0) return 0;
  std::uint32_t info[SK_MEMINFO_VARS] = {};
  socklen_t len = sizeof info;
  if (getsockopt(recv_fd_, SOL_SOCKET, SO_MEMINFO, info, &len) != 0 ||
      len < static_cast<socklen_t>((SK_MEMINFO_DROPS + 1) * sizeof(std::uint32_t)))
    return 0;
  return info[SK_MEMINFO_DROPS];
}

int LcmTransport::HandleTimeout(int timeout_ms) {
  return lcm_.handleTimeout(timeout_ms);
}

}  // namespace rcal::transport
