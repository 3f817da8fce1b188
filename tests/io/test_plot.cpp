// PlotPng: a PNG of the requested size drawn by gnuplot, with no shell between rcal and gnuplot:
// paths and labels with quotes, `;`, `$(...)` and backquotes are drawn as text and run nothing.
// Tests that need gnuplot skip without it (deploy/install-deps installs gnuplot-nox). The layout
// (legend below, two y axes, named x positions) is judged by what gnuplot itself reports after
// drawing (its GPVAL_* variables: where the plot's border landed, each axis' range).
#include "rcal/io/plot.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>

#include "io_test_util.hpp"

namespace rcal::io {
namespace {

namespace fs = std::filesystem;
using testing::ScratchDir;

bool HaveGnuplot() {
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "";
  size_t start = 0;
  while (start <= dirs.size()) {
    const size_t end = std::min(dirs.find(':', start), dirs.size());
    const fs::path dir = dirs.substr(start, end - start);
    if (!dir.empty() && ::access((dir / "gnuplot").c_str(), X_OK) == 0) return true;
    start = end + 1;
  }
  return false;
}

struct PngSize {
  uint32_t width, height;
};

// Width and height from the IHDR chunk of a PNG file, or nullopt when it is not a PNG.
std::optional<PngSize> ReadPngSize(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  unsigned char h[24] = {};
  if (!in.read(reinterpret_cast<char*>(h), sizeof h)) return std::nullopt;
  const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (!std::equal(sig, sig + 8, h) || std::string(h + 12, h + 16) != "IHDR") return std::nullopt;
  const auto be = [&](int o) {
    return uint32_t{h[o]} << 24 | uint32_t{h[o + 1]} << 16 | uint32_t{h[o + 2]} << 8 | h[o + 3];
  };
  return PngSize{be(16), be(20)};
}

std::set<std::string> Names(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.insert(entry.path().filename());
  return names;
}

PlotSpec Line(const std::string& title) {
  PlotSpec s;
  s.title = title;
  s.xlabel = "time [s]";
  s.ylabel = "error [mm]";
  s.series = {{"a", {0, 1, 2, 3}, {0, 1, 4, 9}, "lines"}, {"b", {0, 1, 2}, {3, 2, 1}, "points"}};
  s.width_px = 320;
  s.height_px = 200;
  return s;
}

// Runs the test body in `dir` as the working directory (a stray `touch NAME` lands there).
class InDirectory {
 public:
  explicit InDirectory(const fs::path& dir) : old_(fs::current_path()) { fs::current_path(dir); }
  ~InDirectory() { fs::current_path(old_); }

