// Truth robots with non-geometric effects: every pose-level cause of the issue-6 vocabulary
// (kinematics/joint_effects.hpp) as a switchable effect with its parameters, the conditions a pose
// is taken under (temperature, payload, approach direction, time), and measurements of the
// effected robot. `time_offset` belongs to streamed data and is not a pose-level effect.
// Every function that draws takes the generator explicitly: callers seed it.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::sim {

/// One truth effect and its parameter values [SI, see joint_effects.hpp].
struct TruthEffect {
  kinematics::Effect effect;
  Eigen::VectorXd values;  ///< size effect.num_params()
};

/// Parses a command-line effect, `CAUSE[:JOINT][:OPTION]=V[,V]`:
///   joint_compliance:j2=2e-6          c [rad/(N·m)] of joint 2 (1-based, or the joint's name)
///   joint_periodic:j3=1e-4[,5e-5]     sin, cos amplitude [rad] of the 1st harmonic
///   joint_periodic:j3:h2=1e-4,0       of the 2nd harmonic
///   joint_scale:j4=2e-4               scale error [1]
///   backlash:j5=5e-5                  half dead band [rad]
///   thermal=1.2e-5                    κ [1/K] on temperature (T_ref 20 °C)
///   thermal:time=3e-9                 ρ [1/s] drift with time (t_ref 0 s)
/// Throws std::invalid_argument with the reason (unknown cause or joint, wrong value count;
/// time_offset: "streamed data only").
TruthEffect ParseEffectSpec(const std::string& text, const kinematics::KinematicModel& model);

/// A joint offset that steps while the arm works (see JointOffsetStep), as a command line gives
/// it: `JOINT=DELTA@STOP`, e.g. `j2=1e-3@25` (JOINT j1..jN or the joint's name, DELTA [rad | m],
/// STOP the 1-based calibration stop from whose approach on the joint reads off).
struct JointOffsetStepSpec {
  int joint = 0;  ///< 0-based
  double delta = 0.0;
  int stop = 1;
};
/// Parses `JOINT=DELTA@STOP`. Throws std::invalid_argument naming the text and what is wrong
/// (no joint of that name, a DELTA that is not a finite number or beyond 0.1 rad | m, STOP < 1).
JointOffsetStepSpec ParseJointOffsetStep(const std::string& text,
                                         const kinematics::KinematicModel& model);

/// The extended truth model and its effect vector for a list of truth effects.
struct EffectTruth {
  kinematics::ExtendedModel model;
  Eigen::VectorXd e;  ///< effect parameters in model order [SI]
};
EffectTruth MakeEffectTruth(const kinematics::KinematicModel& model,
                            const std::vector<TruthEffect>& effects,
                            const kinematics::GravityModel& gravity = {});

/// The conditions of a measuring session. Poses are taken in the order given, equally spaced in
/// time over `session_s`; the temperature warms up as T(t) = T₀ + ΔT (1 − exp(−t/τ)) plus
/// Gaussian noise, so it is not a linear function of time.
struct SessionSettings {
  double session_s = 7200.0;                        ///< [s] duration of the session
  double temperature_start_c = 20.0;                ///< T₀ [°C]
  double temperature_rise_c = 12.0;                 ///< ΔT [K]
  double warmup_time_constant_s = 2400.0;           ///< τ [s]
  double temperature_noise_c = 0.3;                 ///< [K] 1σ
  std::vector<double> payloads_kg{0.0, 5.0, 10.0};  ///< drawn uniformly per pose [kg]
  bool random_approach = true;  ///< dq sign drawn ±1 per joint and pose; false: all +1
};

/// The session's warm-up curve without its noise: T₀ + ΔT (1 − exp(−t/τ)) [°C] at t_s [s].
double WarmedTo(const SessionSettings& settings, double t_s);

/// The contexts of `count` poses of an arm with `num_joints` joints (all fields filled).
std::vector<kinematics::EffectContext> SampleSession(int num_joints, int count,
                                                     const SessionSettings& settings, Rng& rng);

/// The conditions at one stop of a running cell (a live simulator's context, stop by stop): t_s
/// [s] since the run started (time_s), the temperature warming up as `settings` says at t_s (plus
/// its noise), a payload drawn from settings.payloads_kg, and the approach direction
/// sign(q − q_before) per joint (0 where the joint did not move; all 0 when q_before is empty).
/// Draws the same two numbers from rng at every call (a resumed run fast-forwards by calling it).
kinematics::EffectContext StopContext(double t_s, const Eigen::VectorXd& q,
                                      const Eigen::VectorXd& q_before,
                                      const SessionSettings& settings, Rng& rng);

/// What the truth robot (geometric errors x_true, effects `truth`) reaches at joints q as read
/// under `ctx`, measured with `noise` (measurement carries the noise covariance).
kinematics::PoseMeasurement MeasurePoseWithEffects(const EffectTruth& truth,
                                                   const Eigen::VectorXd& x_true,
                                                   const Eigen::VectorXd& q,
                                                   const kinematics::EffectContext& ctx,
                                                   const PoseNoise& noise, Rng& rng);

/// Every marker of the truth's model measured at each pose (for each pose one measurement per
/// marker slot, in slot order, PoseMeasurement::marker the slot; one per pose with one marker).
std::vector<kinematics::PoseMeasurement> MeasurePosesWithEffects(
    const EffectTruth& truth, const Eigen::VectorXd& x_true, const std::vector<Eigen::VectorXd>& qs,
    const std::vector<kinematics::EffectContext>& contexts, const PoseNoise& noise, Rng& rng);

}  // namespace rcal::sim

namespace rcal::sim {

/// The values of `effect` that displace the marker by `rms_m` [m] RMS over the poses (joints qs,
/// contexts, geometric errors x), in a seeded random direction for two-parameter effects (the
/// phase of a periodic error) and a seeded random sign. For detection tests "near the noise
/// floor": rms_m a small multiple of the position noise. With `beyond_geometry`, the size is
/// that of the part of the displacement no change of the geometric parameters can reproduce at
/// these poses (least-squares residual of the displacements against the identification
/// Jacobian's position rows): the part a calibration could ever see.
TruthEffect EffectOfSize(const kinematics::KinematicModel& model, const kinematics::Effect& effect,
                         const std::vector<Eigen::VectorXd>& qs,
                         const std::vector<kinematics::EffectContext>& contexts,
                         const Eigen::VectorXd& x, double rms_m, Rng& rng,
                         const kinematics::GravityModel& gravity = {},
                         bool beyond_geometry = false);

}  // namespace rcal::sim
