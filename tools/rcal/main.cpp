// rcal: offline work on the library (simulate, calibrate, analyze, report).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <iostream>

#include "command.hpp"

namespace rcal::tool {

std::vector<CommandEntry>& Registry() {
  static std::vector<CommandEntry> entries;
  return entries;
}

std::string ResolvePath(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty() || fs::exists(path)) return path;
  const fs::path in_repo = fs::path(RCAL_SOURCE_DIR) / path;
  if (fs::exists(in_repo)) return in_repo.string();
  return path;
}

}  // namespace rcal::tool

int main(int argc, char** argv) {
  using namespace rcal::tool;
  CLI::App app{"rcal: online robot calibration with an IMU and a position sensor"};
  app.require_subcommand(1);
  auto& entries = Registry();
  std::sort(entries.begin(), entries.end(),
            [](const CommandEntry& a, const CommandEntry& b) { return a.name < b.name; });
  std::vector<std::pair<CLI::App*, std::function<int()>>> runners;
  for (const auto& e : entries) {
    CLI::App* sub = app.add_subcommand(e.name, e.description);
    runners.emplace_back(sub, e.setup(*sub));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    for (auto& [sub, run] : runners)
      if (sub->parsed()) return run();
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
