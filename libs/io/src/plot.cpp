#include "rcal/io/plot.hpp"

#include <spawn.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

extern char** environ;

namespace rcal::io {
namespace {

// A gnuplot string expression for `s`, built of single-quoted strings (no escapes and no
// `command` substitution inside them; gnuplot runs backquoted commands in double-quoted strings)
// joined with "'" for each quote: 'it' . "'" . 's'. (A doubled quote is not used: a string that
// starts with one reads as gnuplot's '' "previous file".) Line breaks end a gnuplot command, so
// they become spaces (paths with one are refused before).
std::string Quote(const std::string& s) {
  std::string out, piece;
  const auto flush = [&] {
    if (piece.empty()) return;
    out += (out.empty() ? "'" : " . '") + piece + "'";
    piece.clear();
  };
  for (char c : s) {
    if (c != '\'') {
      piece += c == '\n' || c == '\r' ? ' ' : c;
      continue;
    }
    flush();
    out += out.empty() ? "\"'\"" : " . \"'\"";
  }
  flush();
  return out.empty() ? "''" : out;
}

// Runs `gnuplot SCRIPT` with no shell between (argv, PATH lookup as execvp), stderr to
// /dev/null. Returns gnuplot's exit status, or -1 when it could not be started or did not exit.
int RunGnuplot(const std::filesystem::path& script) {
  posix_spawn_file_actions_t actions;
  if (posix_spawn_file_actions_init(&actions) != 0) return -1;
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
  std::string program = "gnuplot", arg = script.string();
  char* argv[] = {program.data(), arg.data(), nullptr};
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) return -1;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

void WriteGnuplotData(const PlotSpec& spec, const std::filesystem::path& data) {
  std::ofstream d(data);
  d.precision(10);
  for (const Series& s : spec.series) {
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) d << s.x[i] << ' ' << s.y[i] << '\n';
    d << "\n\n";  // gnuplot data block separator: one `index` per series
  }
}

std::string GnuplotScript(const PlotSpec& spec, const std::filesystem::path& data,
                          const std::filesystem::path& png) {
  std::ostringstream gp;
  gp << "set terminal pngcairo size " << spec.width_px << "," << spec.height_px
     << " noenhanced font 'Sans,10'\n";
  gp << "set output " << Quote(png.string()) << "\n";
  gp << "set title " << Quote(spec.title) << "\n";
  gp << "set xlabel " << Quote(spec.xlabel) << "\n";
  gp << "set ylabel " << Quote(spec.ylabel) << "\n";
  // The legend below the plot, in as many columns as fit: the plot keeps the full width.
  gp << "set grid\nset key below horizontal\n";
  if (spec.logx) gp << "set logscale x\n";
  if (spec.logy) gp << "set logscale y\n";
  bool y2 = false;
  for (const Series& s : spec.series) y2 |= s.y2;
  if (y2) {
    gp << "set ytics nomirror\nset y2tics\nset y2label " << Quote(spec.y2label) << "\n";
    if (spec.logy2) gp << "set logscale y2\n";
  }
  if (!spec.xtics.empty()) {
    gp << "set xtics rotate by 45 right (";
    for (size_t i = 0; i < spec.xtics.size(); ++i) {
      char at[32];
      std::snprintf(at, sizeof at, "%.10g", spec.xtics[i].first);
      gp << (i ? ", " : "") << Quote(spec.xtics[i].second) << " " << at;
    }
    gp << ")\n";
    // Half a step of room beyond the first and last names: their points (or boxes) are not cut
    // in half by the border.
    double step = 0;  // the smallest gap between two names (1 with a single name)
    for (size_t i = 1; i < spec.xtics.size(); ++i) {
      const double d = std::abs(spec.xtics[i].first - spec.xtics[i - 1].first);
      if (d > 0 && (step == 0 || d < step)) step = d;
    }
    if (step == 0) step = 1;
    char half[32];
    std::snprintf(half, sizeof half, "%.10g", step / 2);
    gp << "set offsets " << half << ", " << half << ", 0, 0\n";
  }
  gp << "plot ";
  for (size_t i = 0; i < spec.series.size(); ++i) {
    if (i) gp << ", ";
    gp << Quote(data.string()) << " index " << i << " using 1:2"
       << (spec.series[i].y2 ? " axes x1y2" : "") << " with " << spec.series[i].style << " title "
       << Quote(spec.series[i].title);
  }
  gp << "\n";
  return gp.str();
}

bool PlotPng(const PlotSpec& spec, const std::filesystem::path& png) {
  namespace fs = std::filesystem;
  if (png.string().find_first_of("\n\r") != std::string::npos) {
    spdlog::warn("plot not drawn: a line break in the path {}", png.string());
    return false;
  }
  if (png.has_parent_path()) fs::create_directories(png.parent_path());
  // Absolute: gnuplot must not read a script path that starts with '-' as an option.
  const std::string stem = fs::absolute(png).string() + ".tmp." + std::to_string(::getpid());
  const fs::path tmp_png = stem + ".png", data = stem + ".dat", script = stem + ".gp";
  WriteGnuplotData(spec, data);
  std::ofstream(script) << GnuplotScript(spec, data, tmp_png);
  const int rc = RunGnuplot(script);
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
