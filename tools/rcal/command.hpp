// The `rcal` command line: each subcommand lives in its own cmd_NAME.cpp and registers itself
// with a static RCAL_COMMAND object, so adding a command touches no other file.
#pragma once

#include <functional>
#include <string>
#include <vector>
#include "cli.hpp"

namespace rcal::tool {

/// Adds options to `sub` and returns the function that runs the command (its exit code).
using CommandSetup = std::function<std::function<int()>(Args& sub)>;

struct CommandEntry {
  std::string name;
  std::string description;
  CommandSetup setup;
};

std::vector<CommandEntry>& Registry();

struct RegisterCommand {
  RegisterCommand(std::string name, std::string description, CommandSetup setup) {
    Registry().push_back({std::move(name), std::move(description), std::move(setup)});
  }
};

/// Resolves a path under the repository (config/, ../shared/...) when it does not exist as given
/// relative to the current directory, so commands work from any working directory.
std::string ResolvePath(const std::string& path);

}  // namespace rcal::tool
