// The logger's file names: `<prefix>.NNNN.lcmlog` in the log directory. A restarted logger starts
// the file after the highest NNNN found; names that look like a log but carry no usable number
// (not digits, or too large) are ignored with a warning, never a reason not to start.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace rcal::logger {

/// The NNNN of `filename` when it is `<prefix>.NNNN.lcmlog` with NNNN decimal digits and a value
/// below INT_MAX (so that one past it is an int). Otherwise nullopt, and when `problem` is not
/// null it receives why a name of the form `<prefix>.*.lcmlog` was refused ("" for any other
/// name: not a log of this prefix).
std::optional<int> ParseLogFileIndex(std::string_view filename, std::string_view prefix,
                                     std::string* problem = nullptr);

/// One past the highest NNNN of the `<prefix>.NNNN.lcmlog` files in `dir` (0: none). Refused
/// names are skipped with a warning naming the file.
int NextFileIndex(const std::filesystem::path& dir, const std::string& prefix);

}  // namespace rcal::logger
