// Runs independent, separately seeded tasks on worker threads. The figures of a sweep never
// depend on the number of threads: each task writes only its own slot of the results, which are
// reported in their fixed order afterwards.
#pragma once

#include <atomic>
#include <future>
#include <vector>

namespace rcal::tool {

/// Runs f(i) for every i in [0, n) on `jobs` threads (the calling one included); an exception
/// thrown by a task reaches the caller once every thread has stopped.
template <class F>
void Parallel(int n, int jobs, F f) {
  std::atomic<int> next{0};
  const auto worker = [&] {
    for (int i = next++; i < n; i = next++) f(i);
  };
  std::vector<std::future<void>> pool;
  for (int k = 1; k < jobs; ++k) pool.push_back(std::async(std::launch::async, worker));
  worker();
  for (auto& p : pool) p.get();
}

}  // namespace rcal::tool
