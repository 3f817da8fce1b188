// What `rcal fuse` and `rcal fuse-loo --ins` share: the position sensor simulated from a BROAD
// trial's truth, and one step of the tracker-aided INS (aided_ins.hpp) fed by the orientation KF.
// Both draw the same samples in the same order, so fuse-loo's in-sample figures are fuse's.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <random>

#include "rcal/estimation/aided_ins.hpp"
#include "rcal/estimation/orientation_kf.hpp"
#include "rcal/sim/draw.hpp"

namespace rcal::tool {

/// The simulated tracker: one sample every 1/rate_hz [s] on the grid of the first finite truth
/// position, the truth plus white noise of noise_m [m] per axis from a generator seeded with seed.
/// Occluded (occlusion_length_s > 0): silent over the first occlusion_length_s of every
/// occlusion_period_s of the trial's time [s]; the samples it would have given are drawn and
/// dropped, so every other sample is the unoccluded tracker's.
class BroadTracker {
 public:
  BroadTracker(double rate_hz, double noise_m, std::uint64_t seed, double occlusion_period_s = 0.0,
               double occlusion_length_s = 0.0)
      : rng_(seed),
        noise_(0.0, noise_m),
        period_(1.0 / rate_hz),
        occlusion_period_(occlusion_period_s),
        occlusion_length_(occlusion_length_s) {}
  /// The sample at t [s] if one is due, the truth p_truth [m] is finite and the marker not
  /// occluded.
  std::optional<Eigen::Vector3d> Sample(double t, const Eigen::Vector3d& p_truth) {
    if (!(t >= next_t_ - 1e-9) || !p_truth.allFinite()) return std::nullopt;
    next_t_ = (std::isfinite(next_t_) ? next_t_ : t) + period_;
    const Eigen::Vector3d p = p_truth + sim::Draw3(noise_, rng_);
    if (occlusion_length_ > 0.0 && std::fmod(t, occlusion_period_) < occlusion_length_)
      return std::nullopt;
    return p;
  }

 private:
  std::mt19937_64 rng_;
  std::normal_distribution<double> noise_;
  double period_;
  double occlusion_period_, occlusion_length_;
  double next_t_ = -std::numeric_limits<double>::infinity();
};

/// One IMU sample into the INS after the orientation KF has taken it
/// (estimation::StepAfterOrientationKf: what the aided_ins process runs) and the tracker's sample
/// if there is one, at the IMU's time.
inline void StepAidedIns(estimation::AidedIns& ins, const estimation::OrientationKf& okf, double t,
                         const Eigen::Vector3d& gyro_B, const Eigen::Vector3d& f_B,
                         bool heading_from_kf, const std::optional<Eigen::Vector3d>& p_WM_W) {
  if (!estimation::StepAfterOrientationKf(ins, okf, t, gyro_B, f_B, heading_from_kf)) return;
  if (p_WM_W) (void)ins.UpdatePosition(t, *p_WM_W);
}

}  // namespace rcal::tool
