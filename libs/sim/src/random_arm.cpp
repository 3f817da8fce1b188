#include "rcal/sim/random_arm.hpp"

#include <numbers>
#include <random>
#include <string>

namespace rcal::sim {

kinematics::KinematicModel RandomDhArm(std::uint64_t seed, const RandomArmSettings& s) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  constexpr double kHalfPi = std::numbers::pi / 2;
  kinematics::ModelBuilder b("random_dh_" + std::to_string(seed));
  b.BaseFrame(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
  for (int i = 0; i < s.joints; ++i) {
    const double alpha =
        (i > 0 && u(rng) < s.parallel_share) ? 0.0 : (u(rng) < 0.5 ? -kHalfPi : kHalfPi);
    const double a = u(rng) < 0.3 ? 0.0 : 0.05 + (s.max_a - 0.05) * u(rng);
    const double d = u(rng) < 0.4 ? 0.0 : 0.05 + (s.max_d - 0.05) * u(rng);
    const double range = s.min_range + (s.max_range - s.min_range) * u(rng);
    kinematics::Joint joint;
    joint.name = std::to_string(i + 1);
    joint.name.insert(0, 1, 'j');  // (GCC 12's -Wrestrict misfires on "j" + std::string)
    joint.lower = -range;
    joint.upper = range;
    // d of a link whose next axis is parallel cannot be told from the next link's d: Hayati's β.
    const bool hayati = alpha == 0.0 && i + 1 < s.joints;
    b.DhLink(a, alpha, hayati ? 0.0 : d, 0.0, joint, hayati);
  }
  b.MarkerOffset(Eigen::Vector3d(0.05, 0.0, 0.1));
  if (s.imu_frame) b.ImuMounting(Eigen::Vector3d::Zero());
  return b.Build();
}

}  // namespace rcal::sim
