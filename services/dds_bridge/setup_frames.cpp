// Set-up frames as tf2 transforms (see include/rcal/dds/setup_frames.hpp).
#include "rcal/dds/setup_frames.hpp"

#include "rcal/geometry/so3.hpp"

namespace rcal::dds {
namespace {

NamedTransform Named(const std::string& parent, const std::string& child, const Eigen::Vector3d& p,
                     const Eigen::Matrix3d& R) {
  NamedTransform t;
  t.parent = parent;
  t.child = child;
  t.p_PC_P = p;
  t.q_PC = Eigen::Quaterniond(R).normalized();
  return t;
}

}  // namespace

std::vector<NamedTransform> SetupTransforms(const io::RobotSpec& c, const std::string& prefix) {
  std::vector<NamedTransform> out;
  const std::string world = prefix + "world";
  if (c.base) out.push_back(Named(world, c.base_link, c.base->xyz, geometry::FromRpy(c.base->rpy)));
  if (c.earth)
    out.push_back(Named(world, prefix + "earth", Eigen::Vector3d::Zero(),
                        geometry::FromRpy(c.earth->rpy).transpose()));
  for (const io::MarkerSpec& m : c.markers)
    out.push_back(Named(
        c.tip_link, prefix + (m.id == 0 ? std::string("marker") : "marker_" + std::to_string(m.id)),
        m.xyz, Eigen::Matrix3d::Identity()));
  if (c.imu)
    out.push_back(
        Named(c.tip_link, prefix + "imu", Eigen::Vector3d::Zero(), geometry::FromRpy(c.imu->rpy)));
  return out;
}

}  // namespace rcal::dds
