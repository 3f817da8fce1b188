// The GRB3016 from config/, its identifiable base set and simulated measurements (Table 3 truth).
#pragma once

#include <cmath>
#include <memory>
#include <vector>

#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/transport/adapters.hpp"

namespace rcal::transport::testing {

struct Grb3016 {
  kinematics::KinematicModel model;
  std::vector<int> base;
  Eigen::VectorXd x_true;
  std::vector<kinematics::PoseMeasurement> poses;

  explicit Grb3016(int num_poses, unsigned seed = 1) {
    model = io::LoadRobot(RCAL_SOURCE_DIR "/config/robots/grb3016.yaml").model;
    sim::Rng rng_id(seed * 1000 + 1), rng(seed * 1000 + 3);
    base =
        kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 200, rng_id),
                                           model.Nominal(), kinematics::MeasurementKind::kFullPose)
            .identifiable;
    x_true = sim::Table3Errors(model);
    poses = sim::MeasurePoses(model, x_true, sim::SampleJoints(model, num_poses, rng),
                              sim::PoseNoise{}, rng);
  }
};

/// A one-joint arm whose model has an earth frame (earth_rx, earth_ry, earth_rz), the identifier's
/// R_EW: what the filter nodes take the tracker's frame from.
inline std::shared_ptr<const kinematics::KinematicModel> OneJointWithEarthFrame() {
  kinematics::ModelBuilder b("earth");
  b.DhLink(0.15, -M_PI / 2, 0.25, 0.0, {"j1", kinematics::JointType::kRevolute, -3.0, 3.0})
      .MarkerOffset(Eigen::Vector3d(0.03, 0, 0.12))
      .EarthFrame(Eigen::Vector3d::Zero());
  return std::make_shared<const kinematics::KinematicModel>(b.Build());
}

/// Another robot's KINEMATIC_PARAMS (its own model id): not the cell's, ignored by the nodes.
inline kinematic_params_t ForeignParams() {
  kinematics::ModelBuilder b("other");
  b.DhLink(0.1, 0.0, 0.0, 0.0, {"j1", kinematics::JointType::kRevolute, -3.0, 3.0});
  const kinematics::KinematicModel other = b.Build();
  return ToKinematicParams(other, other.Nominal(), Eigen::VectorXd::Zero(other.num_params()), {},
                           "other-robot", 1'000'000, 3);
}

}  // namespace rcal::transport::testing
