#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "session/rig_files.hpp"
#include "session/session.hpp"
#include "stages/session_pipeline.hpp"

#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>

#include <iostream>

namespace robocal::app {

namespace {

struct MeasureArgs {
  std::string session, robot, json;
  int threads = 2;
  std::string rig, target, poses, out = "-";
  double sigma_px = 0.0;
  bool no_raw = false;
};

int run_measure(const MeasureArgs& a) {
  double rig_sigma = 0.0;
  const auto rig = load_rig_json(a.rig, &rig_sigma);
  vision::TargetBoard board;
  try {
    board = vision::load_target_file(a.target);
  } catch (const vision::FileFormatError& e) {
    throw InputError(e.what());
  }
  std::vector<std::string> names;
  names.reserve(rig.size());
  for (const auto& c : rig) names.push_back(c.name);
  const auto sets = scan_image_folder(a.poses, names);
  const vision::BoardPoints points = board_points(board);
  vision::PoseMeasurementOptions opt;
  // The corner sigma: given, else the rig calibration's RMS residual, else 0.1 px.
  opt.default_sigma_px = a.sigma_px > 0 ? a.sigma_px : (rig_sigma > 0 ? rig_sigma : 0.1);

  nlohmann::json poses = nlohmann::json::array();
  int usable = 0;
  for (const auto& set : sets) {
    nlohmann::json pj;
    pj["pose"] = set.name;
    std::vector<std::string> problems;
    size_t n_frames = 0;
    for (size_t c = 0; c < rig.size(); ++c) {
      if (set.frames_of_camera[c].empty())
        problems.push_back(fmt::format("no image for camera '{}'", rig[c].name));
      n_frames = std::max(n_frames, set.frames_of_camera[c].size());
    }
    std::vector<std::vector<vision::CameraFrame>> frames(
        n_frames, std::vector<vision::CameraFrame>(rig.size()));
    for (size_t f = 0; f < n_frames; ++f)
      for (size_t c = 0; c < rig.size(); ++c) {
        if (f >= set.frames_of_camera[c].size()) continue;
        std::string problem;
        frames[f][c] = vision::CameraFrame{};
        frames[f][c] = detect_frame(set.frames_of_camera[c][f], rig[c], board, &problem);
        if (!problem.empty()) problems.push_back(problem);
      }
    vision::PoseMeasurement m;
    if (n_frames == 0) {
      m.status = vision::PoseStatus::kNotSeen;
      m.message = "no images";
    } else {
      m = vision::measure_settled_pose(rig, points, frames, opt);
    }
    pj["status"] = vision::pose_status_name(m.status);
    pj["usable"] = m.usable();
    pj["message"] = m.message;
    pj["problems"] = problems;
    pj["frames"] = n_frames;
    pj.update(pose_measurement_to_json(m));
    if (!a.no_raw) {
      // The raw observations, for camera-in-the-loop identification.
      nlohmann::json raw = nlohmann::json::array();
      for (size_t f = 0; f < n_frames; ++f)
        for (size_t c = 0; c < rig.size(); ++c) {
          nlohmann::json corners = nlohmann::json::array();
          for (const auto& o : frames[f][c].corners)
            corners.push_back({o.id, o.pixel.x(), o.pixel.y(),
                               o.sigma_px > 0 ? o.sigma_px : opt.default_sigma_px});
          raw.push_back({{"frame", f}, {"camera", rig[c].name}, {"corners", corners}});
        }
      pj["observations"] = raw;
    }
    usable += m.usable() ? 1 : 0;
    poses.push_back(pj);
    std::cerr << fmt::format("{}: {}{}\n", set.name, vision::pose_status_name(m.status),
                             m.message.empty() ? "" : " (" + m.message + ")");
  }
  nlohmann::json doc;
  doc["rig"] = a.rig;
  doc["target"] = a.target;
  doc["corner_sigma_px"] = opt.default_sigma_px;
  doc["observation_format"] = "corners: [id, u, v, sigma_px], OpenCV pixel convention";
  doc["poses"] = poses;
  doc["summary"] = {{"poses", sets.size()}, {"usable", usable}};
  write_json(doc, a.out);
  return kExitOk;
}

}  // namespace

// Session mode: intrinsics, rig and poses of a session folder into its results/.
int run_measure_session(const MeasureArgs& a) {
  PipelineLog log;
  log.out = human_stream(a.json);
  log.threads = a.threads;
  const auto report = measure_session(a.session, a.robot, log);
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
        cmd.add_option("--threads", a->threads, "Session mode: detection threads")
            ->check(CLI::Range(1, 64));
        cmd.add_option("--json", a->json, "Session mode: also write the report here (- = stdout)");
        cmd.add_option("--rig", a->rig, "Rig JSON written by `robocal rig`");
        cmd.add_option("--target", a->target, "Target file of the end-effector board");
        cmd.add_option("--poses", a->poses,
                       "Folder of pose sub-folders with NAME.png / NAME_<k>.png per camera");
        cmd.add_option("--sigma-px", a->sigma_px,
                       "Corner noise sigma (default: the rig calibration's RMS)");
        cmd.add_flag("--no-raw", a->no_raw, "Leave the raw pixel observations out");
        cmd.add_option("--out", a->out, "JSON to write (- = stdout)");
        return [a]() {
          if (!a->session.empty()) {
            if (!is_session(a->session))
              throw InputError(a->session +
                               ": not a session folder (no session.yaml; see app/SESSION.md)");
            return run_measure_session(*a);
          }
          if (a->rig.empty() || a->target.empty() || a->poses.empty())
            throw InputError("give a SESSION folder, or all of --rig, --target and --poses");
          return run_measure(*a);
        };
      }};
}

}  // namespace robocal::app
