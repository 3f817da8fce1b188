#include "log_files.hpp"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <system_error>

namespace rcal::logger {

namespace {

constexpr std::string_view kLogSuffix = ".lcmlog";
constexpr std::string_view kCsvSuffix = ".kinematic_params.csv";

std::string Numbered(std::string_view prefix, int index, std::string_view suffix) {
  char digits[16];
  std::snprintf(digits, sizeof digits, ".%04d", index);
  return std::string(prefix) + digits + std::string(suffix);
}

// Writes all of `text` with write(2) (one call unless interrupted). False on an error.
bool WriteAll(int fd, const std::string& text) {
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<size_t>(n);
  }
  return true;
}

}  // namespace

std::string LogFileName(std::string_view prefix, int index) {
  return Numbered(prefix, index, kLogSuffix);
}

std::string ParamsCsvName(std::string_view prefix, int index) {
  return Numbered(prefix, index, kCsvSuffix);
}

std::optional<int> ParseLogFileIndex(std::string_view filename, std::string_view prefix,
                                     std::string* problem) {
  if (problem) problem->clear();
  std::string_view suffix;
  for (const std::string_view s : {kLogSuffix, kCsvSuffix})
    if (filename.size() >= prefix.size() + 1 + s.size() && filename.starts_with(prefix) &&
        filename[prefix.size()] == '.' && filename.ends_with(s))
      suffix = s;
  if (suffix.empty()) return std::nullopt;
  const std::string_view digits =
      filename.substr(prefix.size() + 1, filename.size() - prefix.size() - 1 - suffix.size());
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

std::size_t RemoveTornLastRow(const std::filesystem::path& csv) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(csv, ec)) return 0;
  const auto size = fs::file_size(csv);
  std::ifstream in(csv, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.size() != size) throw std::runtime_error(csv.string() + ": cannot read");
  if (text.empty() || text.back() == '\n') return 0;
  const auto keep = text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1;
  fs::resize_file(csv, keep);
  return text.size() - keep;
}

LogFiles::LogFiles(std::filesystem::path dir, std::string prefix)
    : dir_(std::move(dir)), prefix_(std::move(prefix)) {
  index_ = NextFileIndex(dir_, prefix_);
  // The CSV a killed logger was writing: the highest-numbered one.
  for (int i = index_ - 1; i >= 0; --i) {
    const auto csv = dir_ / ParamsCsvName(prefix_, i);
    if (!std::filesystem::exists(csv)) continue;
    if (const std::size_t cut = RemoveTornLastRow(csv); cut > 0)
      spdlog::warn("{}: removed a row cut short by a kill ({} bytes)", csv.string(), cut);
    break;
  }
}

LogFiles::~LogFiles() {
  if (fd_ >= 0) ::close(fd_);
}

std::filesystem::path LogFiles::log_path() const {
  return dir_ / LogFileName(prefix_, index_);
}

std::filesystem::path LogFiles::csv_path() const {
  return dir_ / ParamsCsvName(prefix_, index_);
}

void LogFiles::Next() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ++index_;
}

bool LogFiles::AppendParams(const std::string& header, const std::string& row) {
  if (fd_ < 0) {
    const auto path = csv_path();
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0644);
    if (fd_ < 0) {
      spdlog::error("{}: {}", path.string(), std::strerror(errno));
      return false;
    }
    if (!WriteAll(fd_, header)) return false;
  }
  return WriteAll(fd_, row);
}

}  // namespace rcal::logger
