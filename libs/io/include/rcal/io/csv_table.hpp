// A numeric CSV table with a header row: the format of every dataset rcal reads.
// Lines starting with '#' before the header are comments. Columns are found by name, in any
// order. Cells that are empty, "nan" or "NaN" read as quiet NaN; any other unparsable cell is an
// error naming its row and column.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace rcal::io {

class CsvTable {
 public:
  /// Parses CSV text. `source` names the file in error messages.
  static CsvTable Parse(const std::string& text, const std::string& source = "<text>");
  /// Reads and parses a file. Throws std::runtime_error naming the file, row and column.
  static CsvTable Load(const std::filesystem::path& path);

  int rows() const { return static_cast<int>(data_.size()); }
  const std::vector<std::string>& header() const { return header_; }
  const std::vector<std::string>& comments() const { return comments_; }
  bool Has(const std::string& column) const { return Index(column).has_value(); }
  /// Column index, or nullopt when the header has no such column.
  std::optional<int> Index(const std::string& column) const;
  /// The whole column. Throws std::runtime_error "missing column 'NAME' in SOURCE".
  Eigen::VectorXd Column(const std::string& column) const;
  /// One cell. Throws like Column() for a missing column.
  double At(int row, const std::string& column) const;
  /// Text of one cell, for non-numeric columns such as `set`.
  const std::string& Text(int row, const std::string& column) const;
  const std::string& source() const { return source_; }

 private:
  std::string source_;
  std::vector<std::string> comments_;
  std::vector<std::string> header_;
  std::vector<std::vector<double>> data_;
  std::vector<std::vector<std::string>> text_;
  int Require(const std::string& column) const;
};

}  // namespace rcal::io
