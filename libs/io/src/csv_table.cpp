#include "rcal/io/csv_table.hpp"

#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> SplitCells(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::istringstream ss(line);
  while (std::getline(ss, cell, ',')) cells.push_back(Trim(cell));
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

}  // namespace

CsvTable CsvTable::Parse(const std::string& text, const std::string& source) {
  CsvTable t;
  t.source_ = source;
  // A UTF-8 byte order mark (spreadsheet exports) would otherwise become part of the first
  // column's name.
  std::istringstream in(text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? text.substr(3) : text);
  std::string line;
  int line_no = 0;
  bool have_header = false;
  while (std::getline(in, line)) {
    ++line_no;
    const std::string trimmed = Trim(line);
    if (trimmed.empty()) continue;
    if (!have_header) {
      if (trimmed[0] == '#') {
        t.comments_.push_back(trimmed.substr(1));
        continue;
      }
      t.header_ = SplitCells(trimmed);
      for (size_t i = 0; i < t.header_.size(); ++i)
        for (size_t j = 0; j < i; ++j)
          if (t.header_[i] == t.header_[j])
            throw std::runtime_error(source + ": column '" + t.header_[i] + "' appears twice");
      have_header = true;
      continue;
    }
    if (trimmed[0] == '#') continue;
    std::vector<std::string> cells = SplitCells(trimmed);
    if (cells.size() != t.header_.size()) {
      throw std::runtime_error(source + ": line " + std::to_string(line_no) + " has " +
                               std::to_string(cells.size()) + " cells, the header has " +
                               std::to_string(t.header_.size()));
    }
    std::vector<double> values(cells.size());
    for (size_t c = 0; c < cells.size(); ++c) {
      const std::string& s = cells[c];
      if (s.empty() || s == "nan" || s == "NaN" || s == "NAN") {
        values[c] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      double v = 0;
      const char* first = s.data();
      if (*first == '+') ++first;
      const auto [ptr, ec] = std::from_chars(first, s.data() + s.size(), v);
      // A cell that does not parse keeps NaN here; At() reports it with row and column.
      values[c] = (ec == std::errc() && ptr == s.data() + s.size())
                      ? v
                      : std::numeric_limits<double>::quiet_NaN();
    }
    t.data_.push_back(std::move(values));
    t.text_.push_back(std::move(cells));
  }
  if (!have_header) throw std::runtime_error(source + ": no header row");
  return t;
}

CsvTable CsvTable::Load(const std::filesystem::path& path) {
  return Parse(ReadFile(path), path.string());
}

std::optional<int> CsvTable::Index(const std::string& column) const {
  for (size_t i = 0; i < header_.size(); ++i)
    if (header_[i] == column) return static_cast<int>(i);
  return std::nullopt;
}

int CsvTable::Require(const std::string& column) const {
  const auto i = Index(column);
  if (!i) throw std::runtime_error("missing column '" + column + "' in " + source_);
  return *i;
}

Eigen::VectorXd CsvTable::Column(const std::string& column) const {
  Require(column);
  Eigen::VectorXd v(rows());
  for (int r = 0; r < rows(); ++r) v(r) = At(r, column);
  return v;
}

double CsvTable::At(int row, const std::string& column) const {
  const int c = Require(column);
  const double v = data_.at(row)[c];
  if (std::isnan(v) && !text_[row][c].empty()) {
    const std::string& s = text_[row][c];
    // Spellings of NaN (from_chars also reads "-nan" and "nan(...)") are values, not errors.
    double parsed = 0;
    const char* first = s.data() + (s[0] == '+' ? 1 : 0);
    const auto [ptr, ec] = std::from_chars(first, s.data() + s.size(), parsed);
    const bool is_nan = ec == std::errc() && ptr == s.data() + s.size() && std::isnan(parsed);
    if (!is_nan)
      throw std::runtime_error(source_ + ": row " + std::to_string(row + 1) + " column '" + column +
                               "' is not a number: '" + s + "'");
  }
  return v;
}

const std::string& CsvTable::Text(int row, const std::string& column) const {
  return text_.at(row)[Require(column)];
}

}  // namespace rcal::io
