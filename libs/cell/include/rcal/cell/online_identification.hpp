// The online identification of a cell as the ekf_identifier process runs it, pose by pose, and as
// `rcal calibrate --log LOG --cell FILE` runs it offline on a recorded log, so the two give the
// same parameters. Everything comes from the cell file (io::BuiltCell): no simulator.
//
//   model and base set  the arm with the cell's set-up frames; the identifiable (base) set of the
//                       cell's measurements (its markers, orientation when it measures it) at a
//                       seeded joint sample (identifier.base_set_seed) with the set-up frames at a
//                       generic placement (identification::GenericSetupPlacement): the rank a real
//                       cell has, chosen before any pose arrives
//   start               frames of mode `guess`: the first identifier.guess_poses poses are held
//                       back, the set-up guessed from them (identification::GuessSetup: the
//                       tracker frame and marker offsets registered, the IMU mounting and earth
//                       frame hand–eye, a bad pose left out); frames of mode `prior` and `fixed`
//                       stay at their nominal. The EKF then starts there with the cell's prior σ
//                       per parameter, and takes the held poses in order. Without guessed frames it
//                       starts at the nominal with the first pose.
//   each pose           checked (kinematics::Validate), strictly after the last accepted (or
//                       held) pose in sensor time, then the EKF update (which may reject it by its
//                       gate)
//   effects (optional)  non-geometric effects (kinematics::ExtendedModel, e.g. the effects an
//                       `rcal analyze` selected): the EKF's state is then [base set; e], e starting
//                       at 0 with identification::DefaultEffectPriorSigma (or the settings'
//                       prior_sigma_effects), and each pose's context (TimedPose::context:
//                       temperature, payload, time, approach direction) enters its update. The
//                       set-up guess stays geometric.
//
// Pure: no transport, no files. State worth keeping (the EKF checkpoint and the held poses) is
// exposed for the caller to save and restore.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/identification/extended_lm.hpp"
#include "rcal/io/cell_yaml.hpp"

namespace rcal::cell {

/// A pose given to the identification: the measurement, its sensor time [µs] and source index.
struct TimedPose {
  kinematics::PoseMeasurement z;
  int64_t utime = 0;
  int64_t pose_index = -1;
  /// The conditions it was taken under (an extended model's effects depend on them; ignored
  /// without effects).
  kinematics::EffectContext context;
};

/// The identifiable (base) parameter set of `cell`'s measurements at a seeded joint sample, the
/// set-up frames at a generic placement (file comment). Ascending.
std::vector<int> CellBaseSet(const io::BuiltCell& cell);

/// A change the geometric identification detected that a switched-in effect explains
/// (OnlineIdentification::SwitchIn): its release withdrawn.
struct WithdrawnChange {
  int64_t onset_pose_index = -1;   ///< the pose its release began at
  std::vector<std::string> names;  ///< identification::ChangeNames (empty: detected before a
                                   ///< restart, so not known)
  /// −2 ln of the Bayes factor for withdrawing it: the window's evidence with the release minus
  /// without it (EkfIdentifier::WindowEvidence), ≥ 0.
  double evidence_gain = 0;
};

class OnlineIdentification {
 public:
  /// What one pose did (a held-back pose that completes the guess applies all held poses: one
  /// Update per pose applied, in order).
  struct Update {
    int64_t utime = 0, pose_index = -1;
    int dimension = 0;  ///< of the pose's measurement: 3 (position) or 6
    identification::EkfUpdateResult result;
    /// Largest |Δx_i| / σ_i over the base set by this update (0 when rejected).
    double max_step_sigma = 0;
  };
  struct Outcome {
    std::string rejected;  ///< non-empty: refused before the EKF (names the field)
    bool held = false;     ///< held back for the set-up guess
    bool started = false;  ///< this pose completed the guess: the EKF started
    std::vector<Update> updates;
  };

  /// Throws std::invalid_argument when the cell's identifier settings cannot be used
  /// (guess_poses < 3 with guessed frames).
  /// `effects`: non-geometric effects identified with the base set (none: the geometric
  /// identifier); `gravity`: the point-mass model of joint_compliance. Throws
  /// std::invalid_argument for an effect the model cannot have (ExtendedModel).
  explicit OnlineIdentification(io::BuiltCell cell, std::vector<kinematics::Effect> effects = {},
                                kinematics::GravityModel gravity = {});

  /// One pose in arrival order. `on_update`, when given, is called after each EKF update with the
  /// identification in its state right after that update (to publish the estimate pose by pose,
  /// also within the burst of held poses).
  Outcome Add(const TimedPose& pose, const std::function<void(const Update&)>& on_update = {});

  /// Resume: the EKF state, the poses held for the guess and the last pose's time and index.
  /// Throws std::runtime_error when they do not fit (held poses with the EKF started, or in a cell
  /// that guesses nothing).
  void Restore(const identification::EkfCheckpoint& checkpoint, std::vector<TimedPose> held,
               int64_t last_utime, int64_t last_pose_index);

