// CLI11 behind rcal::tool::Args (cli.hpp): the one command translation unit that includes it.
#include "cli.hpp"

#include <CLI/CLI.hpp>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace rcal::tool {

namespace cli {

Check Range(double lo, double hi) {
  return {Check::Kind::kRange, false, lo, hi, {}};
}
Check Range(int lo, int hi) {
  return {Check::Kind::kRange, true, static_cast<double>(lo), static_cast<double>(hi), {}};
}
Check IsMember(std::vector<std::string> members) {
  return {Check::Kind::kMember, false, 0.0, 0.0, std::move(members)};
}

}  // namespace cli

Opt Opt::capture_default_str() {
  option_->capture_default_str();
  return *this;
}

Opt Opt::check(const cli::Check& c) {
  switch (c.kind) {
    case cli::Check::Kind::kRange:
      if (c.integral)
        option_->check(
            CLI::Range(static_cast<std::int64_t>(c.lo), static_cast<std::int64_t>(c.hi)));
      else
        option_->check(CLI::Range(c.lo, c.hi));
      break;
    case cli::Check::Kind::kPositive:
      option_->check(CLI::PositiveNumber);
      break;
    case cli::Check::Kind::kNonNegative:
      option_->check(CLI::NonNegativeNumber);
      break;
    case cli::Check::Kind::kMember:
      option_->check(CLI::IsMember(c.members));
      break;
  }
  return *this;
}

Opt Opt::required(bool value) {
  option_->required(value);
  return *this;
}

Opt Opt::delimiter(char separator) {
  option_->delimiter(separator);
  return *this;
}

Opt Opt::expected(int count) {
  option_->expected(count);
  return *this;
}

Opt Opt::expected(int min, int max) {
  option_->expected(min, max);
  return *this;
}

Opt Opt::default_str(const std::string& text) {
  option_->default_str(text);
  return *this;
}

Opt Opt::each(std::function<void(const std::string&)> callback) {
  option_->each(std::move(callback));
  return *this;
}

template <typename T>
Opt Args::add_option(const std::string& name, T& value, const std::string& help) {
  return Opt(app_->add_option(name, value, help));
}

// The value types the commands bind (the link fails naming a missing one).
template Opt Args::add_option(const std::string&, int&, const std::string&);
template Opt Args::add_option(const std::string&, unsigned&, const std::string&);
template Opt Args::add_option(const std::string&, long&, const std::string&);
template Opt Args::add_option(const std::string&, unsigned long&, const std::string&);
template Opt Args::add_option(const std::string&, long long&, const std::string&);
template Opt Args::add_option(const std::string&, double&, const std::string&);
template Opt Args::add_option(const std::string&, std::string&, const std::string&);
template Opt Args::add_option(const std::string&, std::vector<std::string>&, const std::string&);
template Opt Args::add_option(const std::string&, std::vector<double>&, const std::string&);
template Opt Args::add_option(const std::string&, std::vector<int>&, const std::string&);

Opt Args::add_flag(const std::string& name, bool& value, const std::string& help) {
  return Opt(app_->add_flag(name, value, help));
}

Args* Args::add_subcommand(const std::string& name, const std::string& description) {
  subcommands_.push_back(std::make_unique<Args>(*app_->add_subcommand(name, description)));
  return subcommands_.back().get();
}

void Args::require_subcommand(int count) {
  app_->require_subcommand(count);
}

std::size_t Args::count(const std::string& name) const {
  return app_->count(name);
}

}  // namespace rcal::tool
