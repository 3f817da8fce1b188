#include "rcal/io/plot.hpp"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace rcal::io {
namespace {

std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

}  // namespace

bool PlotPng(const PlotSpec& spec, const std::filesystem::path& png) {
  namespace fs = std::filesystem;
  if (png.has_parent_path()) fs::create_directories(png.parent_path());
  const fs::path tmp_png = png.string() + ".tmp." + std::to_string(::getpid()) + ".png";
  const fs::path data = png.string() + ".tmp." + std::to_string(::getpid()) + ".dat";
  const fs::path script = png.string() + ".tmp." + std::to_string(::getpid()) + ".gp";
  {
    std::ofstream d(data);
    d.precision(10);
    for (const Series& s : spec.series) {
      for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
        d << s.x[i] << ' ' << s.y[i] << '\n';
      d << "\n\n";  // gnuplot data block separator: one `index` per series
    }
  }
  std::ostringstream gp;
  gp << "set terminal pngcairo size " << spec.width_px << "," << spec.height_px
     << " noenhanced font 'Sans,10'\n";
  gp << "set output " << Quote(tmp_png.string()) << "\n";
  gp << "set title " << Quote(spec.title) << "\n";
  gp << "set xlabel " << Quote(spec.xlabel) << "\n";
  gp << "set ylabel " << Quote(spec.ylabel) << "\n";
  gp << "set grid\nset key outside right\n";
  if (spec.logx) gp << "set logscale x\n";
  if (spec.logy) gp << "set logscale y\n";
  gp << "plot ";
  for (size_t i = 0; i < spec.series.size(); ++i) {
    if (i) gp << ", ";
    gp << Quote(data.string()) << " index " << i << " using 1:2 with " << spec.series[i].style
       << " title " << Quote(spec.series[i].title);
  }
  gp << "\n";
  std::ofstream(script) << gp.str();
  const std::string cmd = "gnuplot " + script.string() + " 2>/dev/null";
  const int rc = std::system(cmd.c_str());
  fs::remove(data);
  fs::remove(script);
  if (rc != 0 || !fs::exists(tmp_png)) {
    spdlog::warn("plot {} not drawn: gnuplot missing or failed", png.string());
    fs::remove(tmp_png);
    return false;
  }
  fs::rename(tmp_png, png);
  return true;
}

}  // namespace rcal::io
