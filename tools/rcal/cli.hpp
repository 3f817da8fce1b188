// The `rcal` command line's options, behind a compile firewall: only cli.cpp and main.cpp include
// CLI11 (2.1, Debian's, header-only). It cost every command's translation unit 3-5 s of its
// 15-25 s at -O3 (measured on cmd_analyze, cmd_fuse and cmd_track; 25 units). The commands declare
// their options through `Args` and `Opt`, which keep CLI11's names and chaining
// (`sub.add_option(...)->capture_default_str()->check(...)`).
#pragma once

#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace CLI {
class App;
class Option;
}  // namespace CLI

namespace rcal::tool {

namespace cli {

/// A validator of an option's value, turned into CLI11's in cli.cpp.
struct Check {
  enum class Kind { kRange, kPositive, kNonNegative, kMember };
  Kind kind = Kind::kRange;
  bool integral = false;  ///< kRange: the bounds are integers (CLI11 then parses an integer)
  double lo = 0.0, hi = 0.0;
  std::vector<std::string> members;
};

/// CLI::Range(lo, hi): the value within [lo, hi].
Check Range(double lo, double hi);
Check Range(int lo, int hi);
/// CLI::IsMember: one of `members`.
Check IsMember(std::vector<std::string> members);
/// CLI::PositiveNumber and CLI::NonNegativeNumber.
inline const Check PositiveNumber{Check::Kind::kPositive, false, 0.0, 0.0, {}};
inline const Check NonNegativeNumber{Check::Kind::kNonNegative, false, 0.0, 0.0, {}};

}  // namespace cli

/// One option of a command (CLI::Option*); its methods return the handle again, and `->` on it
/// gives itself, so CLI11's chains read the same.
class Opt {
 public:
  explicit Opt(CLI::Option* option) : option_(option) {}
  Opt* operator->() { return this; }
  Opt capture_default_str();
  Opt check(const cli::Check& check);
  Opt required(bool value = true);
  Opt delimiter(char separator);
  Opt expected(int count);
  Opt expected(int min, int max);
  Opt default_str(const std::string& text);
  /// Calls `callback` with each value given on the command line.
  Opt each(std::function<void(const std::string&)> callback);

 private:
  CLI::Option* option_;
};

/// A command's options (CLI::App&). add_option is defined in cli.cpp for the value types the
/// commands use (a new type is a link error naming it: add it to the list there).
class Args {
 public:
  explicit Args(CLI::App& app) : app_(&app) {}
  Args(const Args&) = delete;
  Args& operator=(const Args&) = delete;

  template <typename T>
  Opt add_option(const std::string& name, T& value, const std::string& help = "");
  Opt add_flag(const std::string& name, bool& value, const std::string& help = "");
  /// A subcommand of this command; it lives as long as this one.
  Args* add_subcommand(const std::string& name, const std::string& description);
  void require_subcommand(int count);
  /// How many times the option was given on the command line (0: its default stands).
  std::size_t count(const std::string& name) const;

 private:
  CLI::App* app_;
  std::deque<std::unique_ptr<Args>> subcommands_;
};

}  // namespace rcal::tool
