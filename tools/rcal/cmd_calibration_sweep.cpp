// rcal calibration-sweep --robot R [--seeds N] [--position-only] [--json F]: does calibration
// reach the noise floor on this arm? Over seeded simulated cells (calibration_sweep.hpp: 0.5 mm /
// 1 mrad geometric errors, random set-up frames, a deliberately wrong starting noise), per seed:
// identified count against the rank at the truth, estimated/true noise, test-pose error against
// the truth and its Cramér–Rao prediction. Not a timed benchmark: the time column is CPU time of
// one calibration, for information.
//
// Every run has its own seed (CalibrationSeed: robot name, mode, seed index), so its figures do
// not depend on --jobs or on which other seeds run.
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <nlohmann/json.hpp>

#include "calibration_sweep.hpp"
#include "command.hpp"
#include "rcal/io/atomic_file.hpp"
#include "report.hpp"
#include "robot_setup.hpp"

namespace rcal::tool {
namespace {

using nlohmann::json;

struct Options {
  std::string robot, tip_link, base_link, json_path;
  int seeds = 20;
  unsigned first_seed = 1;
  int poses = 200, test_poses = 100;
  bool position_only = false;
  double position_sigma_mm = 0.05;
  double orientation_sigma_deg = 0.05;
  int jobs = 1;
};

json SummaryJson(const RatioSummary& s) {
  return {{"n", s.n}, {"median", s.median}, {"min", s.min}, {"max", s.max}};
}

int Run(const Options& o) {
  if (o.seeds < 1) throw std::runtime_error("--seeds: at least 1");
  if (o.poses < 3 || o.test_poses < 1) throw std::runtime_error("--poses ≥ 3, --test-poses ≥ 1");
  // The robot exactly as `rcal calibrate` loads it for such data.
  io::LoadedRobot robot = LoadRobotForCell(o.robot, o.tip_link, o.base_link, "auto");
  if (!o.position_only) AddOrientationFrame(robot);
  const kinematics::KinematicModel& model = robot.model;
  CalibrationSweepSettings s;
  s.poses = o.poses;
  s.test_poses = o.test_poses;
  s.position_only = o.position_only;
  s.position_sigma_m = o.position_sigma_mm / kMm;
  s.orientation_sigma_rad = o.orientation_sigma_deg / kDeg;
  const std::string mode = o.position_only ? "positions only" : "full pose";
  spdlog::info("{} ({}), {} parameters, {}, {} seeds from {}", model.name(), o.robot,
               model.num_params(), mode, o.seeds, o.first_seed);

  // Seeds run on --jobs threads and are reported in their fixed order afterwards.
  std::vector<CalibrationSeedResult> runs(o.seeds);
  {
    const auto t_start = std::chrono::steady_clock::now();
    std::atomic<int> next{0}, done{0};
    std::mutex log_mutex;
    const auto worker = [&] {
      for (int i = next++; i < o.seeds; i = next++) {
        runs[i] = RunCalibrationSeed(model, model.name(), s, o.first_seed + i);
        const int n = ++done;
        const double elapsed =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
        std::lock_guard lock(log_mutex);
        spdlog::info("{}/{} seeds done: {:.0f} s elapsed, ~{:.0f} s left", n, o.seeds, elapsed,
                     elapsed / n * (o.seeds - n));
      }
    };
    std::vector<std::future<void>> pool;
    for (int k = 1; k < o.jobs; ++k) pool.push_back(std::async(std::launch::async, worker));
    worker();
    for (auto& f : pool) f.get();
  }

  std::printf(
      "\n%s, %s, %d + %d poses, noise %g mm / %g°\n\n| seed | identified / rank | noise est/true "
      "(pos, ori) | test error [mm] | Cramér–Rao [mm] | test / CR (pos, ori) | LM iterations | "
      "CPU [s] |\n| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
      model.name().c_str(), mode.c_str(), o.poses, o.test_poses, o.position_sigma_mm,
      o.position_only ? 0.0 : o.orientation_sigma_deg);
  json jruns = json::array();
  std::vector<double> np, no, rp, ro, secs, ep, eo;  // e*: estimated / realized noise
  int count_eq_rank = 0;
  for (const auto& r : runs) {
    count_eq_rank += r.identified == r.rank_at_truth;
    np.push_back(r.position_noise_ratio);
    ep.push_back(r.position_noise_ratio / r.realized_position_noise_ratio);
    rp.push_back(r.position_ratio);
    secs.push_back(r.seconds);
    if (!o.position_only) {
      no.push_back(r.orientation_noise_ratio);
      eo.push_back(r.orientation_noise_ratio / r.realized_orientation_noise_ratio);
      ro.push_back(r.orientation_ratio);
    }
    std::printf("| %u | %d / %d | %.3f, %s | %.4f | %.4f | %.3f, %s | %d | %.2f |\n", r.seed_index,
                r.identified, r.rank_at_truth, r.position_noise_ratio,
                o.position_only ? "–" : Fmt(r.orientation_noise_ratio, 3).c_str(),
                r.test_position_m * kMm, r.cr_position_m * kMm, r.position_ratio,
                o.position_only ? "–" : Fmt(r.orientation_ratio, 3).c_str(), r.lm_iterations,
                r.seconds);
    jruns.push_back({{"seed_index", r.seed_index},
                     {"seed", r.seed},
                     {"identified", r.identified},
                     {"rank_at_truth", r.rank_at_truth},
                     {"last_kept_singular_value", r.last_kept_singular_value},
                     {"first_dropped_singular_value", r.first_dropped_singular_value},
                     {"position_noise_ratio", r.position_noise_ratio},
                     {"orientation_noise_ratio", r.orientation_noise_ratio},
                     {"realized_position_noise_ratio", r.realized_position_noise_ratio},
                     {"realized_orientation_noise_ratio", r.realized_orientation_noise_ratio},
                     {"test_mean_position_error_m", r.test_position_m},
                     {"cramer_rao_mean_position_error_m", r.cr_position_m},
                     {"position_error_over_cramer_rao", r.position_ratio},
                     {"test_mean_orientation_error_rad", r.test_orientation_rad},
                     {"cramer_rao_mean_orientation_error_rad", r.cr_orientation_rad},
                     {"orientation_error_over_cramer_rao", r.orientation_ratio},
                     {"lm_iterations", r.lm_iterations},
                     {"cost", r.cost},
                     {"arm_error_norm", r.x_norm},
                     {"cpu_s", r.seconds}});
  }
  const RatioSummary snp = SummarizeRatios(np), srp = SummarizeRatios(rp),
                     sno = SummarizeRatios(no), sro = SummarizeRatios(ro),
                     ssec = SummarizeRatios(secs), sep = SummarizeRatios(ep),
                     seo = SummarizeRatios(eo);
  std::printf(
      "\nidentified == rank at the truth: %d of %d seeds\nposition noise est/true: median %.3f "
      "(%.3f–%.3f)\n",
      count_eq_rank, o.seeds, snp.median, snp.min, snp.max);
  if (!o.position_only)
    std::printf("orientation noise est/true: median %.3f (%.3f–%.3f)\n", sno.median, sno.min,
                sno.max);
  std::printf("noise est/realized (this seed's noise at the truth): position %.3f (%.3f–%.3f)",
              sep.median, sep.min, sep.max);
  if (!o.position_only) std::printf(", orientation %.3f (%.3f–%.3f)", seo.median, seo.min, seo.max);
  std::printf("\n");
  std::printf("test position error / Cramér–Rao: median %.3f (%.3f–%.3f)\n", srp.median, srp.min,
              srp.max);
  if (!o.position_only)
    std::printf("test orientation error / Cramér–Rao: median %.3f (%.3f–%.3f)\n", sro.median,
                sro.min, sro.max);
  std::printf("CPU per calibration: median %.2f s (%.2f–%.2f)\n", ssec.median, ssec.min, ssec.max);

  const json j = {{"robot", model.name()},
                  {"robot_file", o.robot},
                  {"tip_link", o.tip_link},
                  {"base_link", o.base_link},
                  {"num_params", model.num_params()},
                  {"mode", o.position_only ? "position_only" : "full_pose"},
                  {"poses", o.poses},
                  {"test_poses", o.test_poses},
                  {"position_noise_m", s.position_sigma_m},
                  {"orientation_noise_rad", o.position_only ? 0.0 : s.orientation_sigma_rad},
                  {"length_error_sigma_m", s.length_error_sigma_m},
                  {"angle_error_sigma_rad", s.angle_error_sigma_rad},
                  {"start_noise_factor", s.start_noise_factor},
                  {"seeds", o.seeds},
                  {"first_seed", o.first_seed},
                  {"seed_rule", "each run's seed is a hash of (robot name, mode, seed index)"},
                  {"runs", jruns},
                  {"summary",
                   {{"identified_equals_rank", count_eq_rank},
                    {"position_noise_ratio", SummaryJson(snp)},
                    {"orientation_noise_ratio", SummaryJson(sno)},
                    {"position_noise_over_realized", SummaryJson(sep)},
                    {"orientation_noise_over_realized", SummaryJson(seo)},
                    {"position_error_over_cramer_rao", SummaryJson(srp)},
                    {"orientation_error_over_cramer_rao", SummaryJson(sro)},
                    {"cpu_s", SummaryJson(ssec)}}}};
  if (!o.json_path.empty()) io::AtomicWriteFile(o.json_path, j.dump(2));
  return 0;
}

const RegisterCommand kCalibrationSweep(
    "calibration-sweep",
    "Calibration against the truth on seeded simulated cells: rank, noise, Cramér–Rao",
    [](Args& sub) -> std::function<int()> {
      auto o = std::make_shared<Options>();
      sub.add_option("--robot", o->robot, "robot file (YAML or URDF)")->required();
      sub.add_option("--tip", o->tip_link, "URDF tip link (default: detected)");
      sub.add_option("--base-link", o->base_link, "URDF base link (default: the root)");
      sub.add_option("--seeds", o->seeds, "runs")->capture_default_str();
      sub.add_option("--first-seed", o->first_seed, "index of the first run")
          ->capture_default_str();
      sub.add_option("--poses", o->poses, "calibration poses per run")->capture_default_str();
      sub.add_option("--test-poses", o->test_poses, "independent test poses per run")
          ->capture_default_str();
      sub.add_flag("--position-only", o->position_only, "measure positions only (no orientation)");
      sub.add_option("--position-sigma-mm", o->position_sigma_mm, "position noise σ per axis")
          ->capture_default_str();
      sub.add_option("--orientation-sigma-deg", o->orientation_sigma_deg,
                     "orientation noise σ per axis (full pose)")
          ->capture_default_str();
      sub.add_option("--jobs", o->jobs, "worker threads (the figures do not depend on it)")
          ->capture_default_str()
          ->check(cli::Range(1, 64));
      sub.add_option("--json", o->json_path, "write the per-seed figures and the summary here");
      return [o]() { return Run(*o); };
    });

}  // namespace
}  // namespace rcal::tool
