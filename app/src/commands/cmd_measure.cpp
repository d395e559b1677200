// `robocal measure SESSION` (the measure stage) or, folder mode, `robocal measure --rig R
// --target T --poses DIR`: the measure stage's board-pose step on pose folders.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "session/image_folders.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <memory>
#include <utility>

namespace robocal::app {

namespace {

struct MeasureArgs {
  std::string session, robot, json;
  int threads = 2;
  std::string rig, target, poses, out = "-";
  double sigma_px = 0.0;
  bool no_raw = false;
  bool accept_implausible = false;
};

// A camera that gives no corners at any pose (recorded at another resolution, another camera's
// name in the rig file, a lens cap): every pose would be measured by the others alone, which is
// not the rig the user calibrated. Returns the refusal, or "" when every camera contributes.
std::string silent_camera(const std::vector<std::string>& names,
                          const std::vector<PoseImages>& measured) {
  for (std::size_t c = 0; c < names.size() && names.size() > 1; ++c) {
    bool seen = false;
    std::string first_problem;
    for (const PoseImages& images : measured) {
      for (const auto& frame : images.frames)
        seen = seen || (c < frame.size() && !frame[c].corners.empty());
      for (const auto& problem : images.problems)
        if (first_problem.empty() && problem.find(names[c]) != std::string::npos)
          first_problem = problem;
    }
    if (!seen && !measured.empty())
      return fmt::format(
          "camera '{}' gives no board corners at any of the {} poses{}: its "
          "images are not this rig's (another resolution or camera), or it never "
          "sees the board",
          names[c], measured.size(),
          first_problem.empty() ? "" : " (first: " + first_problem + ")");
  }
  return "";
}

// The board fits fail as a whole: are two of the rig file's camera names exchanged (each
// camera's images measured with the other's intrinsics and place)? Measures again with each
// pair's names exchanged (rigs of up to four cameras) and returns the sentence that says so when
// that makes the fits plausible, or "".
std::string swapped_camera_names(const std::vector<vision::RigCamera>& rig,
                                 const vision::TargetBoard& board, const std::string& poses,
                                 const PoseStepOptions& options, const BoardFitGate& gate,
                                 int threads) {
  if (rig.size() < 2 || rig.size() > 4) return "";
  for (std::size_t i = 0; i < rig.size(); ++i)
    for (std::size_t j = i + 1; j < rig.size(); ++j) {
      std::vector<vision::RigCamera> exchanged = rig;
      std::swap(exchanged[i].name, exchanged[j].name);
      std::vector<std::string> names;
      names.reserve(exchanged.size());
      for (const auto& c : exchanged) names.push_back(c.name);
      const auto measured = measure_board_poses(exchanged, board, scan_image_folder(poses, names),
                                                options, {nullptr, threads});
      const BoardFitGate other = judge_pose_fits(measured);
      if (other.verdict.plausible)
        return fmt::format(
            "the rig file's camera names '{}' and '{}' look exchanged: with them swapped the board "
            "poses fit their corners (median chi2/dof {:.3g}; as the file names them {:.3g}); "
            "check which camera each name in the rig file is, or which camera's images the "
            "pose folders hold under each name",
            rig[i].name, rig[j].name, other.verdict.median_chi2_dof, gate.verdict.median_chi2_dof);
    }
  return "";
}

int run_measure(const MeasureArgs& a) {
  const RigFile rig_file = read_rig_file(a.rig);
  const auto& rig = rig_file.cameras;
  const vision::TargetBoard board = load_board(a.target);
  std::vector<std::string> names;
  names.reserve(rig.size());
  for (const auto& c : rig) names.push_back(c.name);
  const auto sets = scan_image_folder(a.poses, names);
  PoseStepOptions options;
  // The corner sigma: given, else the rig calibration's RMS residual, else 0.1 px.
  options.measurement.default_sigma_px =
      a.sigma_px > 0 ? a.sigma_px : (rig_file.corner_sigma_px > 0 ? rig_file.corner_sigma_px : 0.1);
  const auto measured = measure_board_poses(rig, board, sets, options, {stderr, a.threads});
  if (const std::string silent = silent_camera(names, measured); !silent.empty())
    throw InputError(a.poses + ": " + silent + "; nothing written");
  // The same gate as a session's measure, with the same words.
  BoardFitGate gate = judge_pose_fits(measured);
  const bool refuse_all = !gate.verdict.plausible && !a.accept_implausible;
  if (!gate.verdict.plausible) {
    if (const std::string swapped =
            swapped_camera_names(rig, board, a.poses, options, gate, a.threads);
        !swapped.empty())
      gate.verdict.reason = a.rig + ": " + swapped + ". (" + gate.verdict.reason + ")";
    fmt::print(stderr, "MEASUREMENTS NOT PLAUSIBLE: {}{}\n", gate.verdict.reason,
               a.accept_implausible ? " (accepted: --accept-implausible)" : "");
  }

  nlohmann::json poses = nlohmann::json::array();
  int usable = 0;
  for (std::size_t p = 0; p < sets.size(); ++p) {
    const auto& m = measured[p].measurement;
    nlohmann::json pj =
        pose_measurement_json(sets[p].name, m, measured[p].problems, measured[p].frames.size());
    // The raw observations, for camera-in-the-loop identification.
    if (!a.no_raw)
      pj["observations"] = corner_observations_json(measured[p].frames, names,
                                                    options.measurement.default_sigma_px, false);
    std::string excluded;
    if (!gate.pose_problem[p].empty() && !a.accept_implausible)
      excluded = gate.pose_problem[p];
    else if (refuse_all && m.usable())
      excluded = "measurements not plausible (see board_fit_gate)";
    if (!excluded.empty()) {
      pj["usable"] = false;
      pj["excluded"] = excluded;
    }
    const bool used = m.usable() && excluded.empty();
    usable += used ? 1 : 0;
    poses.push_back(pj);
    fmt::print(stderr, "{}: {}{}{}\n", sets[p].name, vision::pose_status_name(m.status),
               m.message.empty() ? "" : " (" + m.message + ")",
               excluded.empty() ? "" : "; not usable: " + excluded);
    for (const auto& problem : measured[p].problems) fmt::print(stderr, "  {}\n", problem);
  }
  nlohmann::json doc;
  doc["rig"] = a.rig;
  doc["target"] = a.target;
  doc["corner_sigma_px"] = options.measurement.default_sigma_px;
  doc["observation_format"] = "corners: [id, u, v, sigma_px], OpenCV pixel convention";
  doc["poses"] = poses;
  doc["board_fit_gate"] = {{"plausible", gate.verdict.plausible},
                           {"median_chi2_dof", gate.verdict.median_chi2_dof},
                           {"inconsistent_poses", gate.inconsistent()},
                           {"overridden", !gate.verdict.plausible && a.accept_implausible}};
  if (!gate.verdict.plausible) doc["board_fit_gate"]["reason"] = gate.verdict.reason;
  doc["summary"] = {{"poses", sets.size()}, {"usable", usable}};
  write_json(doc, a.out);
  return refuse_all ? kExitFailure : kExitOk;
}

}  // namespace

// Session mode: intrinsics, rig and poses of a session folder into its results/.
int run_measure_session(const MeasureArgs& a) {
  PipelineLog log;
  log.out = human_stream(a.json);
  log.threads = a.threads;
  const auto report = measure_session(a.session, a.robot, log, {a.accept_implausible});
  if (!a.json.empty()) write_json(report, a.json);
  return exit_code_of(report);
}

// `robocal measure SESSION` or
// `robocal measure --rig rig.json --target ee.yaml --poses DIR --out measurements.json`
CommandSpec measure_command() {
  return {
      "measure", "Measure the end-effector target pose (with covariance) per robot pose",
      [](CLI::App& cmd) -> CommandAction {
        auto a = std::make_shared<MeasureArgs>();
        cmd.footer(
            "Two ways to call it:\n"
            "  robocal measure SESSION   a session folder (app/SESSION.md): calibrates each "
            "camera from its views, the rig from the shared views, then measures the board at "
            "every pose; writes SESSION/results/ (cameras/, rig.json, measured_poses.json, "
            "pixel_observations.json, measurements.yaml for `robocal identify SESSION`).\n"
            "  robocal measure --rig R --target T --poses DIR   pose folders with a calibrated "
            "rig (vision/README_rig.md); writes one JSON.\n"
            "Each pose gets its own status; a missing image or unreadable readings exclude that "
            "pose (named, with the reason) and the others go on. Recorded files are never "
            "changed.");
        cmd.add_option("session", a->session, "Session folder (app/SESSION.md)");
        cmd.add_option("--robot", a->robot,
                       "Session mode: robot file to use instead of the session's (checked)");
        cmd.add_option("--threads", a->threads, "Detection threads")->check(CLI::Range(1, 64));
        cmd.add_option("--json", a->json, "Session mode: also write the report here (- = stdout)");
        cmd.add_option("--rig", a->rig, "Rig JSON written by `robocal rig`");
        cmd.add_option("--target", a->target, "Target file of the end-effector board");
        cmd.add_option("--poses", a->poses,
                       "Folder of pose sub-folders with NAME.png / NAME_<k>.png per camera");
        cmd.add_option("--sigma-px", a->sigma_px,
                       "Corner noise sigma (default: the rig calibration's RMS)")
            ->check(CLI::Range(1e-6, 100.0));
        cmd.add_flag("--no-raw", a->no_raw, "Leave the raw pixel observations out");
        cmd.add_flag("--accept-implausible", a->accept_implausible,
                     "Use poses whose board fits fail the plausibility gate (recorded in "
                     "measure.json or the output's board_fit_gate); only when you know why they "
                     "fit badly");
        cmd.add_option("--out", a->out, "JSON to write (- = stdout)");
        return [a, &cmd]() {
          if (!a->session.empty()) {
            // The session's own rig, boards and pose folders are measured.
            refuse_options(cmd, {"--rig", "--target", "--poses", "--sigma-px", "--no-raw", "--out"},
                           "with a SESSION folder (its options: --robot, --threads, --json, "
                           "--accept-implausible)");
            if (!is_session(a->session))
              throw InputError(a->session +
                               ": not a session folder (no session.yaml; see app/SESSION.md)");
            return run_measure_session(*a);
          }
          refuse_options(cmd, {"--robot", "--json"},
                         "without a SESSION folder (they are a session's options)");
          if (a->rig.empty() || a->target.empty() || a->poses.empty())
            throw UsageError("give a SESSION folder, or all of --rig, --target and --poses");
          return run_measure(*a);
        };
      }};
}

}  // namespace robocal::app
