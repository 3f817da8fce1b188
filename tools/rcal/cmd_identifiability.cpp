// rcal identifiability: which parameter errors of a robot a pose set can identify, and why not
// the others.
#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>
#include <sstream>

#include "command.hpp"
#include "rcal/io/atomic_file.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::tool {
namespace {

struct Options {
  std::string robot = "config/robots/grb3016.yaml";
  bool position_only = false;
  std::vector<double> tool;  // a [m], alpha [rad], d [m], theta [rad]
  int poses = 100;
  unsigned seed = 1;
  std::string json_path;
};

int Run(const Options& o) {
  io::LoadedRobot robot = io::LoadRobot(ResolvePath(o.robot));
  if (!o.tool.empty()) {
    if (o.tool.size() != 4) throw std::runtime_error("--tool: expected a,alpha,d,theta");
    robot.spec.tool = io::ToolSpec{o.tool[0], o.tool[1], o.tool[2], o.tool[3], true};
    robot.model = io::BuildModel(robot.spec);
  }
  const auto& model = robot.model;
  sim::Rng rng(o.seed);
  const auto kind = o.position_only ? kinematics::MeasurementKind::kPositionOnly
                                    : kinematics::MeasurementKind::kFullPose;
  const auto r = kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, o.poses, rng),
                                                    model.Nominal(), kind);
  std::printf("%s: %d parameters, %s, %d random poses inside the limits\n", model.name().c_str(),
              model.num_params(), o.position_only ? "positions only" : "full poses", o.poses);
  std::printf("rank %d of %d; condition number of the base set %.1f\n", r.rank, r.num_params,
              r.condition_number);
  std::printf("not identifiable (%zu):\n", r.unidentifiable.size());
  for (const auto& c : r.unidentifiable)
    std::printf("  - %s  [%s fixed at nominal]\n", c.explanation.c_str(),
                model.parameters()[c.dropped].name.c_str());
  std::printf("base parameter set (%zu):", r.identifiable.size());
  for (int i : r.identifiable) std::printf(" %s", model.parameters()[i].name.c_str());
  std::printf("\n");
  if (!o.json_path.empty()) {
    nlohmann::json j;
    j["robot"] = model.name();
    j["num_params"] = r.num_params;
    j["rank"] = r.rank;
    j["position_only"] = o.position_only;
    j["condition_number"] = r.condition_number;
    j["singular_values"] = std::vector<double>(r.singular_values.data(),
                                               r.singular_values.data() + r.singular_values.size());
    for (int i : r.identifiable) j["identifiable"].push_back(model.parameters()[i].name);
    j["unidentifiable"] = nlohmann::json::array();
    for (const auto& c : r.unidentifiable) {
      nlohmann::json u;
      u["dropped"] = model.parameters()[c.dropped].name;
      u["explanation"] = c.explanation;
      for (size_t k = 0; k < c.params.size(); ++k)
        u["direction"][model.parameters()[c.params[k]].name] = c.direction[k];
      j["unidentifiable"].push_back(u);
    }
    io::AtomicWriteFile(o.json_path, j.dump(2));
  }
  return 0;
}

const RegisterCommand kIdentifiability(
    "identifiability", "Rank, unidentifiable combinations and base parameters of a robot",
    [](CLI::App& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->capture_default_str();
      sub.add_flag("--position-only", o->position_only, "positions only (laser tracker)");
      sub.add_option("--tool", o->tool, "D–H tool a,alpha,d,theta [m, rad] (replaces the file's)")
          ->delimiter(',')
          ->expected(4);
      sub.add_option("--poses", o->poses, "random poses")->capture_default_str();
      sub.add_option("--seed", o->seed, "random seed")->capture_default_str();
      sub.add_option("--json", o->json_path, "also write the figures here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
