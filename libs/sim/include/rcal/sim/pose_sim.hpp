// Pose-level simulation: a truth robot (the nominal model plus parameter errors), joint
// configurations sampled inside the limits, and still-pose measurements with Gaussian noise.
// Every function that draws takes the generator explicitly: callers seed it.
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "rcal/kinematics/measurement.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::sim {

using Rng = std::mt19937_64;

/// The paper's Table 3 (identified errors of the GRB3016, Δa, Δd [mm], Δα, Δθ [deg]) as an error
/// vector for a model with D–H links 1–6 (parameters a1…theta6); SI units. Other parameters 0.
Eigen::VectorXd Table3Errors(const kinematics::KinematicModel& model);

/// Independent Gaussian errors: σ [m] for lengths, σ [rad] for angles.
Eigen::VectorXd RandomErrors(const kinematics::KinematicModel& model, Rng& rng, double sigma_length,
                             double sigma_angle);

/// `count` joint vectors uniform inside the limits shrunk by `margin` (a fraction of each range
/// kept free at both ends).
std::vector<Eigen::VectorXd> SampleJoints(const kinematics::KinematicModel& model, int count,
                                          Rng& rng, double margin = 0.05);

struct PoseNoise {
  double position_sigma = 5e-5;         ///< [m] per axis (0.05 mm)
  double orientation_sigma = 1.745e-3;  ///< [rad] per axis (0.1°)
  bool orientation = true;              ///< false: position-only measurements (laser tracker)
};

/// A measurement of the known true pose `truth` taken at joints q, with `noise` (position per
/// axis, orientation as a left rotation error in the earth frame); it carries the noise's
/// covariance. Every truth model (geometric or with effects) measures through this.
kinematics::PoseMeasurement MeasureTruePose(const kinematics::ToolPose& truth,
                                            const Eigen::VectorXd& q, const PoseNoise& noise,
                                            Rng& rng);

/// The pose the truth robot (model at errors x_true) reaches at q, measured with `noise`; the
/// measurement carries the noise's covariance.
kinematics::PoseMeasurement MeasurePose(const kinematics::KinematicModel& model,
                                        const Eigen::VectorXd& x_true, const Eigen::VectorXd& q,
                                        const PoseNoise& noise, Rng& rng);

/// MeasurePose at every q.
std::vector<kinematics::PoseMeasurement> MeasurePoses(const kinematics::KinematicModel& model,
                                                      const Eigen::VectorXd& x_true,
                                                      const std::vector<Eigen::VectorXd>& qs,
                                                      const PoseNoise& noise, Rng& rng);

/// Every marker of the model (KinematicModel::markers()) measured at each joint vector, as a
/// tracker measuring several reflectors on the tool at one stop: for each q, one measurement per
/// marker slot in slot order (PoseMeasurement::marker = the slot), each with its own noise.
std::vector<kinematics::PoseMeasurement> MeasureMarkers(const kinematics::KinematicModel& model,
                                                        const Eigen::VectorXd& x_true,
                                                        const std::vector<Eigen::VectorXd>& qs,
                                                        const PoseNoise& noise, Rng& rng);

}  // namespace rcal::sim
