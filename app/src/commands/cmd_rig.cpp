// `robocal rig`: a multi-camera rig from views of a board, by the measure stage's rig step.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "session/image_folders.hpp"
#include "session/results_files.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"

#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/rig_calibration.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace robocal::app {

namespace {

struct RigArgs {
  std::vector<std::string> cameras;  // name=camera.yaml
  std::string target, views, out = "-", reference;
  bool refine_intrinsics = false;
  double sigma_px = 0.05;
  int threads = 2;
};

int run_rig(const RigArgs& a) {
  std::vector<vision::RigCamera> cams;
  for (const auto& spec : a.cameras) {
    const auto eq = spec.find('=');
    if (eq == std::string::npos || eq == 0)
      throw UsageError(fmt::format("--camera {}: expected NAME=camera.yaml", spec));
    vision::RigCamera c;
    c.name = spec.substr(0, eq);
    c.model = vision::load_camera_file(spec.substr(eq + 1));
    cams.push_back(c);
  }
  const vision::TargetBoard board = load_board(a.target);
  if (cams.empty()) throw UsageError("give at least one --camera NAME=camera.yaml");
  std::vector<std::string> names;
  names.reserve(cams.size());
  for (const auto& c : cams) names.push_back(c.name);
  RigStepOptions options;
  vision::RigCalibrationOptions& opt = options.calibration;
  opt.refine_intrinsics = a.refine_intrinsics;
  opt.default_sigma_px = a.sigma_px;
  if (!a.reference.empty()) {
    const auto it = std::find(names.begin(), names.end(), a.reference);
    if (it == names.end()) throw UsageError("--reference " + a.reference + ": no such camera");
    opt.reference_camera = static_cast<int>(it - names.begin());
  }
  const auto sets = scan_image_folder(a.views, names);
  const RigStep step = calibrate_rig_from_views(cams, board, sets, options, {stderr, a.threads});
  const auto& views = step.views;
  const auto& res = step.result;
  nlohmann::json view_json = nlohmann::json::array();
  for (std::size_t v = 0; v < sets.size(); ++v) {
    nlohmann::json per_cam = nlohmann::json::object();
    for (std::size_t c = 0; c < cams.size(); ++c)
      per_cam[cams[c].name] = step.problems[v][c].empty()
                                  ? fmt::format("{} corners", views[v][c].corners.size())
                                  : step.problems[v][c];
    view_json.push_back({{"view", sets[v].name}, {"detection", per_cam}});
  }
  if (!res.ok) {
    write_json({{"ok", res.ok}, {"message", res.message}, {"views", view_json}}, a.out);
    fmt::print(stderr, "robocal rig: {}\n", res.message);
    return kExitFailure;
  }
  nlohmann::json doc = rig_file_json(res, cams[static_cast<std::size_t>(opt.reference_camera)].name,
                                     a.target, res.rms_px);
  for (std::size_t c = 0; c < res.cameras.size(); ++c) {
    const auto& cc = res.cameras[c];
    auto& j = doc["cameras"][c];
    j["position_in_rig"] = {cc.position.x(), cc.position.y(), cc.position.z()};
    j["rms_px"] = cc.rms_px;
    j["views"] = cc.views;
    j["corners"] = cc.corners;
    if (!cc.intrinsic_sigma.empty()) j["intrinsic_sigma"] = cc.intrinsic_sigma;
  }
  for (std::size_t v = 0; v < views.size(); ++v) {
    nlohmann::json rms = nlohmann::json::object();
    for (std::size_t c = 0; c < cams.size(); ++c)
      if (!std::isnan(res.view_rms_px[v][c])) rms[cams[c].name] = res.view_rms_px[v][c];
    view_json[v]["rms_px"] = rms;
    view_json[v]["used"] = res.rig_T_board[v].has_value();
  }
  doc["views"] = view_json;
  nlohmann::json cvj = nlohmann::json::array();
  for (std::size_t c = 0; c < cams.size(); ++c) {
    if (static_cast<int>(c) == opt.reference_camera) continue;
    const auto cv = vision::opencv_stereo_calibrate(cams, board_points(board), views,
                                                    opt.reference_camera, static_cast<int>(c));
    cvj.push_back({{"camera", cams[c].name},
                   {"ok", cv.ok},
                   {"message", cv.message},
                   {"baseline_m", cv.baseline_m},
                   {"rms_px", cv.rms_px},
                   {"views", cv.views}});
  }
  doc["opencv_stereoCalibrate"] = cvj;
  write_json(doc, a.out);
  for (const auto& cc : res.cameras)
    fmt::print(stderr, "{}: baseline {:.6f} m ± {:.2f} µm, rms {:.3f} px, {} views\n", cc.name,
               cc.baseline_m, cc.baseline_sigma_m * 1e6, cc.rms_px, cc.views);
  return kExitOk;
}

}  // namespace

// `robocal rig --camera left=l.yaml --camera right=r.yaml --target board.yaml --views DIR`
CommandSpec rig_command() {
  return {
      "rig", "Calibrate a multi-camera rig from views of a board (extrinsics +- sigma)",
      [](CLI::App& cmd) -> CommandAction {
        auto a = std::make_shared<RigArgs>();
        cmd.add_option("--camera", a->cameras, "NAME=camera.yaml, once per camera")->required();
        cmd.add_option("--target", a->target, "Target file of the calibration board")->required();
        cmd.add_option("--views", a->views,
                       "Folder of view sub-folders with NAME.png per camera (vision/README_rig.md)")
            ->required();
        cmd.add_option("--reference", a->reference, "Reference camera (default: the first)");
        cmd.add_flag("--refine-intrinsics", a->refine_intrinsics,
                     "Refine every camera's intrinsics too");
        cmd.add_option("--sigma-px", a->sigma_px, "Corner noise sigma for the covariance")
            ->check(CLI::Range(1e-6, 100.0));
        cmd.add_option("--threads", a->threads, "Detection threads")->check(CLI::Range(1, 64));
        cmd.add_option("--out", a->out, "Rig JSON to write (- = stdout)");
        return [a]() { return run_rig(*a); };
      }};
}

}  // namespace robocal::app
