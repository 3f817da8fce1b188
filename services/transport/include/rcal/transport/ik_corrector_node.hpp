// The ik_corrector process's node: KINEMATIC_PARAMS (the latest calibration) and IK_REQUEST in,
// IK_COMMAND out, HEALTH at 1 Hz of the messages' utime. Each request is solved by
// rcal::ik::LevenbergMarquardtIk on the calibrated model (the nominal one until the first
// KINEMATIC_PARAMS) and on the nominal model; the command also says how far the nominal answer
// would put the tool on the calibrated model (nominal_tool_error). With non-geometric effects in
// the options (an `rcal analyze` / `rcal calibrate --effects` result), the calibrated answer is
// solved by rcal::ik::ExtendedIk on the extended model (geometric errors from KINEMATIC_PARAMS,
// effect values from the options, or from KINEMATIC_PARAMS when it carries this model's effects:
// an identifier run with --effects; effects of another model refuse the message, naming the
// field) under the options' context; backlash takes the direction of
// the commanded motion (sign of the geometric answer − q_seed per joint). Parameters for another
// model (model id, names, sizes), non-finite values, malformed requests and undecodable bytes are
// rejected, counted in HEALTH, and change nothing.
//
// Which estimate is in use: the newest by (poses_used, utime). A KINEMATIC_PARAMS equal to the one
// in use on both is a duplicate, one older on them is stale: refused and counted (HEALTH
// duplicates / stale), so a late or replayed 1-pose estimate can never replace a 30-pose one. A
// utime beyond the host-clock ceiling (estimation::HostCeilingUs) is refused as out of horizon.
// An identifier that really started over (no checkpoint) sends estimates that are all stale:
// after Options::restart_params of them in a row, each newer than the one before by
// (poses_used, utime), they are taken (HEALTH resyncs). An IK_REQUEST with the request_id and
// utime of the previous one is a duplicate: refused and counted, not answered twice.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "rcal/ik/extended_ik.hpp"
#include "rcal/ik/levenberg_marquardt_ik.hpp"
#include "rcal/ik_request_t.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/kinematics/joint_effects.hpp"
#include "rcal/kinematics/model.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/transport.hpp"

namespace rcal::transport {

class IkCorrectorNode {
 public:
  struct Options {
    std::string name = "ik_corrector";
    std::string params_channel = "KINEMATIC_PARAMS";
    std::string request_channel = "IK_REQUEST";
    std::string command_channel = "IK_COMMAND";
    std::string health_channel = "HEALTH";
    /// The arm's non-geometric effects and their values [SI, joint_effects.hpp]; empty: the
    /// geometric model alone.
    std::vector<kinematics::Effect> effects;
    Eigen::VectorXd effect_values;
    kinematics::GravityModel gravity;
    /// Context of every command: payload at the tool [kg], temperature [°C] (NaN: unknown).
    double payload_kg = 0.0;
    double temperature_c = std::numeric_limits<double>::quiet_NaN();
    /// Consecutive stale estimates, each newer than the previous, that mean the identifier
    /// started over [-] (≥ 1).
    int restart_params = 5;
  };
  IkCorrectorNode(Transport& t, const kinematics::KinematicModel& model, Options options);
  IkCorrectorNode(Transport& t, const kinematics::KinematicModel& model)
      : IkCorrectorNode(t, model, Options{}) {}

  /// Publishes one HEALTH with utime 0 (outside the 1 Hz schedule) so listeners know the process
  /// is up before any estimate or request came (as the filter nodes do).
  void Announce();
  /// Publishes the final HEALTH (on a clean stop): the counts up to the end.
  void Finish() { health_.Final(t_, o_.health_channel); }

  void OnParams(const kinematic_params_t& msg);
  void OnRequest(const ik_request_t& msg);
  void OnUndecodable(const std::string& reason);

  /// Parameter errors in use [m | rad] (the nominal model's until the first KINEMATIC_PARAMS).
  const Eigen::VectorXd& x() const { return x_; }
  /// Effect values in use [SI] (empty without effects).
  Eigen::VectorXd e() const { return extended_ ? extended_->e() : Eigen::VectorXd(); }
  /// utime of the KINEMATIC_PARAMS in use (0: nominal).
  int64_t params_utime() const { return params_utime_; }
  /// poses_used of the KINEMATIC_PARAMS in use (−1: nominal).
  int32_t params_poses_used() const { return params_poses_used_; }
  const Health& health() const { return health_; }

 private:
  void Reject(const std::string& reason);
  void Use(const kinematic_params_t& msg, const Eigen::VectorXd& values,
           const std::optional<Eigen::VectorXd>& effects);
  Transport& t_;
  const kinematics::KinematicModel& model_;
  Options o_;
  ik::LevenbergMarquardtIk calibrated_, nominal_;
  std::optional<ik::ExtendedIk> extended_;  // with effects: the calibrated answer
  Eigen::VectorXd x_;
  int64_t params_utime_ = 0, latest_ = 0;
  int32_t params_poses_used_ = -1;
  // The run of stale estimates (see the header): its length and its last (poses_used, utime).
  int stale_run_ = 0;
  std::pair<int32_t, int64_t> stale_last_{-1, 0};
  std::optional<std::pair<int64_t, int64_t>> last_request_;  // (request_id, utime)
  Health health_;
};

}  // namespace rcal::transport
