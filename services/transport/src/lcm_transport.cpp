#include "rcal/transport/lcm_transport.hpp"

#include <cstdlib>
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

void LcmTransport::SubscribeRaw(const std::string& channel, RawHandler handler) {
  slots_.push_back(std::make_unique<Slot>(Slot{std::move(handler)}));
  lcm::Subscription* sub = lcm_.subscribe(channel, &Slot::Handle, slots_.back().get());
  if (sub != nullptr) sub->setQueueCapacity(queue_capacity_);
}

int LcmTransport::HandleTimeout(int timeout_ms) {
  return lcm_.handleTimeout(timeout_ms);
}

}  // namespace rcal::transport
