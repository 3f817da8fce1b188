// Files are written atomically: a temporary file beside the target, written and fsynced, then
// renamed over it and the directory fsynced, so a reader (or a crash) never sees half a file and
// a completed write survives a power loss.
#pragma once

#include <filesystem>
#include <string_view>

namespace rcal::io {

/// Writes `content` to `path` atomically. Creates missing parent directories.
/// Throws std::runtime_error naming the path on failure.
void AtomicWriteFile(const std::filesystem::path& path, std::string_view content);

/// Reads a whole file. Throws std::runtime_error naming the path if it cannot be read.
std::string ReadFile(const std::filesystem::path& path);

}  // namespace rcal::io
