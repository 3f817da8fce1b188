// URDF (io/robot_urdf.hpp): parse through tinyxml and liburdfdom, walk to the tip, build the
// model, and write a calibrated URDF back.
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/robot_urdf.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] {
    // With the set-up frames a cell adds, so the calibrated URDF's fixed joints are written too.
    rcal::io::UrdfOptions options;
    options.add_base_frame = true;
    options.add_marker = true;
    const rcal::io::RobotSpec spec = rcal::io::ParseUrdfRobotSpec(text, "fuzz.urdf", options);
    const rcal::kinematics::KinematicModel model = rcal::io::BuildModel(spec);
    (void)model.Forward(Eigen::VectorXd::Zero(model.num_joints()), model.Nominal());
    (void)rcal::io::CalibratedUrdfText(text, "fuzz.urdf", spec, model,
                                       Eigen::VectorXd::Constant(model.num_params(), 1e-3));
  });
  return 0;
}
