// tools/rcal/cli.hpp: rcal's options reach CLI11 unchanged: values of every bound type, the
// validators (bounds included, a fraction refused for an integer, the help CLI11's own), flags,
// counts, each, subcommands, and a refusal names the option.
#include "cli.hpp"

#include <gtest/gtest.h>

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace rcal::tool {
namespace {

// Parses `argv` (after the program name) into `app`; the error's text, or "" when it parsed.
std::string Parse(CLI::App& app, std::vector<std::string> argv) {
  std::vector<char*> raw;
  std::string program = "rcal";
  raw.push_back(program.data());
  for (auto& a : argv) raw.push_back(a.data());
  try {
    app.parse(static_cast<int>(raw.size()), raw.data());
  } catch (const CLI::ParseError& e) {
    return std::string(e.get_name()) + ": " + e.what();
  }
  return "";
}

TEST(Cli, EveryBoundTypeTakesItsValue) {
  CLI::App app;
  Args args(app);
  int i = 0;
  unsigned u = 0;
  long l = 0;
  unsigned long ul = 0;
  long long ll = 0;
  double d = 0.0;
  std::string s;
  std::vector<std::string> vs;
  std::vector<double> vd;
  std::vector<int> vi;
  bool flag = false;
  args.add_option("--i", i, "");
  args.add_option("--u", u, "");
  args.add_option("--l", l, "");
  args.add_option("--ul", ul, "");
  args.add_option("--ll", ll, "");
  args.add_option("--d", d, "");
  args.add_option("--s", s, "");
  args.add_option("--vs", vs, "")->delimiter(',');
  args.add_option("--vd", vd, "")->delimiter(',');
  args.add_option("--vi", vi, "")->delimiter(',');
  args.add_flag("--flag", flag, "");
  ASSERT_EQ(Parse(app, {"--i",        "-3",   "--u",  "7",      "--l",    "-9000000000", "--ul",
                        "9000000000", "--ll", "-5",   "--d",    "2.5e-3", "--s",         "x y",
                        "--vs",       "a,b",  "--vd", "1.5,-2", "--vi",   "4,5,6",       "--flag"}),
            "");
  EXPECT_EQ(i, -3);
  EXPECT_EQ(u, 7u);
  EXPECT_EQ(l, -9000000000L);
  EXPECT_EQ(ul, 9000000000UL);
  EXPECT_EQ(ll, -5);
  EXPECT_EQ(d, 2.5e-3);
  EXPECT_EQ(s, "x y");
  EXPECT_EQ(vs, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(vd, (std::vector<double>{1.5, -2.0}));
  EXPECT_EQ(vi, (std::vector<int>{4, 5, 6}));
  EXPECT_TRUE(flag);
  EXPECT_EQ(args.count("--flag"), 1u);
  EXPECT_EQ(args.count("--i"), 1u);
}

TEST(Cli, ValidatorsRefuseNamingTheOption) {
  struct Case {
    std::vector<std::string> argv;
    bool accepted;
  };
  const std::vector<Case> cases = {
      {{"--jobs", "4"}, true},    {{"--jobs", "65"}, false},     {{"--jobs", "0"}, false},
      {{"--jobs", "1.5"}, false}, {{"--tau", "0.5"}, true},      {{"--tau", "1.5"}, false},
      {{"--sigma", "0.1"}, true}, {{"--sigma", "0"}, false},     {{"--sigma", "-1"}, false},
      {{"--offset", "0"}, true},  {{"--offset", "-0.1"}, false}, {{"--frame", "enu"}, true},
      {{"--frame", "up"}, false}, {{"--need"}, false},
  };
  for (const Case& c : cases) {
    CLI::App app;
    Args args(app);
    int jobs = 1;
    double tau = 0.0, sigma = 1.0, offset = 0.0;
    std::string frame = "ned", need;
    args.add_option("--jobs", jobs, "")->check(cli::Range(1, 64));
    args.add_option("--tau", tau, "")->check(cli::Range(0.0, 1.0));
    args.add_option("--sigma", sigma, "")->check(cli::PositiveNumber);
    args.add_option("--offset", offset, "")->check(cli::NonNegativeNumber);
    args.add_option("--frame", frame, "")->check(cli::IsMember({"ned", "enu"}));
    args.add_option("--need", need, "")->expected(1);
    const std::string error = Parse(app, c.argv);
    SCOPED_TRACE(c.argv.front() + (c.argv.size() > 1 ? " " + c.argv[1] : ""));
    EXPECT_EQ(error.empty(), c.accepted) << error;
    if (!c.accepted) {
      EXPECT_NE(error.find(c.argv.front()), std::string::npos) << error;
    }
  }
}

// An integer range describes itself as CLI11's Range<int> did in the commands' --help.
TEST(Cli, AnIntegerRangeReadsAsCli11sInHelp) {
  CLI::App app;
  Args args(app);
  int jobs = 1;
  double tau = 0.5;
  args.add_option("--jobs", jobs, "")->check(cli::Range(1, 64));
  args.add_option("--tau", tau, "")->check(cli::Range(0.0, 1.0));
  CLI::App reference;
  reference.add_option("--jobs", jobs, "")->check(CLI::Range(1, 64));
  reference.add_option("--tau", tau, "")->check(CLI::Range(0.0, 1.0));
  EXPECT_EQ(app.help(), reference.help());
  EXPECT_NE(app.help().find("[1 - 64]"), std::string::npos) << app.help();
}

TEST(Cli, RequiredDefaultsEachAndSubcommands) {
  CLI::App app;
  Args args(app);
  int seed = 7;
  std::string robot, out = "out/x";
  int given = 0;
  args.add_option("--seed", seed, "random seed")->capture_default_str();
  args.add_option("--robot", robot, "")->required();
  Args* paper = args.add_subcommand("paper", "the paper's experiment");
  args.require_subcommand(1);
  paper->add_option("--out", out, "")->default_str("out/x")->each([&](const std::string&) {
    ++given;
  });
  EXPECT_NE(app.help().find("INT=7"), std::string::npos) << app.help();  // the captured default
  EXPECT_NE(Parse(app, {"paper"}).find("--robot"), std::string::npos);
  CLI::App app2;
  Args args2(app2);
  args2.add_option("--robot", robot, "")->required();
  Args* sub = args2.add_subcommand("paper", "");
  args2.require_subcommand(1);
  sub->add_option("--out", out, "")->each([&](const std::string&) { ++given; });
  ASSERT_EQ(Parse(app2, {"--robot", "r.yaml", "paper", "--out", "o"}), "");
  EXPECT_EQ(robot, "r.yaml");
  EXPECT_EQ(out, "o");
  EXPECT_EQ(given, 1);
  EXPECT_EQ(sub->count("--out"), 1u);
  EXPECT_EQ(args2.count("--robot"), 1u);
  CLI::App app3;
  Args args3(app3);
  args3.add_subcommand("paper", "");
  args3.require_subcommand(1);
  EXPECT_NE(Parse(app3, {}), "");  // a subcommand is required
}

}  // namespace
}  // namespace rcal::tool
