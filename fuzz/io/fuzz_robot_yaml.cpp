// Robot YAML (io/robot_yaml.hpp): parse, build the model, write and read back.
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/robot_yaml.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] {
    const rcal::io::RobotSpec spec = rcal::io::ParseRobotYaml(text, "fuzz.yaml");
    const rcal::kinematics::KinematicModel model = rcal::io::BuildModel(spec);
    (void)rcal::io::ParseRobotYaml(rcal::io::RobotYamlText(spec), "again.yaml");
    (void)model.Forward(Eigen::VectorXd::Zero(model.num_joints()), model.Nominal());
  });
  return 0;
}
