// A DDS reader inside a test process: how a test sees what a process published on DDS.
#pragma once

#include <dds/dds.h>
#include <gtest/gtest.h>

#include <functional>

#include "rcal/dds/convert.hpp"

namespace rcal::dds::testing {

template <typename T>
class Reader {
 public:
  /// Takes ownership of `qos` (deleted here).
  Reader(dds_entity_t participant, const char* topic, dds_qos_t* qos) {
    const dds_entity_t t = dds_create_topic(participant, Descriptor<T>(), topic, qos, nullptr);
    reader_ = dds_create_reader(participant, t, qos, nullptr);
    dds_delete_qos(qos);
    EXPECT_GT(reader_, 0) << topic;
  }
  /// Takes every available sample; calls `f` on each valid one.
  void Take(const std::function<void(const T&)>& f) {
    for (;;) {
      void* samples[1] = {nullptr};
      dds_sample_info_t info;
      const int n = dds_take(reader_, samples, &info, 1, 1);
      if (n <= 0) return;
      if (info.valid_data) f(*static_cast<const T*>(samples[0]));
      dds_return_loan(reader_, samples, n);
    }
  }

 private:
  dds_entity_t reader_ = 0;
};

}  // namespace rcal::dds::testing
