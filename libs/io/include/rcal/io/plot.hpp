// Plots for human reports, drawn by gnuplot (Debian's gnuplot-nox) into PNG files.
// Units in axis labels are the caller's: reports show mm and degrees, code keeps SI.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace rcal::io {

struct Series {
  std::string title;
  std::vector<double> x;
  std::vector<double> y;
  /// gnuplot style: "lines", "points", "linespoints", "boxes", "impulses".
  std::string style = "lines";
};

struct PlotSpec {
  std::string title;
  std::string xlabel;
  std::string ylabel;
  std::vector<Series> series;
  bool logx = false;
  bool logy = false;
  int width_px = 900;
  int height_px = 500;
};

/// Draws `spec` into `png` (written atomically). Returns false, with a warning logged, when
/// gnuplot is not installed or fails: a report without its plots is still a report.
bool PlotPng(const PlotSpec& spec, const std::filesystem::path& png);

}  // namespace rcal::io
