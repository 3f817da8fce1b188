// rcal watch: a live line per pose of the online calibration. Listens on LCM for
// KINEMATIC_PARAMS and CALIBRATION_STATUS (published in that order after every pose by
// ekf_identifier) and prints, per pose: poses used, the largest parameter change of that pose
// (in its σ, and the change's norm over lengths [mm] and angles [mrad]), the RMS residuals, and —
// with --sim FILE (a simulated cell, schema rcal.cell_sim/1: what sensor_acquisition --sim runs)
// — the mean position error on the test poses against the simulator's truth, as the offline
// experiment reports it (the same truth cell, cell::MakeSimCell, and the same test stops: drawn
// after the --poses calibration stops from mt19937_64(S·1000+3), S the sim file's seed).
// Ends after --poses poses (0: never), on Ctrl-C, or when nothing was heard for --idle seconds
// after the first pose (wall clock: a viewer, not a filter).
// The cell (--cell FILE, or the sim file's cell) gives the channels, which parameters are angles,
// and whether orientation is measured: a positions-only cell has no orientation residual, shown
// as "(positions only)" instead of the status message's 0.
// With --step-offset (the same as sensor_acquisition's): after the step's sensor time (the sim's
// default --start-utime 0), the truth the test error is judged against is where the arm stands
// when its joints read the test stops (sim::TrueJoints). Each line ends with the identifier's
// tracking status and, on a detection, what it named and by how much. A MODEL_DISCREPANCY (the
// identifier's discrepancy watch) gets its own line: what it suspects, z, the expected gain.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "command.hpp"
#include "experiment_sensors.hpp"
#include "rcal/calibration_status_t.hpp"
#include "rcal/cell/cell_sim_yaml.hpp"
#include "rcal/identification/metrics.hpp"
#include "rcal/io/cell_yaml.hpp"
#include "rcal/kinematic_params_t.hpp"
#include "rcal/model_discrepancy_t.hpp"
#include "rcal/sim/effects.hpp"
#include "rcal/sim/pose_sim.hpp"
#include "rcal/sim/sensor_sim.hpp"
#include "rcal/transport/adapters.hpp"
#include "rcal/transport/channels.hpp"
#include "rcal/transport/lcm_transport.hpp"

namespace rcal::tool {
namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) {
  g_stop = true;
}

struct Options {
  std::string lcm_url;
  std::string sim;   ///< empty: no truth to judge against
  std::string cell;  ///< the cell file (without --sim); empty: the default channels
  int poses = 0, test_poses = 50;
  int min_poses = -1;  // success with this many when the stream ends early (-1: --poses)
  double idle_s = 30.0;
  std::vector<std::string> step_offsets;  ///< JOINT=DELTA@STOP, as the sim's --step-offset
};

