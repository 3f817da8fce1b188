// The calibration record of `rcal export --calibration` (io/calibration_export.hpp): parse it,
// rebuild its model, map its parameters by name, and write and check the URDF it exports.
#include <cstdint>

#include "fuzz_common.hpp"
#include "rcal/io/calibration_export.hpp"
#include "rcal/io/robot_urdf.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text = rcal::fuzz::Text(data, size);
  rcal::fuzz::Refusing([&] {
    const rcal::io::CalibrationRecord r = rcal::io::ParseCalibrationRecord(text, "fuzz.json");
    const rcal::kinematics::KinematicModel model = rcal::io::BuildModel(r.spec);
    const rcal::io::ModelParameters p =
        rcal::io::ParametersByName(model, r.names, r.values, r.sigmas, "fuzz.json: parameters");
    (void)rcal::io::CalibrationHash(model, p.x);
    const std::string urdf = rcal::io::RobotDescriptionUrdf(r.spec, model, p.x);
    rcal::io::ParityOptions o;
    o.samples = 3;  // the parser's paths, not the statistics
    (void)rcal::io::CheckUrdfParity(urdf, r.spec, model, p.x, o);
  });
  return 0;
}
