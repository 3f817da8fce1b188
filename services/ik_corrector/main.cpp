// ik_corrector: answers IK_REQUEST with IK_COMMAND, solved by rcal::ik::LevenbergMarquardtIk on
// the latest calibrated parameters (KINEMATIC_PARAMS; the nominal model until the first), and
// reports the nominal model's answer and how far it would put the tool (nominal_tool_error).
// With --effects (an `rcal analyze` analysis.json or an `rcal calibrate --effects` result) the
// calibrated answer is solved on the extended model: joint compliance, gear errors, backlash,
// thermal growth as identified. The node (checks, conversions, HEALTH) is
// rcal::transport::IkCorrectorNode. The model is the cell's (--cell FILE: the arm with its set-up
// frames, the model ekf_identifier estimates), so a target is in the world (position sensor)
// frame and places the cell's first marker.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "rcal/io/cell_yaml.hpp"
#include "rcal/io/effects_json.hpp"
#include "rcal/services/common.hpp"
#include "rcal/transport/ik_corrector_node.hpp"
#include "rcal/transport/lcm_transport.hpp"

int main(int argc, char** argv) {
  using namespace rcal;
  std::string cell_path = "config/cells/grb3016.yaml", lcm_url, effects_path;
  transport::IkCorrectorNode::Options options;
  CLI::App app{
      "ik_corrector: IK_REQUEST -> IK_COMMAND on the calibrated model (latest KINEMATIC_PARAMS).\n"
      "LCM URL: --lcm-url, else $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0."};
  app.add_option("--cell", cell_path,
                 "cell file (schema rcal.cell/1): the arm and its set-up frames, as the "
                 "identifier's")
      ->capture_default_str();
  app.add_option("--name", options.name, "process name in HEALTH")->capture_default_str();
  app.add_option("--lcm-url", lcm_url, "LCM URL");
  app.add_option("--effects", effects_path,
                 "non-geometric effects and their values (analysis.json of rcal analyze, or the "
                 "JSON of rcal calibrate --effects)");
  app.add_option("--payload", options.payload_kg, "payload at the tool for every command [kg]")
      ->capture_default_str();
  app.add_option("--temperature", options.temperature_c,
                 "arm temperature for thermal growth [degC] (default: unknown, no growth)");
  app.add_option("--link-density", options.gravity.link_density_kg_per_m,
                 "gravity model of joint compliance [kg/m]")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    services::InstallStopHandlers();
    transport::LcmTransport t(lcm_url);
    const io::BuiltCell cell = io::LoadCell(services::RepoPath(cell_path));
    const kinematics::KinematicModel& model = cell.model;
    if (!effects_path.empty()) {
      const io::AnalysisEffects ae =
          io::ReadAnalysisEffects(services::RepoPath(effects_path), model);
      options.effects = ae.effects;
      options.effect_values = ae.values;
      // The gravity model the compliance was fitted with, unless given here.
      if (std::isfinite(ae.link_density_kg_per_m) && app.count("--link-density") == 0)
        options.gravity.link_density_kg_per_m = ae.link_density_kg_per_m;
    }
    transport::IkCorrectorNode node(t, model, options);
    node.Announce();
    spdlog::info("ik_corrector on {}: cell {} ({}), {} non-geometric effects", t.url(),
                 cell.spec.name, model.name(), options.effects.size());
    if (const int rc =
            rcal::services::ServeUntilStopped([&](int ms) { return t.HandleTimeout(ms); });
        rc != 0)
      return rc;
    node.Finish();
    return 0;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}