  /// The poses of the EKF's window as they arrived: its accepted poses and, between them, those
  /// its gate refused (the poses a model that lacks an effect cannot explain are the evidence of
  /// it), oldest first (at most as many refused poses as the window holds, and 100: the oldest
  /// refused ones are dropped first, never one of the window's own). After a
  /// Restore the refused poses of the restored window are not known: its accepted poses (utime 0)
  /// and what arrives after them.
  std::vector<TimedPose> Window() const;
  /// Window().size(), without the copy.
  int WindowSize() const;
  /// The changes released inside Window() as geometry steps (first_pose: index into Window(),
  /// ≥ 1; directions: the released directions of the geometric parameters, full length), oldest
  /// first. A release at the window's first pose is left out: nothing before it to step from.
  std::vector<identification::GeometryStep> WindowSteps() const;

  /// Adds `effects` to those identified (issue 15 item 5, the discrepancy watch's switch): the
  /// identification is rebuilt on the extended model, the state of the geometric parameters and
  /// of the effects it already had kept with their covariance, each new effect parameter from 0
  /// with its weak prior (uncorrelated), and relinearised over Window() (the poses the old gate
  /// refused included, then those still beyond the gate of the new model dropped), so the new
  /// effects are identified from the poses already seen (the information folded out of the window
  /// carries none about them). Effects already identified are skipped. Returns the effects added.
  /// Before anything is identified (the set-up guess still holding poses, or a restart about to
  /// Restore a checkpoint of the extended model) the EKF simply starts with them. Throws
  /// std::invalid_argument for an effect the model cannot have (nothing changed).
  ///
  /// A large effect the model lacks is first seen as steps (the change detector fires on it): each
  /// change the old identification released within the window is tested again under the new
  /// model, newest first, and withdrawn (its inflation dropped, the window relinearised) where the
  /// window's poses are at least as likely without it (EkfIdentifier::WindowEvidence: a Bayes
  /// factor, the release's Occam factor against what it explains). withdrawn() lists them.
  std::vector<kinematics::Effect> SwitchIn(const std::vector<kinematics::Effect>& effects);
  /// The changes the last SwitchIn withdrew (newest first).
  const std::vector<WithdrawnChange>& withdrawn() const { return withdrawn_; }

  const io::BuiltCell& cell() const { return cell_; }
  /// The non-geometric effects identified (none: the geometric identification).
  const std::vector<kinematics::Effect>& effects() const { return effects_; }
  const kinematics::GravityModel& gravity() const { return gravity_; }
  const kinematics::KinematicModel& model() const { return cell_.model; }
  const std::vector<int>& base() const { return base_; }
  const identification::EkfIdentifier& ekf() const { return *ekf_; }
  /// The start the EKF was given (the set-up guess), full length [m | rad].
  const Eigen::VectorXd& start() const { return start_; }
  bool started() const { return started_; }
  const std::vector<TimedPose>& held() const { return held_; }
  int64_t last_utime() const { return last_utime_; }
  int64_t last_pose_index() const { return last_pose_index_; }

 private:
  Update Apply(const TimedPose& pose);
  /// SwitchIn's second look at the old identification's releases (its comment), on `ekf` (the
  /// new identification over `window`).
  std::vector<WithdrawnChange> WithdrawExplainedChanges(identification::EkfIdentifier& ekf,
                                                        const std::vector<TimedPose>& window,
                                                        int passes) const;
  /// Where Window() starts in seen_ (seen_.size() when the EKF holds no pose).
  size_t WindowStart() const;
  /// An EKF on the base set starting at x0 (full length) with the cell's prior σ.
  std::unique_ptr<identification::EkfIdentifier> MakeEkf(const Eigen::VectorXd& x0) const;

  io::BuiltCell cell_;
  std::vector<int> guessed_;
  std::vector<int> base_;
  std::vector<kinematics::Effect> effects_;
  kinematics::GravityModel gravity_;
  Eigen::VectorXd start_;
  std::unique_ptr<identification::EkfIdentifier> ekf_;
  std::vector<TimedPose> held_;
  /// Poses applied to the EKF (accepted or refused by its gate) since its window began.
  std::deque<TimedPose> seen_;
  std::vector<WithdrawnChange> withdrawn_;
  /// The changes released, oldest first (the last as many as the window holds): the onset pose's
  /// measurement and the names, what SwitchIn names a withdrawn one by (matched on the pose).
  struct Release {
    kinematics::PoseMeasurement onset;
    std::vector<std::string> names;
  };
  std::deque<Release> releases_;
  bool started_ = true;
  int64_t last_utime_ = std::numeric_limits<int64_t>::min();
  int64_t last_pose_index_ = -1;
};

/// The cell's online identification with the effects listed in `effects_path`, an `rcal
/// analyze` analysis.json or the JSON of `rcal calibrate --effects` (empty: none, the geometric
/// identification); joint_compliance's gravity model as the analysis fitted it (its
/// link_density_kg_per_m), else 10 kg/m, rcal analyze's default. What ekf_identifier --effects and
/// `rcal calibrate --log --effects` both build. Throws std::runtime_error naming the file and key.
OnlineIdentification MakeOnlineIdentification(io::BuiltCell cell, const std::string& effects_path);

}  // namespace rcal::cell
