// Files are written atomically: a temporary file beside the target, written and fsynced, then
// renamed over it and the directory fsynced, so a reader (or a crash) never sees half a file and
// a completed write survives a power loss.
//
// The temporary file is `NAME.tmp.PID.N`. A writer killed mid-write leaves it behind; the first
// write to a target in a process (or RemoveStaleTempFiles at start) removes those of that target
// whose PID is no longer running. A running process's temporary file is never touched.
#pragma once

#include <filesystem>
#include <string_view>

namespace rcal::io {

/// Writes `content` to `path` atomically. Creates missing parent directories.
/// Throws std::runtime_error naming the path on failure.
void AtomicWriteFile(const std::filesystem::path& path, std::string_view content);

/// Removes the temporary files `NAME.tmp.PID[.N]` of target `path` left by processes that are no
/// longer running (PID not alive; this process's own and live processes' files are kept). Returns
/// how many were removed. AtomicWriteFile calls it once per target and process; a process may call
/// it at start for the files it writes. Errors reading the directory are ignored (nothing removed).
int RemoveStaleTempFiles(const std::filesystem::path& path);

/// Reads a whole file. Throws std::runtime_error naming the path if it cannot be read.
std::string ReadFile(const std::filesystem::path& path);

}  // namespace rcal::io
