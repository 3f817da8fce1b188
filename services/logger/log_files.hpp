// The logger's files: `<prefix>.NNNN.lcmlog` in the log directory, and beside each log the
// readable history of its KINEMATIC_PARAMS, `<prefix>.NNNN.kinematic_params.csv` (same NNNN: the
// CSV holds the parameters of that log's events). Every logger start — a new run, or the
// supervisor's restart after a crash — and every rotation past --max-bytes takes the next number,
// one past the highest NNNN of either kind found, so no run ever appends to another's files and
// the newest run's files are the highest-numbered. Names that look like one of these files but
// carry no usable number (not digits, or too large) are ignored with a warning, never a reason
// not to start.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace rcal::logger {

/// `<prefix>.NNNN.lcmlog` (at least four digits).
std::string LogFileName(std::string_view prefix, int index);
/// `<prefix>.NNNN.kinematic_params.csv`, the parameters of LogFileName(prefix, index).
std::string ParamsCsvName(std::string_view prefix, int index);

/// The NNNN of `filename` when it is `<prefix>.NNNN.lcmlog` or `<prefix>.NNNN.kinematic_params.csv`
/// with NNNN decimal digits and a value below INT_MAX (so that one past it is an int). Otherwise
/// nullopt, and when `problem` is not null it receives why a name of the form
/// `<prefix>.*.lcmlog` / `<prefix>.*.kinematic_params.csv` was refused ("" for any other name:
/// not a file of this prefix).
std::optional<int> ParseLogFileIndex(std::string_view filename, std::string_view prefix,
                                     std::string* problem = nullptr);

/// One past the highest NNNN of the `<prefix>.NNNN.lcmlog` and `<prefix>.NNNN.kinematic_params.csv`
/// files in `dir` (0: none). Refused names are skipped with a warning naming the file.
int NextFileIndex(const std::filesystem::path& dir, const std::string& prefix);

/// Removes a last row cut short by a kill (the file does not end in a newline). Returns the
/// number of bytes removed (0: the file ends in a newline, is empty, or does not exist).
std::size_t RemoveTornLastRow(const std::filesystem::path& csv);

/// The files of one logger start. The first index is NextFileIndex(dir, prefix); at start the
/// highest-numbered existing CSV (the one a killed logger was writing) loses a row cut short.
class LogFiles {
 public:
  LogFiles(std::filesystem::path dir, std::string prefix);
  ~LogFiles();
  LogFiles(const LogFiles&) = delete;
  LogFiles& operator=(const LogFiles&) = delete;

  int index() const { return index_; }
  /// The current event log (the caller writes it).
  std::filesystem::path log_path() const;
  /// The current parameter history (created by the first AppendParams on this index).
  std::filesystem::path csv_path() const;
  /// Rotation: the next index (the next AppendParams starts the next CSV).
  void Next();
  /// Appends `row` (one line, ending in '\n') to the current CSV in one write(2), creating the
  /// file with `header` (one line) first. False on an error.
  bool AppendParams(const std::string& header, const std::string& row);

 private:
  std::filesystem::path dir_;
  std::string prefix_;
  int index_ = 0;
  int fd_ = -1;  // the current CSV, open for appending; -1 before its first row
};

}  // namespace rcal::logger
