// The GRB3016 from config/, its identifiable base set and simulated measurements (Table 3 truth).
#pragma once

#include <vector>

#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"

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

}  // namespace rcal::transport::testing
