// still_window: the still-window stage of the sensor-level pipeline. Subscribes JOINTS, IMU and
// POSITION, runs rcal::estimation::PosePipeline (orientation KF + position KF + still windows,
// exactly as the offline `rcal experiment paper --sensors` does), and publishes one
// POSE_MEASUREMENT per still window (utime: the window's end, pose_index counting from 0), HEALTH
// at 1 Hz of sensor time.
//
// Why the raw streams and not ORIENTATION + TOOL_POSITION: the offline experiment feeds the raw
// samples to PosePipeline, whose window covariance is the scatter of the *raw* FQA and position
// samples the filters accepted; the filter nodes' messages do not carry those. Running the same
// class on the same samples in the same order reproduces the offline windows to rounding.
//
// Input order: PosePipeline needs non-decreasing sensor time across the three streams (ties
// allowed); a sample older than the last one is rejected and counted (HEALTH). Magnetic field:
// IMU messages carry tesla; the pipeline is given µT (the unit its FQA noise is tuned for).
// Warm-up: the pose pipeline starts its filters at the first stop (the joints standing still) and
// drops that stop's window (estimation::PosePipelineSettings::rest_from_joints), so a process
// started or restarted anywhere, in a move or inside a stop, publishes only windows of filters
// that converged at rest (as the offline experiment drops the home stop). --warmup S drops, in
// addition, the windows that begin within S seconds of the first sample (0: none).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstring>
#include <optional>

#include "rcal/estimation/pose_pipeline.hpp"
#include "rcal/kinematics/measurement.hpp"
#include "rcal/services/common.hpp"
#include "rcal/sim/imu_model.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/filter_nodes.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace {

using namespace rcal;
namespace ch = transport::channels;

class StillWindowNode {
 public:
  StillWindowNode(const estimation::PosePipelineSettings& ps, double warmup,
                  transport::Transport& t, const std::string& name)
      : pipeline_(ps), warmup_(warmup), t_(t), health_(name) {
    t_.Subscribe<joint_state_t>(
        ch::kJoints, [this](const joint_state_t& m) { OnJoints(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<imu_sample_t>(
        ch::kImu, [this](const imu_sample_t& m) { OnImu(m); },
        [this](const std::string& e) { Bad(e); });
    t_.Subscribe<position_sample_t>(
        ch::kPosition, [this](const position_sample_t& m) { OnPosition(m); },
        [this](const std::string& e) { Bad(e); });
  }
  int emitted() const { return emitted_; }

 private:
  static double Seconds(int64_t utime) { return static_cast<double>(utime) * 1e-6; }

  void Bad(const std::string& e) {
    health_.Received();
    health_.Rejected(e);
    spdlog::warn("rejected: {}", e);
  }
  void Done(int64_t utime, const estimation::Status& s) {
    if (!s.ok()) {
      health_.Rejected(s.error());
      spdlog::warn("rejected: {}", s.error());
    }
    if (!t_first_) t_first_ = Seconds(utime);
    if (const auto& c = pipeline_.counters(); c.windows_dropped > dropped_) {
      dropped_ = c.windows_dropped;
      spdlog::warn("window dropped ({} so far): {}", dropped_, c.last_error);
    }
    for (const auto& p : pipeline_.TakePoses()) Emit(p);
    health_.Tick(utime, t_);
  }
  void OnJoints(const joint_state_t& m) {
    health_.Received();
    if (m.num_joints < 1 || static_cast<int>(m.q.size()) != m.num_joints)
      return Bad("joint_state.q: size does not match num_joints");
    Eigen::VectorXd q(m.num_joints);
    for (int i = 0; i < m.num_joints; ++i) q(i) = m.q[i];
    Done(m.utime, pipeline_.AddJoints(Seconds(m.utime), q));
  }
  void OnImu(const imu_sample_t& m) {
    health_.Received();
    std::string error;
    const auto s = transport::ImuFromMessage(m, &error);
    if (!s) return Bad(error);
    if (!s->has_mag) return Bad("imu_sample: no magnetic field");
    Done(s->utime, pipeline_.AddImu(Seconds(s->utime), s->gyro_B, s->f_B, s->m_B * 1e6));
  }
  void OnPosition(const position_sample_t& m) {
    health_.Received();
    std::string error;
    const auto s = transport::PositionFromMessage(m, &error);
    if (!s) return Bad(error);
    Done(s->utime, pipeline_.AddPosition(Seconds(s->utime), s->p));
  }
  void Emit(const estimation::StillPose& p) {
    if (t_first_ && p.t_begin - *t_first_ < warmup_) {
      spdlog::info("window {:.3f}–{:.3f} s dropped: warm-up", p.t_begin, p.t_end);
      return;
    }
    const kinematics::PoseMeasurement z = p.ToMeasurement();
    const int64_t utime = std::llround(p.t_end * 1e6);
    if (t_.Publish(ch::kPoseMeasurement, transport::ToMessage(z, utime, emitted_))) {
      health_.Published();
      spdlog::info("pose {}: window {:.3f}–{:.3f} s, {} IMU / {} position samples", emitted_,
                   p.t_begin, p.t_end, p.imu_samples, p.position_samples);
      ++emitted_;
    } else {
      health_.Error("publish failed");
    }
  }

  estimation::PosePipeline pipeline_;
  double warmup_;
  transport::Transport& t_;
  transport::Health health_;
  std::optional<double> t_first_;
  int emitted_ = 0;
  std::int64_t dropped_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string lcm_url, name = "still_window";
  const sim::SensorSimSettings sim_defaults;
  double position_sigma = sim_defaults.position.sigma;
  double gyro_noise = sim_defaults.imu.gyro_noise_density;
  double warmup = 0.0;
  bool position_only = false;
  CLI::App app{
      "still_window: still-window pose measurements from the raw sensor streams.\n"
      "Subscribes JOINTS, IMU, POSITION; runs the pose pipeline (orientation + position KF, "
      "still windows); publishes POSE_MEASUREMENT per window and HEALTH.\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  app.add_option("--position-sigma", position_sigma, "position sensor σ per axis [m]")
      ->capture_default_str();
  app.add_option("--gyro-noise-density", gyro_noise, "gyro noise density [rad/s/√Hz]")
      ->capture_default_str();
  app.add_option("--warmup", warmup,
                 "windows beginning within this time of the first sample are dropped [s]")
      ->capture_default_str();
  app.add_flag("--position-only", position_only, "position-only measurements");
  app.add_option("--name", name, "process name in HEALTH")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    estimation::PosePipelineSettings ps;
    ps.position.position_sigma = position_sigma;
    ps.orientation.gyro_noise_density = gyro_noise;
    ps.use_orientation = !position_only;
    spdlog::info("still_window on {}", t.url());
    StillWindowNode node(ps, warmup, t, name);
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    spdlog::info("stopped: {} poses published", node.emitted());
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
