// Helpers of the DDS process tests: the integration tests' process and namespace helpers
// (tests/integration/netns.hpp: Spawn, Wait, RCAL_IN_NAMESPACE), under the DDS tests' names.
#pragma once

#include "../integration/netns.hpp"

namespace rcal::dds::testing {

namespace fs = std::filesystem;

using integration::Spawn;
using integration::Wait;

/// True while `pid` (a child) has not exited.
inline bool Alive(pid_t pid) {
  return integration::Running(pid);
}

}  // namespace rcal::dds::testing
