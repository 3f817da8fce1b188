// The `rcal` command run as a user runs it, for the CLI tests of tests/tools: from the source
// folder (so relative paths such as config/robots/... resolve), stdout and stderr together.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <system_error>
#include <vector>

namespace rcal::tool::testing {

struct Result {
  int exit_code;  ///< −1: killed by a signal (a crash)
  std::string output;
};

/// Runs `rcal ARGS`. `cpu_limit_s` > 0: under that CPU-time limit, so a runaway fails the test
/// instead of stalling it (no address-space limit: a sanitizer build reserves terabytes of it).
inline Result RunRcal(const std::string& args, int cpu_limit_s = 0) {
  const std::string limit =
      cpu_limit_s > 0 ? "ulimit -t " + std::to_string(cpu_limit_s) + " && " : std::string();
  const std::string cmd =
      std::string("cd ") + RCAL_SOURCE_DIR + " && " + limit + RCAL_EXE + " " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

inline nlohmann::json ReadJson(const std::filesystem::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

/// A fresh folder rcal_<prefix>_<name>_<pid> in the temporary directory (named after the process:
/// ctest runs a file's tests as parallel processes). Removed when the process ends if every test
/// passed; kept, with what the commands wrote, when one failed.
inline std::filesystem::path TempDir(const std::string& prefix, const std::string& name) {
  namespace fs = std::filesystem;
  // Made at the first call, after gtest's UnitTest (so destroyed before it).
  struct Made {
    std::vector<fs::path> dirs;
    ~Made() {
      if (::testing::UnitTest::GetInstance()->Passed()) {
        std::error_code ec;
        for (const fs::path& d : dirs) fs::remove_all(d, ec);
      }
    }
  };
  static Made made;
  const fs::path d =
      fs::temp_directory_path() / ("rcal_" + prefix + "_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  made.dirs.push_back(d);
  return d;
}

}  // namespace rcal::tool::testing
