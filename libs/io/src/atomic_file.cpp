#include "rcal/io/atomic_file.hpp"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>
#include <mutex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <system_error>

namespace rcal::io {
namespace {

std::runtime_error WriteError(const std::filesystem::path& path, const std::string& what,
                              int error) {
  return std::runtime_error("cannot write " + path.string() + ": " + what + ": " +
                            std::strerror(error));
}

// Writes all of `content` to `fd`, retrying short writes and EINTR. False (errno set) on error.
bool WriteAll(int fd, std::string_view content) {
  size_t done = 0;
  while (done < content.size()) {
    const ssize_t n = ::write(fd, content.data() + done, content.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      if (n == 0) errno = EIO;
      return false;
    }
    done += static_cast<size_t>(n);
  }
  return true;
}

// fsync of the directory holding a renamed file, so that the rename itself survives a crash.
bool SyncDirectory(const std::filesystem::path& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  const int error = errno;
  ::close(fd);
  errno = error;
  return ok;
}

/// The PID of a temporary file name `target.tmp.PID` or `target.tmp.PID.N` of `target`, else 0.
pid_t TempFilePid(const std::string& name, const std::string& target) {
  const std::string prefix = target + ".tmp.";
  if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) return 0;
  const char* first = name.data() + prefix.size();
  const char* last = name.data() + name.size();
  long pid = 0;
  const auto [ptr, ec] = std::from_chars(first, last, pid);
  if (ec != std::errc() || ptr == first || pid <= 0 || pid > (1L << 30)) return 0;
  if (ptr != last) {
    // ".N": the writer's counter, digits only.
    if (*ptr != '.' || ptr + 1 == last) return 0;
    for (const char* c = ptr + 1; c != last; ++c)
      if (*c < '0' || *c > '9') return 0;
  }
  return static_cast<pid_t>(pid);
}

/// True unless no process has this PID (EPERM: it runs, as another user).
bool Alive(pid_t pid) {
  return ::kill(pid, 0) == 0 || errno != ESRCH;
}

/// RemoveStaleTempFiles once per target in this process.
void RemoveStaleTempFilesOnce(const std::filesystem::path& path) {
  static std::mutex mutex;
  static std::set<std::string> cleaned;
  std::error_code ec;
  const std::filesystem::path key = std::filesystem::absolute(path, ec).lexically_normal();
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (!cleaned.insert(ec ? path.string() : key.string()).second) return;
  }
  RemoveStaleTempFiles(path);
}

}  // namespace

int RemoveStaleTempFiles(const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  const std::string target = path.filename().string();
  if (target.empty()) return 0;
  const pid_t self = ::getpid();
  int removed = 0;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const pid_t pid = TempFilePid(it->path().filename().string(), target);
    if (pid == 0 || pid == self || Alive(pid)) continue;
    std::error_code rm;
    if (it->is_regular_file(rm) && fs::remove(it->path(), rm)) ++removed;
  }
  return removed;
}

void AtomicWriteFile(const std::filesystem::path& path, std::string_view content) {
  namespace fs = std::filesystem;
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
  RemoveStaleTempFilesOnce(path);
  // A temporary file of our own beside the target (pid and a counter: threads share the pid;
  // O_EXCL: never one left by another writer), written, fsynced, then renamed over the target.
  static std::atomic<unsigned long> counter{0};
  fs::path tmp;
  int fd = -1;
  for (int attempt = 0; fd < 0; ++attempt) {
    tmp = path.string() + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
    fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && (errno != EEXIST || attempt > 100)) throw WriteError(tmp, "open", errno);
  }
  const bool written = WriteAll(fd, content);
  const bool synced = written && ::fsync(fd) == 0;
  const int error = errno;
  const bool closed = ::close(fd) == 0;
  if (!written || !synced || !closed) {
    const int e = written && synced ? errno : error;
    ::unlink(tmp.c_str());
    throw WriteError(path, !written ? "write" : !synced ? "fsync" : "close", e);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    throw WriteError(path, "rename", e);
  }
  if (!SyncDirectory(path.parent_path())) throw WriteError(path, "fsync of its directory", errno);
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace rcal::io
