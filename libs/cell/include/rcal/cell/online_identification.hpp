// The online identification as the ekf_identifier process runs it, pose by pose, and as
// `rcal calibrate --log` runs it offline on a recorded log, so the two give the same parameters:
//
//   model and base set  generic: the robot file's model, the identifiable set at a seeded joint
//                       sample (ident_seed) around the nominal; cell (cell_seed > 0): the
//                       simulated cell of `rcal experiment paper --sensors --seed S` (arm + set-up
//                       frames, its preferred base set)
//   start               generic: the EKF at the nominal; cell: the first `guess_poses` poses are
//                       held back, the set-up frames guessed from them (cell::SetupGuess), then the
//                       EKF starts there and takes the held poses in order
//   each pose           checked (kinematics::Validate), strictly after the last accepted (or held)
//                       pose in sensor time, then the EKF update (which may reject it by its gate)
//
// Pure: no transport, no files. State worth keeping (the EKF checkpoint and the held poses) is
// exposed for the caller to save and restore.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "rcal/cell/sim_cell.hpp"
#include "rcal/identification/ekf_identifier.hpp"
#include "rcal/io/robot_yaml.hpp"

namespace rcal::cell {

struct OnlineIdentificationSettings {
  unsigned ident_seed = 1;  ///< generic: seed of the joint sample that selects the base set
  unsigned cell_seed = 0;   ///< > 0: the simulated cell of this seed
  int guess_poses = 6;      ///< cell: poses held back for the set-up guess (≥ 1)
  bool position_only = false;
};

/// A pose given to the identification: the measurement, its sensor time [µs] and source index.
struct TimedPose {
  kinematics::PoseMeasurement z;
  int64_t utime = 0;
  int64_t pose_index = -1;
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

  /// Throws std::invalid_argument for guess_poses < 1.
  OnlineIdentification(const io::RobotSpec& robot, const kinematics::KinematicModel& robot_model,
                       const OnlineIdentificationSettings& settings);

  /// One pose in arrival order. `on_update`, when given, is called after each EKF update with the
  /// identification in its state right after that update (to publish the estimate pose by pose,
  /// also within the burst of held poses).
  Outcome Add(const TimedPose& pose, const std::function<void(const Update&)>& on_update = {});

  /// Resume: the EKF state, the poses held for the guess and the last pose's time and index.
  /// Throws std::runtime_error when they do not fit (held poses with the EKF started, or without
  /// a cell).
  void Restore(const identification::EkfCheckpoint& checkpoint, std::vector<TimedPose> held,
               int64_t last_utime, int64_t last_pose_index);

  const kinematics::KinematicModel& model() const { return model_; }
  const std::vector<int>& base() const { return base_; }
  const identification::EkfIdentifier& ekf() const { return *ekf_; }
  const std::optional<Cell>& cell() const { return cell_; }
  bool started() const { return started_; }
  const std::vector<TimedPose>& held() const { return held_; }
  int64_t last_utime() const { return last_utime_; }
  int64_t last_pose_index() const { return last_pose_index_; }

 private:
  Update Apply(const TimedPose& pose);

  OnlineIdentificationSettings settings_;
  std::optional<Cell> cell_;
  kinematics::KinematicModel model_;
  std::vector<int> base_;
  std::unique_ptr<identification::EkfIdentifier> ekf_;
  std::vector<TimedPose> held_;
  bool started_ = true;
  int64_t last_utime_ = std::numeric_limits<int64_t>::min();
  int64_t last_pose_index_ = -1;
};

}  // namespace rcal::cell