 private:
  fs::path old_;
};

TEST(Plot, DrawsAPngOfTheRequestedSizeAndLeavesNoTemporaryFiles) {
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  ASSERT_TRUE(PlotPng(Line("plain"), d / "out/plot.png"));
  const auto size = ReadPngSize(d / "out/plot.png");
  ASSERT_TRUE(size.has_value());
  EXPECT_EQ(size->width, 320u);
  EXPECT_EQ(size->height, 200u);
  EXPECT_EQ(Names(d / "out"), std::set<std::string>{"plot.png"});
}

TEST(Plot, ADirectoryNamedWithAQuoteASemicolonAndASpaceWorks) {
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  const fs::path dir = d / "it's; a \"plot\" dir";
  ASSERT_TRUE(PlotPng(Line("it's \"quoted\""), dir / "p'lot.png"));
  EXPECT_TRUE(ReadPngSize(dir / "p'lot.png").has_value());
  EXPECT_EQ(Names(dir), std::set<std::string>{"p'lot.png"});
}

TEST(Plot, APathOrLabelThatLooksLikeACommandRunsNothing) {
  ScratchDir d;
  const InDirectory cwd(d.path());
  // Shell separators and substitutions in the directory, the file name and the labels.
  const fs::path dir = d / "x; touch SENTINEL1; y";
  PlotSpec spec = Line("`touch SENTINEL2` $(touch SENTINEL3)");
  spec.xlabel = "\"; `touch SENTINEL4`";
  spec.series[0].title = "'`touch SENTINEL5`'";
  const bool drawn = PlotPng(spec, dir / "$(touch SENTINEL6) `touch SENTINEL7`.png");
  for (const char* s : {"SENTINEL1", "SENTINEL2", "SENTINEL3", "SENTINEL4", "SENTINEL5",
                        "SENTINEL6", "SENTINEL7"}) {
    EXPECT_FALSE(fs::exists(d / s)) << s;
    EXPECT_FALSE(fs::exists(dir / s)) << s;
  }
  if (HaveGnuplot()) {
    EXPECT_TRUE(drawn);
    EXPECT_EQ(Names(dir), std::set<std::string>{"$(touch SENTINEL6) `touch SENTINEL7`.png"});
  }
}

TEST(Plot, LabelsAreTextForGnuplotToo) {
  // gnuplot itself runs `...` in double-quoted strings: labels must reach it as plain text.
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  const InDirectory cwd(d.path());
  PlotSpec spec = Line("`touch SENTINEL1` \\ \\\"");
  spec.ylabel = "\"`touch SENTINEL2`\"";
  spec.series[1].title = "it's `touch SENTINEL3`";
  ASSERT_TRUE(PlotPng(spec, d / "plot.png"));
  for (const char* s : {"SENTINEL1", "SENTINEL2", "SENTINEL3"})
    EXPECT_FALSE(fs::exists(d / s)) << s;
  EXPECT_EQ(Names(d.path()), std::set<std::string>{"plot.png"});
}

// Draws `spec` with the script PlotPng uses and returns gnuplot's own report of the result: the
// plot border's left and right ends in pixels of the canvas (term_xmin, term_xmax; pngcairo
// reports these in pixels) and the ranges of the axes.
std::map<std::string, double> Layout(const PlotSpec& spec, const fs::path& dir) {
  const fs::path data = dir / "p.dat", script = dir / "p.gp", report = dir / "layout.txt";
  WriteGnuplotData(spec, data);
  std::ofstream(script)
      << GnuplotScript(spec, data, dir / "p.png") << "set print '" << report.string()
      << "'\nprint GPVAL_TERM_XMIN, GPVAL_TERM_XMAX, "
         "GPVAL_Y_MIN, GPVAL_Y_MAX, GPVAL_Y2_MIN, GPVAL_Y2_MAX, GPVAL_X_MIN, GPVAL_X_MAX\n";
  EXPECT_EQ(std::system(("gnuplot '" + script.string() + "'").c_str()), 0);
  std::ifstream in(report);
  std::map<std::string, double> m;
  for (const char* k :
       {"term_xmin", "term_xmax", "y_min", "y_max", "y2_min", "y2_max", "x_min", "x_max"})
    in >> m[k];
  EXPECT_TRUE(in) << "gnuplot's report " << report;
  return m;
}

// The reports' legends used to sit outside on the right and take up to 40 % of the width (the
// EKF convergence plot: 62 % left for the data). Below the plot, the data keeps the width.
TEST(Plot, TheLegendLeavesTheWidthToTheData) {
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  PlotSpec spec;
  spec.title = "EKF convergence";
  spec.xlabel = "poses used";
  spec.ylabel = "error";
  const std::vector<double> x = {1, 2, 3, 4};
  for (const char* t :
       {"RMS parameter error [Cramér–Rao σ of 50 poses]",
        "mean test position error against truth [mm]", "EKF (pose level)", "Cramér–Rao prediction"})
    spec.series.push_back({t, x, {4, 3, 2, 1}, "linespoints"});
  const auto m = Layout(spec, d.path());
  const double data_width = (m.at("term_xmax") - m.at("term_xmin")) / spec.width_px;
  EXPECT_GT(data_width, 0.85) << "the plot border spans " << data_width << " of the width";
}

// σ and mm on one axis made one of them unreadable: each unit gets its own axis and range.
TEST(Plot, TwoUnitsGetTwoAxes) {
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  PlotSpec spec;
  spec.ylabel = "RMS parameter error [σ]";
  spec.y2label = "test error [mm]";
  spec.series = {{"parameters [σ]", {1, 2, 3}, {2.0, 1.0, 0.5}, "linespoints"},
                 {"test error [mm]", {1, 2, 3}, {900, 40, 10}, "linespoints", true}};
  const auto m = Layout(spec, d.path());
  EXPECT_LE(m.at("y_max"), 2.5);  // the σ series alone sets the left axis
  EXPECT_GE(m.at("y2_max"), 900.0);
  EXPECT_LE(m.at("y2_min"), 10.0);
  EXPECT_TRUE(PlotPng(spec, d / "two_axes.png"));
}

// A categorical axis (the identified parameters) names its points instead of numbering them, with
// half a step of room at each end (the first and last points used to sit on the border).
TEST(Plot, NamedXPositionsAreTheTickLabels) {
  if (!HaveGnuplot()) GTEST_SKIP() << "gnuplot not installed";
  ScratchDir d;
  PlotSpec spec = Line("parameters");
  spec.xtics = {{0, "a1"}, {1, "alpha1"}, {2, "it's d2"}, {3, "theta3"}};
  const std::string script = GnuplotScript(spec, d / "p.dat", d / "p.png");
  const auto xtics = script.find("set xtics");
  ASSERT_NE(xtics, std::string::npos) << script;
  const std::string line = script.substr(xtics, script.find('\n', xtics) - xtics);
  for (const char* name : {"'a1' 0", "'alpha1' 1", "'it' . \"'\" . 's d2' 2", "'theta3' 3"})
    EXPECT_NE(line.find(name), std::string::npos) << name << " in " << line;
  const auto m = Layout(spec, d.path());
  EXPECT_LE(m.at("x_min"), -0.5);
  EXPECT_GE(m.at("x_max"), 3.5);
  EXPECT_TRUE(PlotPng(spec, d / "named.png"));
}

TEST(Plot, WithoutGnuplotItReturnsFalseAndLeavesNoFiles) {
  ScratchDir d;
  const char* old = std::getenv("PATH");
  const std::string saved = old ? old : "";
  fs::create_directories(d / "empty_bin");
  ::setenv("PATH", (d / "empty_bin").c_str(), 1);
  const bool drawn = PlotPng(Line("no gnuplot"), d / "out/plot.png");
  ::setenv("PATH", saved.c_str(), 1);
  EXPECT_FALSE(drawn);
  EXPECT_TRUE(Names(d / "out").empty());
}

}  // namespace
}  // namespace rcal::io