int Run(const Options& o) {
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  transport::LcmTransport t(o.lcm_url);
  std::optional<cell::Cell> cell;
  std::optional<io::BuiltCell> built;
  std::vector<Eigen::VectorXd> test_q;
  std::vector<sim::JointOffsetStep> steps;
  unsigned seed = 0;
  if (!o.sim.empty() && !o.cell.empty())
    throw std::runtime_error("watch: --sim names its cell; give --sim or --cell, not both");
  if (!o.cell.empty()) built = io::LoadCell(ResolvePath(o.cell));
  if (!o.sim.empty()) {
    const cell::CellSimSpec sim_spec = cell::LoadCellSimSpec(ResolvePath(o.sim));
    seed = sim_spec.seed;
    built = io::LoadCell(sim_spec.cell);
    cell = cell::MakeSimCell(*built, sim_spec);
    sim::Rng rng(seed * 1000 + 3);
    sim::SampleJoints(cell->model, 1, rng);  // home
    const auto stops = sim::SampleJoints(cell->model, o.poses + o.test_poses, rng);
    test_q.assign(stops.begin() + o.poses, stops.end());
    if (!o.step_offsets.empty()) {
      const cell::SimProgramme programme =
          cell::MakeSimProgramme(*built, sim_spec, seed, o.poses, o.test_poses);
      for (const std::string& text : o.step_offsets)
        steps.push_back(cell::OffsetStepInProgramme(
            programme, sim::ParseJointOffsetStep(text, programme.cell.model)));
    }
  } else if (!o.step_offsets.empty()) {
    throw std::invalid_argument("--step-offset needs --sim (the truth it changes)");
  }
  std::optional<kinematic_params_t> params, previous;
  std::optional<double> last_test_mm;
  int last_poses = 0;
  int changes_seen = 0, last_rejected = 0;
  auto last_heard = std::chrono::steady_clock::now();
  bool heard = false;
  const io::CellChannels channels = built ? built->spec.channels : io::CellChannels{};
  const bool orientation = !built || built->spec.measures_orientation();
  t.Subscribe<kinematic_params_t>(channels.kinematic_params, [&](const kinematic_params_t& m) {
    params = m;
    last_heard = std::chrono::steady_clock::now();
    heard = true;
  });
  t.Subscribe<model_discrepancy_t>(channels.model_discrepancy, [&](const model_discrepancy_t& m) {
    std::string error;
    const auto d = transport::ModelDiscrepancyFromMessage(m, &error);
    if (!d) {
      std::printf("discrepancy refused: %s\n", error.c_str());
      return;
    }
    std::string suspects;
    for (const auto& x : d->suspects)
      suspects += (suspects.empty() ? "" : ", ") + x.description + " (z " +
                  std::to_string(x.z).substr(0, 4) + (x.in_model ? ", in the model)" : ")");
    std::string strongest;
    if (!d->correlations.empty())
      strongest = "; residual vs " + d->correlations[0].regressor +
                  ": r = " + std::to_string(d->correlations[0].r).substr(0, 5);
    std::string withdrawn;  // poses numbered from 1, as the identifier's log numbers them
    for (const auto& w : d->withdrawn)
      withdrawn += "; change from pose " +
                   (w.onset_pose_index >= 0 ? std::to_string(w.onset_pose_index + 1) : "?") + " (" +
                   (w.changed.empty() ? "raised before a restart" : w.changed) + ") withdrawn";
    std::printf("discrepancy over %d poses: chi2/dof %.2f; %s; held-out %.4f -> %.4f mm%s%s%s\n",
                d->window_poses, d->chi2_dof > 0 ? d->chi2 / d->chi2_dof : 0.0,
                suspects.empty() ? "nothing suspected" : ("suspected: " + suspects).c_str(),
                d->heldout_rms_before_m * 1e3, d->heldout_rms_after_m * 1e3, strongest.c_str(),
                d->switched_in ? "; switched in" : "", withdrawn.c_str());
    std::fflush(stdout);
  });
  t.Subscribe<calibration_status_t>(
      channels.calibration_status, [&](const calibration_status_t& s) {
        last_heard = std::chrono::steady_clock::now();
        if (s.poses_rejected > last_rejected) {
          // A refused pose publishes no new parameters: its own line, with the reason.
          std::printf("refused   t %8.2f s  (%d so far): %s  %s\n", s.utime * 1e-6,
                      s.poses_rejected, s.last_rejection.c_str(), s.tracking_status.c_str());
          std::fflush(stdout);
        }
        last_rejected = s.poses_rejected;  // a change retakes refused poses: the count can fall
        if (!params || params->utime != s.utime || params->poses_used == last_poses) return;
        const kinematic_params_t& p = *params;
        double max_step = 0, d_len = 0, d_ang = 0;
        if (previous && previous->num_params == p.num_params)
          for (int i = 0; i < p.num_params; ++i) {
            const double d = p.values[i] - previous->values[i];
            if (p.sigmas[i] > 0) max_step = std::max(max_step, std::abs(d) / p.sigmas[i]);
            const bool angle = built && i < built->model.num_params()
                                   ? built->model.parameters()[i].is_angle
                                   : (p.names[i].find("alpha") != std::string::npos ||
                                      p.names[i].find("theta") != std::string::npos ||
                                      p.names[i].find("beta") != std::string::npos ||
                                      p.names[i].find("_r") != std::string::npos);
            (angle ? d_ang : d_len) += d * d;
          }
        std::string test = "";
        if (cell) {
          std::string error;
          const auto x = transport::ParamsFromMessage(p, cell->model, &error);
          if (x) {
            std::vector<Eigen::VectorXd> test_q_true;
            for (const auto& q : test_q)
              test_q_true.push_back(sim::TrueJoints(q, s.utime * 1e-6, steps));
            last_test_mm = identification::ErrorsAgainstTruth(cell->model, *x, cell->x_true, test_q,
                                                              test_q_true)
                               .mean_position_m *
                           1e3;
            char b[64];
            std::snprintf(b, sizeof b, "  test error %7.3f mm", *last_test_mm);
            test = b;
          } else {
            test = "  (" + error + ")";
          }
        }
        char rms_orientation[32] = "(positions only)";
        if (orientation)
          std::snprintf(rms_orientation, sizeof rms_orientation, "%6.3f mrad",
                        s.rms_orientation_residual * 1e3);
        // The tracking state; on the pose that detected a change, what it named and by how much
        // (mm and mrad: a human report).
        std::string status =
            s.tracking_status.empty() ? (s.converged ? "converged" : "") : s.tracking_status;
        if (s.changes_detected > changes_seen) {
          changes_seen = s.changes_detected;
          status += ":";
          for (int i = 0; i < s.num_changed; ++i) {
            const std::string& name = s.changed[i];
            const int index = built ? built->model.FindParameter(name) : -1;
            bool angle = index >= 0 ? built->model.parameters()[index].is_angle
                                    : name.find("theta") != std::string::npos ||
                                          name.find("alpha") != std::string::npos ||
                                          name.find("beta") != std::string::npos;
            if (built && name.rfind("offset of joint ", 0) == 0)
              for (const auto& joint : built->model.joints())
                if (name == "offset of joint " + joint.name)
                  angle = joint.type == kinematics::JointType::kRevolute;
            char b[160];
            std::snprintf(b, sizeof b, " %s %+.3f %s", name.c_str(), s.changed_step[i] * 1e3,
                          angle ? "mrad" : "mm");
            status += b;
            // Alternatives (the poses could not tell which stepped): each with its probability.
            if (static_cast<size_t>(i) < s.changed_probability.size() &&
                s.changed_probability[i] < 1) {
              std::snprintf(b, sizeof b, " (p %.2f)", s.changed_probability[i]);
              status += b;
            }
          }
        }
        // The effect parameters identified live (ekf_identifier --effects), SI with their units.
        std::string effects;
        for (int k = 0; k < p.num_effect_params; ++k) {
          char b[200];
          std::snprintf(b, sizeof b, "  %s %.3g ± %.2g %s", p.effect_names[k].c_str(),
                        p.effect_values[k], p.effect_sigmas[k], p.effect_units[k].c_str());
          effects += b;
        }
        std::printf(
            "pose %3d  t %8.2f s  change max %7.2f σ (|Δ| %7.3f mm, %7.3f mrad)  RMS residual "
            "%6.3f mm %s  rejected %d%s  %s%s\n",
            p.poses_used, s.utime * 1e-6, max_step, std::sqrt(d_len) * 1e3, std::sqrt(d_ang) * 1e3,
            s.rms_position_residual * 1e3, rms_orientation, s.poses_rejected, test.c_str(),
            status.c_str(), effects.c_str());
        std::fflush(stdout);
        last_poses = p.poses_used;
        previous = p;
      });
  std::printf("rcal watch on %s%s\n", t.url().c_str(),
              cell ? (" (truth: " + o.sim + ", seed " + std::to_string(seed) + ")").c_str() : "");
  std::fflush(stdout);
  while (!g_stop && (o.poses <= 0 || last_poses < o.poses)) {
    t.HandleTimeout(100);
    if (heard && o.idle_s > 0 &&
        std::chrono::steady_clock::now() - last_heard > std::chrono::duration<double>(o.idle_s)) {
      std::fprintf(stderr, "rcal watch: nothing heard for %.0f s\n", o.idle_s);
      break;
    }
  }
  if (last_test_mm)
    std::printf("final: %d poses, test error %.3f mm\n", last_poses, *last_test_mm);
  else
    std::printf("final: %d poses\n", last_poses);
  const int needed = o.min_poses >= 0 ? std::min(o.min_poses, o.poses) : o.poses;
  return (o.poses > 0 && last_poses < needed) ? 1 : 0;
}

