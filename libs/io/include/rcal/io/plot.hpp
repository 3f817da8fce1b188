// Plots for human reports, drawn by gnuplot (Debian's gnuplot-nox) into PNG files.
// Units in axis labels are the caller's: reports show mm and degrees, code keeps SI.
// Layout: the legend goes below the plot (it used to sit outside on the right and take up to 40 %
// of the width); quantities of different units go on two y axes (Series::y2, PlotSpec::y2label);
// a categorical x axis names its points (PlotSpec::xtics, e.g. parameter names).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace rcal::io {

struct Series {
  std::string title;
  std::vector<double> x;
  std::vector<double> y;
  /// gnuplot style: "lines", "points", "linespoints", "boxes", "impulses".
  std::string style = "lines";
  /// On the right-hand axis (PlotSpec::y2label, logy2): a quantity with another unit.
  bool y2 = false;
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
  std::string y2label = {};  ///< the right-hand axis, used when a series has y2
  bool logy2 = false;
  /// Named x positions (e.g. {1, "a1"}, {2, "alpha1"}): the x axis shows these names instead of
  /// numbers, turned 45° so that long names fit.
  std::vector<std::pair<double, std::string>> xtics = {};
};

/// Draws `spec` into `png` (written atomically). Returns false, with a warning logged, when
/// gnuplot is not installed or fails: a report without its plots is still a report.
bool PlotPng(const PlotSpec& spec, const std::filesystem::path& png);

/// What PlotPng gives gnuplot: the data file (one `index` block per series) and the script that
/// draws it from `data` into `png`. Every string reaches gnuplot as plain text.
void WriteGnuplotData(const PlotSpec& spec, const std::filesystem::path& data);
std::string GnuplotScript(const PlotSpec& spec, const std::filesystem::path& data,
                          const std::filesystem::path& png);

}  // namespace rcal::io
