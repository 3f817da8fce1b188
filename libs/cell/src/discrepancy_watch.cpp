#include "rcal/cell/discrepancy_watch.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "rcal/cell/claimed_noise.hpp"

namespace rcal::cell {

std::vector<kinematics::Effect> DiscrepancyReport::NewEffects() const {
  std::vector<kinematics::Effect> out;
  for (const auto& s : suspects)
    if (!s.in_model) out.push_back(s.effect);
  return out;
}

bool WatchDue(const OnlineIdentification& id, const DiscrepancyWatchSettings& s) {
  // Poses the EKF took, whether its gate accepted or refused them, and the window's poses as the
  // watch analyses them (its refused poses too): a model that lacks a large effect has its gate
  // refuse many of the poses that show it, so counting accepted poses only would look last, or
  // never, where the evidence is strongest. (A change's release re-accepts refused poses: the sum
  // stays.)
  const auto& ekf = id.ekf();
  const int taken = ekf.accepted() + ekf.rejected();
  return s.every_poses > 0 && taken > 0 && taken % s.every_poses == 0 &&
         id.WindowSize() >= std::max(s.min_poses, 1);
}

discrepancy::PoseData WatchWindow(const OnlineIdentification& id) {
  discrepancy::PoseData data;
  for (const TimedPose& p : id.Window()) {
    data.measurements.push_back(p.z);
    data.contexts.push_back(p.context);
  }
  data.steps = id.WindowSteps();
  return data;
}

DiscrepancyReport WatchForDiscrepancy(const kinematics::KinematicModel& model,
                                      const discrepancy::PoseData& window,
                                      const std::vector<kinematics::Effect>& in_model,
                                      const kinematics::GravityModel& gravity,
                                      const DiscrepancyWatchSettings& s) {
  if (window.measurements.size() < 10)
    throw std::invalid_argument("discrepancy watch: " + std::to_string(window.measurements.size()) +
                                " poses in the window, at least 10 needed");
  discrepancy::AnalysisSettings as = s.analysis;
  as.gravity = gravity;
  if (as.stated_position_sigma_m <= 0) {
    // The noise the poses claim: RMS per-axis σ of their covariances (position, orientation).
    double vp = 0, vo = 0;
    int np = 0, no = 0;
    for (const auto& m : window.measurements) {
      const ClaimedVariance v = PerAxisVariance(m);
      if (v.position > 0) vp += v.position, ++np;
      if (v.orientation > 0) vo += v.orientation, ++no;
    }
    as.stated_position_sigma_m = np > 0 ? std::sqrt(vp / np) : 0.0;
    as.stated_orientation_sigma_rad = no > 0 ? std::sqrt(vo / no) : 0.0;
  }
  const discrepancy::Analysis a = discrepancy::Analyze(model, window, as);
  DiscrepancyReport r;
  r.window_poses = static_cast<int>(window.measurements.size());
  r.window_steps = static_cast<int>(window.steps.size());
  r.gravity = gravity;
  for (const auto& t : a.noise_tests)
    if (t.against == "stated noise") {
      r.noise_against = t.against;
      r.chi2 = t.chi2;
      r.chi2_dof = t.dof;
      r.chi2_log_p = t.log_p;
    }
  for (const auto& f : a.effects) {
    SuspectedEffect e;
    e.effect = f.effect;
    e.description = discrepancy::Describe(model, f.effect);
    e.cause = f.cause;
    e.joints = f.joints;
    e.z = f.z;
    e.parameters = f.parameters;
    e.values = f.values;
    e.sigma = f.sigma;
    e.in_model = std::any_of(in_model.begin(), in_model.end(),
                             [&](const kinematics::Effect& o) { return o.SameAs(f.effect); });
    r.suspects.push_back(std::move(e));
  }
  // Strongest first (the selection adds them in that order; ties kept).
  std::stable_sort(r.suspects.begin(), r.suspects.end(),
                   [](const SuspectedEffect& x, const SuspectedEffect& y) { return x.z > y.z; });
  r.heldout_rms_before_m = a.gain.heldout_rms_before_m;
  r.heldout_rms_after_m =
      a.effects.empty() ? a.gain.heldout_rms_before_m : a.gain.heldout_rms_after_m;
  r.expected_gain = a.effects.empty() ? 0.0 : a.gain.relative_gain;
  r.scheme = a.gain.scheme;
  for (const auto& c : a.correlations) {  // strongest first (Analysis::correlations)
    if (r.correlations.size() == 8) break;
    r.correlations.push_back({c.regressor + " [" + c.unit + "]", c.correlation, c.log_p});
  }
  return r;
}

DiscrepancyReport WatchForDiscrepancy(const OnlineIdentification& id,
                                      const DiscrepancyWatchSettings& s) {
  return WatchForDiscrepancy(id.model(), WatchWindow(id), id.effects(), id.gravity(), s);
}

}  // namespace rcal::cell
