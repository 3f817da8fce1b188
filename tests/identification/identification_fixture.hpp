// A calibration scenario with a known truth: the model, its base parameter set, true errors, the
// truth's exact equivalent on the base set, and calibration and test measurements.
#pragma once

#include <gtest/gtest.h>

#include "../kinematics/test_robots.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::identification::testing {

/// The real UR10 (FIGAROH, config/robots/ur10.urdf), loaded from its URDF, with the set-up a cell
/// has (world ← base frame and a marker offset, both identified).
inline kinematics::KinematicModel Ur10FromUrdf() {
  io::UrdfOptions o;
  o.tip_link = "wrist_3_link";
  o.add_base_frame = true;
  o.base_xyz = Eigen::Vector3d(0.3, -0.2, 0.1);
  o.add_marker = true;
  o.marker_xyz = Eigen::Vector3d(0.02, 0.05, 0.1);
  return io::LoadRobotUrdf(RCAL_SOURCE_DIR "/config/robots/ur10.urdf", o);
}

struct Scenario {
  kinematics::KinematicModel model;
  std::vector<int> identified;
  Eigen::VectorXd x_true;        ///< full truth (includes unidentifiable parts)
  Eigen::VectorXd x_equivalent;  ///< the base-set errors that reproduce the truth exactly
  std::vector<kinematics::PoseMeasurement> cal, test;
  std::vector<Eigen::VectorXd> test_q;
};

inline Scenario MakeScenario(const kinematics::KinematicModel& model, const sim::PoseNoise& noise,
                             unsigned seed, int num_cal = 50, double sigma_length = 0.003,
                             double sigma_angle = 0.005) {
  Scenario s;
  s.model = model;
  sim::Rng rng(seed);
  const auto kind = noise.orientation ? kinematics::MeasurementKind::kFullPose
                                      : kinematics::MeasurementKind::kPositionOnly;
  const auto report = kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 80, rng),
                                                         model.Nominal(), kind);
  s.identified = report.identifiable;
  s.x_true = sim::RandomErrors(model, rng, sigma_length, sigma_angle);
  // The truth's equivalent on the base set: fit noise-free poses (independent of the noise).
  sim::PoseNoise exact = noise;
  exact.position_sigma = 1e-9;
  exact.orientation_sigma = 1e-9;
  const auto dense =
      sim::MeasurePoses(model, s.x_true, sim::SampleJoints(model, 200, rng), exact, rng);
  const LmResult eq = BatchLm(model, s.identified).Solve(dense, model.Nominal());
  s.x_equivalent = eq.x;
  s.cal = sim::MeasurePoses(model, s.x_true, sim::SampleJoints(model, num_cal, rng), noise, rng);
  s.test_q = sim::SampleJoints(model, 50, rng);
  s.test = sim::MeasurePoses(model, s.x_true, s.test_q, noise, rng);
  return s;
}

/// The base set of `kind` measurements at 80 seeded joint samples, and a truth on it: random
/// errors (1 mm, 2 mrad σ) with the parameters outside the base set at 0, so that a step of an
/// identified parameter is a step of the identified state.
struct BaseSetTruth {
  std::vector<int> identified;
  Eigen::VectorXd x_true;
};
inline BaseSetTruth MakeBaseSetTruth(const kinematics::KinematicModel& model, sim::Rng& rng,
                                     kinematics::MeasurementKind kind) {
  const auto report = kinematics::AnalyzeIdentifiability(model, sim::SampleJoints(model, 80, rng),
                                                         model.Nominal(), kind);
  BaseSetTruth t{report.identifiable, sim::RandomErrors(model, rng, 0.001, 0.002)};
  for (const auto& c : report.unidentifiable) t.x_true(c.dropped) = 0;
  return t;
}

/// Mean distance [m] between the marker predicted with x and the truth over the test joints.
inline double MeanTestPositionError(const Scenario& s, const Eigen::VectorXd& x) {
  double sum = 0;
  for (const auto& q : s.test_q)
    sum += (s.model.Forward(q, x).p_WM_W - s.model.Forward(q, s.x_true).p_WM_W).norm();
  return sum / s.test_q.size();
}

/// The mean test position error the noise allows: E|Jₚ δx| with δx ~ N(0, CRB), by seeded
/// sampling.
inline double CramerRaoMeanTestPositionError(const Scenario& s) {
  const Eigen::MatrixXd C = CramerRaoBound(s.model, s.identified, s.cal, s.x_true);
  const Eigen::MatrixXd L = C.llt().matrixL();
  sim::Rng rng(99);
  std::normal_distribution<double> n(0.0, 1.0);
  double sum = 0;
  int count = 0;
  Eigen::MatrixXd J(6, s.model.num_params());
  for (const auto& q : s.test_q) {
    s.model.IdentificationJacobian(q, s.x_true, J);
    for (int k = 0; k < 200; ++k) {
      Eigen::VectorXd z(L.rows());
      for (int i = 0; i < z.size(); ++i) z(i) = n(rng);
      const Eigen::VectorXd dx = L * z;
      Eigen::Vector3d dp = Eigen::Vector3d::Zero();
      for (size_t i = 0; i < s.identified.size(); ++i)
        dp += J.block<3, 1>(0, s.identified[i]) * dx(i);
      sum += dp.norm();
      ++count;
    }
  }
  return sum / count;
}

}  // namespace rcal::identification::testing
