#include "calibration_sweep.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "rcal/geometry/so3.hpp"
#include "rcal/identification/batch_lm.hpp"
#include "rcal/identification/calibration.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/kinematics/identifiability.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/sim/draw.hpp"
#include "rcal/sim/pose_sim.hpp"

namespace rcal::tool {
namespace {

constexpr double kPi = std::numbers::pi;

// SplitMix64's finaliser: a bijection of 64-bit words that mixes every bit.
std::uint64_t Mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// A rotation uniform on SO(3) (a normalised Gaussian quaternion) as roll, pitch, yaw.
Eigen::Vector3d RandomRpy(sim::Rng& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Vector4d q = sim::Draw4(n, rng);
  return geometry::ToRpy(geometry::QuatToMatrix(q));
}

// The truth: geometric errors on the arm's parameters, and set-up frames as a real cell has them
// (the set-up parameters hold the whole frame, so the drawn value minus the nominal).
Eigen::VectorXd DrawTruth(const kinematics::KinematicModel& model,
                          const CalibrationSweepSettings& s, sim::Rng& rng) {
  Eigen::VectorXd x =
      sim::RandomErrors(model, rng, s.length_error_sigma_m, s.angle_error_sigma_rad);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto in = [&](double lo, double hi) { return lo + (hi - lo) * u(rng); };
  // World ← base: 1–3 m away in any direction of the floor, ±0.5 m in height, any yaw, up to
  // ±0.1 rad of tilt (a sensor not levelled with the robot).
  const double bearing = in(-kPi, kPi), distance = in(1.0, 3.0);
  const Eigen::Vector3d p_WB(distance * std::cos(bearing), distance * std::sin(bearing),
                             in(-0.5, 0.5));
  const Eigen::Vector3d rpy_WB(in(-0.1, 0.1), in(-0.1, 0.1), in(-kPi, kPi));
  // Flange → marker: 5–15 cm in any direction.
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Vector3d p_FM = sim::Draw3(n, rng).normalized() * in(0.05, 0.15);
  // Flange → IMU and earth ← world: any rotation.
  const Eigen::Vector3d rpy_FI = RandomRpy(rng), rpy_EW = RandomRpy(rng);
  const auto set = [&](const char* name, double value) {
    const int i = model.FindParameter(name);
    if (i >= 0) x(i) = value - model.parameters()[i].nominal;
  };
  const char* xyz[3] = {"x", "y", "z"};
  const char* rzyx[3] = {"rz", "ry", "rx"};  // yaw, pitch, roll: rpy(2), rpy(1), rpy(0)
  for (int k = 0; k < 3; ++k) {
    set((std::string("base_") + xyz[k]).c_str(), p_WB(k));
    set((std::string("marker_") + xyz[k]).c_str(), p_FM(k));
    set((std::string("base_") + rzyx[k]).c_str(), rpy_WB(2 - k));
    set((std::string("imu_") + rzyx[k]).c_str(), rpy_FI(2 - k));
    set((std::string("earth_") + rzyx[k]).c_str(), rpy_EW(2 - k));
  }
  return x;
}

}  // namespace

std::uint64_t CalibrationSeed(std::string_view robot, bool position_only, unsigned seed_index) {
  std::uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a of the name
  for (unsigned char c : robot) h = (h ^ c) * 0x100000001b3ull;
  h = Mix(h ^ (position_only ? 0x706f73ull : 0x66756cull));  // "pos" / "ful"
  return Mix(h ^ seed_index);
}

SweepCell MakeSweepCell(const kinematics::KinematicModel& model, std::string_view robot_name,
                        const CalibrationSweepSettings& s, unsigned seed_index) {
  SweepCell c;
  c.seed = CalibrationSeed(robot_name, s.position_only, seed_index);
  sim::Rng rng(c.seed);
  c.x_true = DrawTruth(model, s, rng);
  c.cal_q = sim::SampleJoints(model, s.poses, rng);
  c.test_q = sim::SampleJoints(model, s.test_poses, rng);
  sim::PoseNoise noise;
  noise.position_sigma = s.position_sigma_m;
  noise.orientation_sigma = s.orientation_sigma_rad;
  noise.orientation = !s.position_only;
  c.measured = sim::MeasurePoses(model, c.x_true, c.cal_q, noise, rng);
  return c;
}

CalibrationSeedResult RunCalibrationSeed(const kinematics::KinematicModel& model,
                                         std::string_view robot_name,
                                         const CalibrationSweepSettings& s, unsigned seed_index) {
  const SweepCell cell = MakeSweepCell(model, robot_name, s, seed_index);
  const Eigen::VectorXd& x_true = cell.x_true;
  const auto& cal_q = cell.cal_q;
  const auto& test_q = cell.test_q;
  const auto& measured = cell.measured;
  CalibrationSeedResult r;
  r.seed_index = seed_index;
  r.seed = cell.seed;
  r.num_params = model.num_params();

  const auto kind = s.position_only ? kinematics::MeasurementKind::kPositionOnly
                                    : kinematics::MeasurementKind::kFullPose;
  const kinematics::IdentifiabilityReport truth =
      kinematics::AnalyzeIdentifiability(model, cal_q, x_true, kind);
  r.rank_at_truth = truth.rank;
  const auto& sv = truth.singular_values;
  if (truth.rank > 0) r.last_kept_singular_value = sv(truth.rank - 1) / sv(0);
  if (truth.rank < sv.size()) r.first_dropped_singular_value = sv(truth.rank) / sv(0);

  double ss_p = 0, ss_o = 0;
  for (const auto& m : measured) {
    const Eigen::VectorXd e = kinematics::Residual(model, m, x_true);
    ss_p += e.head<3>().squaredNorm();
    if (m.has_orientation) ss_o += e.tail<3>().squaredNorm();
  }
  const double n_axes = 3.0 * static_cast<double>(measured.size());
  r.realized_position_noise_ratio = std::sqrt(ss_p / n_axes) / s.position_sigma_m;
  if (!s.position_only)
    r.realized_orientation_noise_ratio = std::sqrt(ss_o / n_axes) / s.orientation_sigma_rad;

  // The user does not know the noise: Calibrate starts from a wrong one and estimates it.
  auto ms = measured;
  identification::SetNoise(ms, s.start_noise_factor * s.position_sigma_m,
                           s.position_only ? 0.0 : s.start_noise_factor * s.orientation_sigma_rad);
  const double t0 = ThreadCpuSeconds();
  const identification::CalibrationFit fit = identification::Calibrate(model, ms);
  r.seconds = ThreadCpuSeconds() - t0;
  r.identified = static_cast<int>(fit.identified.size());
  r.lm_iterations = fit.iterations;
  r.cost = fit.cost;
  const auto setup = identification::SetupParameters(model);
  double xx = 0;
  for (int i = 0; i < model.num_params(); ++i)
    if (std::find(setup.begin(), setup.end(), i) == setup.end()) xx += fit.x(i) * fit.x(i);
  r.x_norm = std::sqrt(xx);
  r.position_noise_ratio = fit.position_sigma_m / s.position_sigma_m;
  if (!s.position_only)
    r.orientation_noise_ratio = fit.orientation_sigma_rad / s.orientation_sigma_rad;

  // Judged on poses never fitted, against the truth; the Cramér–Rao prediction is the error an
  // efficient estimator of the identified set has there, with the true noise, at the truth.
  const auto e = identification::ErrorsAgainstTruth(model, fit.x, x_true, test_q);
  r.test_position_m = e.mean_position_m;
  r.test_orientation_rad = e.mean_orientation_rad;
  const Eigen::MatrixXd C = identification::CramerRaoBound(model, fit.identified, measured, x_true);
  const auto [cr_p, cr_o] = identification::PredictedMeanErrors(
      model, fit.identified, C, x_true, test_q, static_cast<unsigned>(r.seed >> 32));
  r.cr_position_m = cr_p;
  r.position_ratio = e.mean_position_m / cr_p;
  if (!s.position_only) {
    r.cr_orientation_rad = cr_o;
    r.orientation_ratio = e.mean_orientation_rad / cr_o;
  }
  return r;
}

RatioSummary SummarizeRatios(std::vector<double> v) {
  std::erase_if(v, [](double x) { return !std::isfinite(x); });
  RatioSummary s;
  s.n = static_cast<int>(v.size());
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  const double h = 0.5 * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(h)), hi = std::min(lo + 1, v.size() - 1);
  s.median = v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
  s.min = v.front();
  s.max = v.back();
  return s;
}

}  // namespace rcal::tool
