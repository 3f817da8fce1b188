// rcal: offline work on the library (simulate, calibrate, analyze, report).
#include <spdlog/sinks/base_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <iostream>
#include <memory>
#include <mutex>
#include <utility>

#include <CLI/CLI.hpp>

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

namespace {

/// Passes messages below warning to `inner` (stdout, with the figures); warnings and errors go to
/// stderr, where a user (and a script) looks for why a command failed.
class BelowWarningSink : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit BelowWarningSink(std::shared_ptr<spdlog::sinks::sink> inner)
      : inner_(std::move(inner)) {}

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    if (msg.level < spdlog::level::warn) inner_->log(msg);
  }
  void flush_() override { inner_->flush(); }

 private:
  std::shared_ptr<spdlog::sinks::sink> inner_;
};

void LogWarningsToStderr() {
  auto err = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  err->set_level(spdlog::level::warn);
  auto out =
      std::make_shared<BelowWarningSink>(std::make_shared<spdlog::sinks::stdout_color_sink_mt>());
  auto logger = std::make_shared<spdlog::logger>("", spdlog::sinks_init_list{out, err});
  logger->set_level(spdlog::default_logger()->level());
  spdlog::set_default_logger(logger);
}

}  // namespace

}  // namespace rcal::tool

int main(int argc, char** argv) {
  using namespace rcal::tool;
  LogWarningsToStderr();
  CLI::App app{"rcal: online robot calibration with an IMU and a position sensor"};
  app.require_subcommand(1);
  auto& entries = Registry();
  std::sort(entries.begin(), entries.end(),
            [](const CommandEntry& a, const CommandEntry& b) { return a.name < b.name; });
  // Each command's Args outlives the parse (its subcommands live in it).
  std::vector<std::unique_ptr<Args>> args;
  std::vector<std::pair<CLI::App*, std::function<int()>>> runners;
  for (const auto& e : entries) {
    CLI::App* sub = app.add_subcommand(e.name, e.description);
    args.push_back(std::make_unique<Args>(*sub));
    runners.emplace_back(sub, e.setup(*args.back()));
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
