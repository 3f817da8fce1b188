#include "rcal/io/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
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

}  // namespace

void AtomicWriteFile(const std::filesystem::path& path, std::string_view content) {
  namespace fs = std::filesystem;
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
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
