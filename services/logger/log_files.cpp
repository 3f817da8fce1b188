#include "log_files.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <climits>
#include <system_error>

namespace rcal::logger {

std::optional<int> ParseLogFileIndex(std::string_view filename, std::string_view prefix,
                                     std::string* problem) {
  if (problem) problem->clear();
  constexpr std::string_view kSuffix = ".lcmlog";
  if (filename.size() < prefix.size() + 1 + kSuffix.size() || !filename.starts_with(prefix) ||
      filename[prefix.size()] != '.' || !filename.ends_with(kSuffix))
    return std::nullopt;
  const std::string_view digits =
      filename.substr(prefix.size() + 1, filename.size() - prefix.size() - 1 - kSuffix.size());
  const auto refuse = [&](const std::string& why) -> std::optional<int> {
    if (problem) problem->append("'").append(digits).append("' ").append(why);
    return std::nullopt;
  };
  // from_chars takes a leading '-'; the index is digits only.
  if (digits.empty() ||
      !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return refuse("is not a file number (decimal digits)");
  int index = 0;
  const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), index);
  if (ec == std::errc::result_out_of_range || (ec == std::errc() && index == INT_MAX))
    return refuse("is too large a file number");
  if (ec != std::errc() || end != digits.data() + digits.size())
    return refuse("is not a file number (decimal digits)");
  return index;
}

int NextFileIndex(const std::filesystem::path& dir, const std::string& prefix) {
  int next = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    const std::string f = entry.path().filename().string();
    std::string problem;
    if (const auto index = ParseLogFileIndex(f, prefix, &problem))
      next = std::max(next, *index + 1);
    else if (!problem.empty())
      spdlog::warn("{}: ignored, not one of the logger's files: {}", (dir / f).string(), problem);
  }
  return next;
}

}  // namespace rcal::logger
