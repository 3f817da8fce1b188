// ik_corrector: answers IK_REQUEST with IK_COMMAND, solved by rcal::ik::LevenbergMarquardtIk on
// the latest calibrated parameters (KINEMATIC_PARAMS; the nominal model until the first), and
// reports the nominal model's answer and how far it would put the tool (nominal_tool_error).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>

#include "rcal/ik/levenberg_marquardt_ik.hpp"
#include "rcal/io/robot_urdf.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/health.hpp"
#include "rcal/transport/lcm_transport.hpp"

int main(int argc, char** argv) {
  using namespace rcal;
  namespace ch = transport::channels;
  std::string robot_path = "config/robots/grb3016.yaml", lcm_url;
  CLI::App app{
      "ik_corrector: IK_REQUEST -> IK_COMMAND on the calibrated model (latest KINEMATIC_PARAMS)."};
  app.add_option("--robot", robot_path, "robot YAML or URDF")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  CLI11_PARSE(app, argc, argv);
  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    const auto robot = io::LoadRobot(services::RepoPath(robot_path));
    const auto& model = robot.model;
    ik::LevenbergMarquardtIk calibrated(model, model.Nominal()), nominal(model, model.Nominal());
    Eigen::VectorXd x = model.Nominal();
    int64_t params_utime = 0, latest = 0;
    transport::Health health("ik_corrector");
    auto reject = [&](const std::string& e) {
      health.Rejected(e);
      spdlog::warn("rejected: {}", e);
    };
    t.Subscribe<kinematic_params_t>(
        ch::kKinematicParams,
        [&](const kinematic_params_t& m) {
          health.Received();
          std::string error;
          const auto values = transport::ParamsFromMessage(m, model, &error);
          if (!values) return reject(error);
          x = *values;
          calibrated.SetParameters(x);
          params_utime = m.utime;
          latest = std::max(latest, m.utime);
          health.Tick(latest, t);
        },
        [&](const std::string& e) { health.Received(), reject(e); });
    t.Subscribe<ik_request_t>(
        ch::kIkRequest,
        [&](const ik_request_t& m) {
          health.Received();
          std::string error;
          const auto q = transport::FromMessage(m, model.num_joints(), &error);
          if (!q) return reject(error);
          const auto solve = [&](ik::LevenbergMarquardtIk& s) {
            return q->position_only ? s.SolvePosition(q->T_WT.translation(), q->q_seed)
                                    : s.Solve(q->T_WT, q->q_seed);
          };
          const auto cal = solve(calibrated), nom = solve(nominal);
          // Where the nominal answer really puts the tool (the calibrated model is the truth here).
          const double nominal_error =
              (model.ToolFrame(nom.q, x).translation() - q->T_WT.translation()).norm();
          if (t.Publish(ch::kIkCommand,
                        transport::ToIkCommand(m, cal, nom, nominal_error, params_utime)))
            health.Published();
          latest = std::max(latest, m.utime);
          health.Tick(latest, t);
        },
        [&](const std::string& e) { health.Received(), reject(e); });
    while (!services::StopRequested())
      if (t.HandleTimeout(100) < 0 && errno != EINTR) return 1;
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
