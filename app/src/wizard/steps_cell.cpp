// Intrinsics (a camera file, or calibrated from board images as `robocal intrinsics` does), the
// cell (camera placement suggested by the planner, obstacles, safe workspace) and the plan
// preview (plan.yaml, plan.svg and a summary).
#include "cli/cli_common.hpp"
#include "robocal/core/files.hpp"
#include "robocal/planner/camera_placement.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/plan.hpp"
#include "robocal/planner/plan_output.hpp"
#include "robocal/planner/task_sampling.hpp"
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/vision/camera_io.hpp"
#include "session/session_robot.hpp"
#include "stages/measure_steps.hpp"
#include "wizard/live_views.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <sstream>

namespace robocal::app::wizard {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> camera_names(const WizardState& s) {
  std::vector<std::string> names;
  std::istringstream in(s.get("cameras.list"));
  std::string item;
  while (in >> item) names.push_back(item.substr(0, item.find('=')));
  return names;
}

std::vector<fs::path> images_in(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string ext = e.path().extension().string();
    if (ext == ".png" || ext == ".tif" || ext == ".tiff" || ext == ".pgm" || ext == ".jpg")
      files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Whether the wizard's cell (the cell step's) gives `camera` a camera file.
bool cell_names_camera_file(const WizardState& s, const std::string& camera) {
  const fs::path cell = s.folder / "cell.yaml";
  if (!fs::is_regular_file(cell)) return false;
  try {
    for (const auto& c : YAML::LoadFile(cell.string())["cameras"])
      if (c["name"].as<std::string>("") == camera && c["file"]) return true;
  } catch (const YAML::Exception&) {
    // The cell step reads the cell and says what is wrong with it.
  }
  return false;
}

// The board in the calibration images: kept in the wizard's state, since the identify step
// names it in the session (measure detects it in the calibration views).
std::string ask_calibration_board(const WizardContext& ctx) {
  // One board for every camera: asked once a run (a resumed run asks again, its answer kept).
  if (ctx.ask.given().count("intrinsics.board") != 0 && !ctx.state.get("intrinsics.board").empty())
    return ctx.state.get("intrinsics.board");
  for (;;) {
    std::string file =
        ctx.ask.ask("intrinsics.board", "Target file of the calibration board in the images",
                    ctx.state.get("intrinsics.board", ctx.state.get("cameras.target")));
    try {
      (void)load_board(file);
      ctx.state.set("intrinsics.board", fs::absolute(file).string());
      ctx.state.save();
      return file;
    } catch (const InputError& e) {
      say_check(ctx, false, e.what(), "give the target file of the board held in the images");
    }
  }
}

class IntrinsicsStep final : public Step {
 public:
  std::string key() const override { return "intrinsics"; }
  std::string title() const override { return "Camera intrinsics"; }
  std::string what() const override {
    return "Each camera's lens model (focal length, centre, distortion), used to plan the poses "
           "and to check the frames (the identify step calibrates it again from the calibration "
           "views). Give a camera file you already have, 'cell' for the file the cell names, "
           "'live' to take views of the "
           "calibration board now (held at many tilts and places; the wizard shows after each "
           "view how the image is covered and what to add), or a folder of such images: the "
           "wizard calibrates from them as `robocal intrinsics` does and explains a refusal.";
  }
  StepOutcome run(WizardContext& ctx) override {
    for (const std::string& cam : camera_names(ctx.state)) {
      for (;;) {
        const std::string key = "intrinsics." + cam;
        // The cell file's camera file where it names one (the lens' datasheet values are
        // enough to plan: the identify step calibrates every camera from its views again).
        const std::string given = ctx.ask.ask(
            key, fmt::format("Intrinsics of {} (camera file, image folder, 'live' or 'cell')", cam),
            ctx.state.get(key, cell_names_camera_file(ctx.state, cam) ? "cell" : "live"));
        if (given == "cell") {
          ctx.state.set(key, "cell");
          break;
        }
        if (fs::is_regular_file(given)) {
          try {
            const auto model = vision::load_camera_file(given);
            fmt::print(ctx.out, "{}: {}x{} from {}\n", cam, model.width, model.height, given);
            ctx.state.set(key, fs::absolute(given).string());
            break;
          } catch (const std::exception& e) {
            say_check(ctx, false, e.what(), "give a camera file (vision/camera_io.hpp format)");
            continue;
          }
        }
        std::string folder = given;
        std::string board_file;
        if (given == "live") {
          board_file = ask_calibration_board(ctx);
          ctx.state.set(key, "live");  // a resumed wizard offers to go on taking views
          std::string why;
          std::optional<fs::path> taken;
          try {
            const auto [width, height] = camera_frame_size(ctx.state);
            taken = take_live_views(ctx, cam, camera_source(ctx.state, cam), load_board(board_file),
                                    width, height, why);
          } catch (const std::exception& e) {
            say_check(ctx, false, fmt::format("{}: live views: {}", cam, e.what()),
                      "check the board file and the camera (the cameras step), then retry");
            continue;
          }
          if (!taken) return StepOutcome::stopped(why);
          folder = taken->string();
        }
        if (!fs::is_directory(folder)) {
          say_check(ctx, false, fmt::format("'{}' is neither a camera file nor a folder", given),
                    "give a camera file, a folder of board images, 'live' or 'cell'");
          continue;
        }
        const auto files = images_in(folder);
        if (board_file.empty()) board_file = ask_calibration_board(ctx);
        if (files.empty()) {
          say_check(ctx, false, folder + ": no images (.png, .tif, .pgm, .jpg)",
                    "take 20-40 images of the board: near and far, tilted 20-40 degrees, "
                    "reaching every corner of the image");
          continue;
        }
        const cv::Mat first = cv::imread(files.front().string(), cv::IMREAD_UNCHANGED);
        const auto step = calibrate_camera(cam, first.cols, first.rows, files,
                                           load_board(board_file), {ctx.out, 2});
        const auto& r = step.result;
        print_coverage(ctx.out, r.coverage);
        for (const auto& w : r.warnings) fmt::print(ctx.out, "  warning: {}\n", w);
        for (const auto& a : r.advice) fmt::print(ctx.out, "  advice: {}\n", a);
        if (r.status == vision::CalibrationStatus::kOk) {
          const fs::path out = ctx.state.folder / "cameras" / (cam + ".yaml");
          fs::create_directories(out.parent_path());
          vision::save_camera_file(r.camera, out, cam);
          say_check(ctx, true,
                    fmt::format("{}: calibrated from {} views, RMS {:.3f} px", cam,
                                step.views.size(), r.rms_px));
          ctx.state.set(key, out.string());
          ctx.state.set(key + ".views", fs::absolute(folder).string());
          break;
        }
        say_check(ctx, false, fmt::format("{}: calibration refused: {}", cam, r.reason),
                  "add views as the advice says (tilt the board more, reach the image corners), "
                  "then retry");
        if (ctx.ask.choose("intrinsics.problem", "Retry with other images, or stop here",
                           {"retry", "quit"}, "retry") == "quit")
          return StepOutcome::stopped(cam + ": no intrinsics yet; resume with more views");
      }
    }
    return StepOutcome::done();
  }
};

// Relative file names in the cell resolve against the cell file's folder; the wizard's copy
// lives elsewhere, so they become absolute.
// A YAML::Node is a handle: the copy edits the same document.
// NOLINTNEXTLINE(performance-unnecessary-value-param)
void absolutise(YAML::Node node, const fs::path& base) {
  if (node.IsMap()) {
    for (auto kv : node) {
      const std::string k = kv.first.as<std::string>();
      if (kv.second.IsScalar() && (k == "file" || k == "mesh" || k == "robot")) {
        const fs::path p = kv.second.as<std::string>();
        if (p.is_relative() && fs::exists(base / p))
          kv.second = (base / p).lexically_normal().string();
      } else {
        absolutise(kv.second, base);
      }
    }
  } else if (node.IsSequence()) {
    for (auto item : node) absolutise(item, base);
  }
}

// The wizard's cell: the operator's, with the intrinsics step's camera files.
std::string wizard_cell(const WizardState& s, const std::string& cell_file) {
  YAML::Node root = YAML::LoadFile(cell_file);
  absolutise(root, fs::absolute(cell_file).parent_path());
  for (auto cam : root["cameras"]) {
    const std::string given = s.get("intrinsics." + cam["name"].as<std::string>(), "cell");
    if (given != "cell") cam["file"] = given;
  }
  YAML::Emitter e;
  e << root;
  return std::string(e.c_str()) + "\n";
}

class CellStep final : public Step {
 public:
  std::string key() const override { return "cell"; }
  std::string title() const override { return "The cell"; }
  std::string what() const override {
    return "Where the cameras are, what else is in reach (obstacles) and the box the robot may "
           "move in (the safe workspace), in a cell file (planner/README.md). The planner also "
           "suggests where cameras would see the most of the workspace.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const calib::Mechanism model = load_robot(ctx.state.get("robot.file"));
    for (;;) {
      const std::string file =
          ctx.ask.ask("cell.file", "Cell file (cameras, obstacles, workspace, target)",
                      ctx.state.get("cell.file"));
      planner::Cell cell;
      if (file.empty() || !fs::is_regular_file(file)) {
        say_check(ctx, false, file.empty() ? "no cell file given" : file + ": no such file",
                  "give the path of the cell file (planner/README.md; the library's cells are in "
                  "testdata/cells/)");
        continue;
      }
      try {
        const fs::path out = ctx.state.folder / "cell.yaml";
        core::write_file_atomic(out, wizard_cell(ctx.state, file));
        cell = planner::load_cell_file(out.string());
      } catch (const std::exception& e) {
        say_check(ctx, false, e.what(),
                  "correct the cell file (planner/README.md; examples in "
                  "testdata/cells/) and give it again");
        continue;
      }
      bool ok = true;
      for (const auto& name : camera_names(ctx.state))
        if (cell.camera_index(name) < 0) {
          say_check(ctx, false, fmt::format("the cell has no camera '{}'", name),
                    "name the cameras as the cell file does");
          ok = false;
        }
      if (!ok) continue;
      ctx.state.set("cell.file", fs::absolute(file).string());
      fmt::print(ctx.out, "Cell '{}': {} cameras, {} obstacles, clearance {:.1f} mm\n", cell.name,
                 cell.cameras.size(), cell.obstacles.size(), cell.margins.clearance * 1e3);
      say_check(
          ctx, cell.workspace.declared,
          cell.workspace.declared
              ? fmt::format("safe workspace x {:.3f}..{:.3f}, y {:.3f}..{:.3f}, z {:.3f}..{:.3f} m",
                            cell.workspace.min.x(), cell.workspace.max.x(), cell.workspace.min.y(),
                            cell.workspace.max.y(), cell.workspace.min.z(), cell.workspace.max.z())
              : "no safe workspace declared: only the actuator limits bound the motion",
          "declare `workspace: {min: [..], max: [..]}` in the cell file");
      try {
        const auto p = planner::propose_cameras(model, model.nominal_parameters(), cell);
        fmt::print(ctx.out, "Suggested camera placement: {}\n", p.summary);
        for (std::size_t i = 0; i < p.world_T_camera.size() && i < cell.cameras.size(); ++i) {
          const Eigen::Vector3d s = p.world_T_camera[i].translation();
          const Eigen::Vector3d now = cell.cameras[i].world_T_camera.translation();
          fmt::print(ctx.out,
                     "  {}: now at [{:.3f}, {:.3f}, {:.3f}], suggested [{:.3f}, {:.3f}, "
                     "{:.3f}] m (looking at [{:.3f}, {:.3f}, {:.3f}])\n",
                     cell.cameras[i].name, now.x(), now.y(), now.z(), s.x(), s.y(), s.z(),
                     p.look_at.x(), p.look_at.y(), p.look_at.z());
        }
      } catch (const std::exception& e) {
        say_check(ctx, false, std::string("no camera placement to suggest: ") + e.what(),
                  "check that the robot can reach its workspace");
      }
      return StepOutcome::done();
    }
  }
};

// A whole number of at least 1 for `key`, asked again (on a terminal) until one is given.
std::size_t ask_count(const WizardContext& ctx, const std::string& key, const std::string& question,
                      const std::string& default_value) {
  for (;;) {
    const std::string text = ctx.ask.ask(key, question, default_value);
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (end != text.c_str() && *end == '\0' && v >= 1 && v <= 1000000)
      return static_cast<std::size_t>(v);
    say_check(ctx, false, fmt::format("'{}' is not a whole number of 1 or more", text),
              "give a number such as " + default_value);
  }
}

class PlanStep final : public Step {
 public:
  std::string key() const override { return "plan"; }
  std::string title() const override { return "Plan the measurement poses"; }
  std::string what() const override {
    return "The planner picks poses the robot reaches without collision, where every camera "
           "sees the whole board, and that together tell the most about the geometry. A preview "
           "is written as an SVG (top and side views).";
  }
  StepOutcome run(WizardContext& ctx) override {
    const calib::Mechanism model = load_robot(ctx.state.get("robot.file"));
    for (unsigned attempt = 0;; ++attempt) {
      const std::size_t count =
          ask_count(ctx, "plan.count", "How many poses", ctx.state.get("plan.count", "30"));
      const std::size_t pool = ask_count(ctx, "plan.pool", "Candidate poses to choose from",
                                         ctx.state.get("plan.pool", "3000"));
      ctx.state.set("plan.count", std::to_string(count));
      ctx.state.set("plan.pool", std::to_string(pool));
      planner::Cell cell;
      try {
        const fs::path cell_out = ctx.state.folder / "cell.yaml";
        core::write_file_atomic(cell_out, wizard_cell(ctx.state, ctx.state.get("cell.file")));
        cell = planner::load_cell_file(cell_out.string());
      } catch (const std::exception& e) {
        return StepOutcome::stopped(std::string("the cell file no longer reads: ") + e.what());
      }
      planner::PlanOptions po;
      po.selection.count = count;
      po.pool = pool;
      // A retry draws other candidates: the same draw would give the same plan again.
      po.seed = 1 + 7919U * attempt;
      // The collection homes the robot first: the tour starts there, so that the first motion
      // is checked like the others.
      po.start = calib::readings_from_joint_values(model, model.nominal_parameters(),
                                                   model.home_actuated());
      // A robot whose own joints turn the board (fewer than six actuators) is planned with its
      // board turned towards the cameras; in joint space it faces them at a few per cent of
      // the samples.
      po.task_space = planner::target_turned_by_joints(model, model.task.frame);
      // The planner's own lines name its methods and constraints' internals: the operator sees
      // what it does, and the count of candidates each constraint removed below.
      po.progress = [](const std::string& /*line*/) {};
      // A delta printer's firmware cannot command a carriage below the nozzle: such candidates
      // are left out before the selection (the counts below say how many).
      std::size_t not_commandable = 0;
      if (const auto frame =
              robotio::carriage_frame_from_text(ctx.state.get("controller.firmware_frame")))
        po.admissible = [f = *frame, &not_commandable](const Eigen::VectorXd& q) {
          const bool ok = robotio::firmware_can_command(f, robotio::delta_counts(f, q));
          if (!ok) ++not_commandable;
          return ok;
        };
      fmt::print(ctx.out, "Choosing {} poses among {} candidates...\n", count, pool);
      std::fflush(ctx.out);
      // Where few candidates are feasible, up to four times as many are drawn again (each is
      // checked for reach, collision and sight: minutes for tens of thousands).
      const planner::PlanResult plan = planner::plan_with_enough_candidates(
          model, model.nominal_parameters(), cell, po, po.selection.count, 4 * pool);
      fmt::print(ctx.out, "{}\n", plan.counts.summary(false));
      if (not_commandable > 0)
        fmt::print(ctx.out,
                   "{} feasible candidates left out: the printer's firmware cannot command them "
                   "(its delta kinematics has no carriage below the nozzle)\n",
                   not_commandable);
      if (plan.poses.empty() || plan.status == planner::PlanStatus::kBadCell) {
        say_check(ctx, false, "no plan: " + plan.message,
                  "the line above says which constraint removed the candidates: move the cameras "
                  "(see the suggested placement), enlarge the safe workspace, or move obstacles; "
                  "edit the cell file, then retry");
        if (ctx.ask.choose("plan.problem", "Retry after editing the cell file, or stop here",
                           {"retry", "quit"}, "retry") == "quit")
          return StepOutcome::stopped("no feasible plan in this cell: " + plan.message);
        continue;
      }
      const fs::path yaml = ctx.state.folder / "plan.yaml";
      const fs::path svg = ctx.state.folder / "plan.svg";
      core::write_file_atomic(yaml, planner::plan_to_yaml(model, cell, plan, po));
      core::write_file_atomic(svg, planner::plan_to_svg(cell, plan));
      fmt::print(ctx.out,
                 "Plan: {} poses; the calibration they allow should place the board within "
                 "{:.1f} µm RMS ({:.1f} µm at worst) over the poses the cameras see.\n"
                 "Preview: {} (open it in a browser)\n",
                 plan.poses.size(), plan.selection.predicted_rms * 1e6,
                 plan.selection.predicted_max * 1e6, svg.string());
      for (const auto& w : plan.warnings) fmt::print(ctx.out, "  warning: {}\n", w);
      ctx.state.set("plan.file", yaml.string());
      ctx.state.set("plan.poses", std::to_string(plan.poses.size()));
      const bool accepted = plan.status == planner::PlanStatus::kOk;
      say_check(ctx, accepted,
                accepted ? "the plan is accepted" : "the plan is NOT accepted: " + plan.message,
                "retry: it draws other candidate poses; more poses (a larger count), more "
                "candidates or a larger safe workspace also help");
      if (accepted) return StepOutcome::done();
      const std::string c = ctx.ask.choose("plan.problem", "Use it anyway, retry, or stop here",
                                           {"continue", "retry", "quit"}, "retry");
      if (c == "continue") return StepOutcome::done();
      if (c == "quit") return StepOutcome::stopped("the plan is not accepted: " + plan.message);
    }
  }
};

}  // namespace

std::unique_ptr<Step> intrinsics_step() {
  return std::make_unique<IntrinsicsStep>();
}
std::unique_ptr<Step> cell_step() {
  return std::make_unique<CellStep>();
}
std::unique_ptr<Step> plan_step() {
  return std::make_unique<PlanStep>();
}

}  // namespace robocal::app::wizard
