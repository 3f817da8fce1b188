// What every rcal benchmark main shares: medians of 5 repetitions unless the caller chose
// (--benchmark_repetitions=N), and a console reporter that also keeps each benchmark's median
// (or single-run) real time in nanoseconds for the summary table a main prints after the run.
#pragma once

#include <benchmark/benchmark.h>

#include <map>
#include <string>
#include <vector>

namespace rcal::bench {

/// benchmark::Initialize with 5 repetitions and aggregates only unless the command line sets
/// --benchmark_repetitions. Returns false when an argument is not understood (already reported).
inline bool InitializeWithMedians(int argc, char** argv) {
  static std::vector<char*> args;
  static std::string reps = "--benchmark_repetitions=5";
  static std::string only = "--benchmark_report_aggregates_only=true";
  args.assign(argv, argv + argc);
  bool chose_repetitions = false;
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]).rfind("--benchmark_repetitions", 0) == 0) chose_repetitions = true;
  if (!chose_repetitions) {
    args.push_back(reps.data());
    args.push_back(only.data());
  }
  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  return !benchmark::ReportUnrecognizedArguments(n, args.data());
}

/// Console output as usual, plus the median real time of each benchmark [ns].
class TableReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& reports) override {
    ConsoleReporter::ReportRuns(reports);
    for (const Run& r : reports) {
      if (r.error_occurred) continue;
      const std::string name = r.run_name.function_name;
      const double ns = r.GetAdjustedRealTime() * ToNs(r.time_unit);
      if (r.run_type == Run::RT_Aggregate && r.aggregate_name == "median")
        median_[name] = ns;
      else if (r.run_type == Run::RT_Iteration)
        single_[name] = ns;
    }
  }
  /// Median (else single-run) real time of `name` [ns]; −1 when it did not run.
  double Ns(const std::string& name) const {
    if (auto it = median_.find(name); it != median_.end()) return it->second;
    if (auto it = single_.find(name); it != single_.end()) return it->second;
    return -1.0;
  }
  bool has_medians() const { return !median_.empty(); }

 private:
  static double ToNs(benchmark::TimeUnit u) {
    switch (u) {
      case benchmark::kSecond:
        return 1e9;
      case benchmark::kMillisecond:
        return 1e6;
      case benchmark::kMicrosecond:
        return 1e3;
      default:
        return 1.0;
    }
  }
  std::map<std::string, double> median_, single_;
};

}  // namespace rcal::bench
