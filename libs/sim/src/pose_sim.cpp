#include "rcal/sim/pose_sim.hpp"

#include <algorithm>
#include <numbers>
#include <string>

#include "rcal/geometry/so3.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::sim {

Eigen::VectorXd Table3Errors(const kinematics::KinematicModel& model) {
  // Du, Zhang, Li 2014, Table 3 (EKF row), joints 1–6.
  constexpr double kDa[6] = {3.596, 3.945, 2.545, 2.957, 2.425, 2.636};           // mm
  constexpr double kDalpha[6] = {-0.589, -0.234, -1.296, -0.385, -0.424, 0.654};  // deg
  constexpr double kDd[6] = {3.157, 3.321, 3.598, 3.475, 3.235, 2.474};           // mm
  constexpr double kDtheta[6] = {2.385, -0.838, 0.454, 0.168, -0.325, -0.368};    // deg
  constexpr double kDeg = std::numbers::pi / 180.0;
  Eigen::VectorXd x = model.Nominal();
  for (int j = 0; j < 6; ++j) {
    const std::string n = std::to_string(j + 1);
    const auto set = [&](const std::string& name, double v) {
      const int i = model.FindParameter(name);
      if (i >= 0) x(i) = v;
    };
    set("a" + n, kDa[j] * 1e-3);
    set("alpha" + n, kDalpha[j] * kDeg);
    set("d" + n, kDd[j] * 1e-3);
    set("theta" + n, kDtheta[j] * kDeg);
  }
  return x;
}

Eigen::VectorXd RandomErrors(const kinematics::KinematicModel& model, Rng& rng, double sigma_length,
                             double sigma_angle) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd x(model.num_params());
  for (int i = 0; i < model.num_params(); ++i)
    x(i) = n(rng) * (model.parameters()[i].is_angle ? sigma_angle : sigma_length);
  return x;
}

std::vector<Eigen::VectorXd> SampleJoints(const kinematics::KinematicModel& model, int count,
                                          Rng& rng, double margin) {
  return kinematics::SampleJointsInLimits(model, count, rng, margin);
}

kinematics::PoseMeasurement MeasurePose(const kinematics::KinematicModel& model,
                                        const Eigen::VectorXd& x_true, const Eigen::VectorXd& q,
                                        const PoseNoise& noise, Rng& rng) {
  return MeasureTruePose(model.Forward(q, x_true), q, noise, rng);
}

kinematics::PoseMeasurement MeasureTruePose(const kinematics::ToolPose& truth,
                                            const Eigen::VectorXd& q, const PoseNoise& noise,
                                            Rng& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  kinematics::PoseMeasurement m;
  m.q = q;
  m.p_WM_W = truth.p_WM_W + noise.position_sigma * Draw3(n, rng);
  m.has_orientation = noise.orientation;
  const int dim = noise.orientation ? 6 : 3;
  m.covariance = Eigen::MatrixXd::Zero(dim, dim);
  m.covariance.topLeftCorner<3, 3>().diagonal().setConstant(noise.position_sigma *
                                                            noise.position_sigma);
  if (noise.orientation) {
    const Eigen::Vector3d dtheta = noise.orientation_sigma * Draw3(n, rng);
    m.R_EI = geometry::Exp(dtheta) * truth.R_EI;  // left error, earth frame (measurement.hpp)
    m.covariance.bottomRightCorner<3, 3>().diagonal().setConstant(noise.orientation_sigma *
                                                                  noise.orientation_sigma);
  }
  return m;
}

std::vector<kinematics::PoseMeasurement> MeasurePoses(const kinematics::KinematicModel& model,
                                                      const Eigen::VectorXd& x_true,
                                                      const std::vector<Eigen::VectorXd>& qs,
                                                      const PoseNoise& noise, Rng& rng) {
  std::vector<kinematics::PoseMeasurement> out;
  out.reserve(qs.size());
  for (const auto& q : qs) out.push_back(MeasurePose(model, x_true, q, noise, rng));
  return out;
}

std::vector<kinematics::PoseMeasurement> MeasureMarkers(const kinematics::KinematicModel& model,
                                                        const Eigen::VectorXd& x_true,
                                                        const std::vector<Eigen::VectorXd>& qs,
                                                        const PoseNoise& noise, Rng& rng) {
  const int slots = std::max<int>(1, static_cast<int>(model.markers().size()));
  std::vector<kinematics::PoseMeasurement> ms;
  ms.reserve(qs.size() * slots);
  for (const auto& q : qs)
    for (int k = 0; k < slots; ++k) {
      ms.push_back(MeasurePose(model.ForMarker(k), x_true, q, noise, rng));
      ms.back().marker = k;
    }
  return ms;
}

}  // namespace rcal::sim