const RegisterCommand kWatch(
    "watch", "A live line per pose of the online calibration (KINEMATIC_PARAMS on LCM)",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--lcm-url", o->lcm_url,
                     "LCM URL (default $RCAL_LCM_URL, else udpm://239.255.76.67:7667?ttl=0)");
      sub.add_option("--sim", o->sim,
                     "simulated cell (schema rcal.cell_sim/1, as sensor_acquisition --sim): show "
                     "the test error against its truth");
      sub.add_option("--cell", o->cell,
                     "cell file (schema rcal.cell/1; a simulated one's comes with --sim): its "
                     "channels, and no orientation residual for a positions-only cell");
      sub.add_option("--poses", o->poses, "stop after this many poses used (0: Ctrl-C)")
          ->capture_default_str();
      sub.add_option("--test-poses", o->test_poses, "test stops (as the sim's --test-poses)")
          ->capture_default_str();
      sub.add_option("--min-poses", o->min_poses,
                     "with --poses: a run that ends (--idle) after at least this many poses is a "
                     "success (a ROS 2 cell refuses the windows before its clocks are known)")
          ->check(cli::NonNegativeNumber);
      sub.add_option("--idle", o->idle_s, "stop when nothing heard this long [s] (0: never)")
          ->capture_default_str();
      sub.add_option("--step-offset", o->step_offsets,
                     "with --sim: the sim's --step-offset JOINT=DELTA@STOP, so that the test "
                     "error after it is judged against where the arm now stands");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
