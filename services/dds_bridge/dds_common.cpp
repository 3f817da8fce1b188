// Topic QoS and Cyclone configuration selection (see include/rcal/dds/dds_common.hpp).
#include "rcal/dds/dds_common.hpp"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace rcal::dds {

dds_qos_t* LatchedQos() {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
  return q;
}

dds_qos_t* StreamQos() {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 1);
  return q;
}

std::string LoopbackConfigUri() {
  namespace fs = std::filesystem;
  const fs::path relative = "config/cyclonedds-loopback.xml";
  fs::path p = fs::exists(relative) ? relative : fs::path(RCAL_SOURCE_DIR) / relative;
  if (!fs::exists(p))
    throw std::runtime_error("Cyclone DDS loopback configuration " + p.string() +
                             " not found (set CYCLONEDDS_URI to choose one)");
  return "file://" + fs::absolute(p).lexically_normal().string();
}

std::string EnsureCycloneConfig() {
  const char* uri = std::getenv("CYCLONEDDS_URI");
  if (uri && *uri) return uri;
  const std::string loopback = LoopbackConfigUri();
  setenv("CYCLONEDDS_URI", loopback.c_str(), 1);
  return loopback;
}

}  // namespace rcal::dds
