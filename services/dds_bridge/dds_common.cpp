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

dds_qos_t* SensorDataQos(int depth) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

dds_qos_t* StreamQos() {
  return SensorDataQos(1);
}

dds_entity_t CreateEndpoint(dds_entity_t participant, const dds_topic_descriptor_t* desc,
                            const std::string& topic_name, const dds_qos_t* qos, bool writer) {
  const dds_entity_t topic = dds_create_topic(participant, desc, topic_name.c_str(), qos, nullptr);
  if (topic < 0)
    throw std::runtime_error("dds_create_topic " + topic_name + ": " + dds_strretcode(topic));
  const dds_entity_t e = writer ? dds_create_writer(participant, topic, qos, nullptr)
                                : dds_create_reader(participant, topic, qos, nullptr);
  if (e < 0)
    throw std::runtime_error(std::string(writer ? "dds_create_writer " : "dds_create_reader ") +
                             topic_name + ": " + dds_strretcode(e));
  return e;
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
