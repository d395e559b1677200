// Safety confirmation (every planned motion checked by the guard first: collect's dry run),
// collection (collect_session: progress, pause, Ctrl-C, resume), identify (measure + identify
// stages), validation on held-out poses and the export.
#include "cli/cli_common.hpp"
#include "live/collect.hpp"
#include "session/session.hpp"
#include "stages/export_stage.hpp"
#include "stages/stages.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace robocal::app::wizard {
namespace {

namespace fs = std::filesystem;

CollectOptions collect_options(const WizardState& s) {
  CollectOptions o;
  o.session = s.session();
  o.robot = s.get("robot.file");
  o.cell = (s.folder / "cell.yaml").string();
  o.plan = s.get("plan.file");
  o.link = s.get("controller.link");
  o.steps_per_mm = std::stod(s.get("controller.steps_per_mm", "80"));
  o.steps_per_degree = std::stod(s.get("controller.steps_per_degree", "100"));
  o.speed = std::stod(s.get("safety.speed", "0.02"));
  o.acceleration = std::stod(s.get("safety.acceleration", "0.5"));
  std::istringstream in(s.get("cameras.list"));
  std::string item;
  while (in >> item) {
    const auto eq = item.find('=');
    o.cameras.push_back({item.substr(0, eq), item.substr(eq + 1)});
  }
  o.yes = true;  // the wizard asked (safety step, and again before a resumed collection)
  return o;
}

class SafetyStep final : public Step {
 public:
  std::string key() const override { return "safety"; }
  std::string title() const override { return "Safety check and confirmation"; }
  std::string what() const override {
    return "Every motion of the plan is checked first, without moving: inside the safe "
           "workspace, clear of obstacles along the whole path, within the actuator limits and "
           "the speed you set. Then you confirm that the cell is clear and the robot may move.";
  }
  StepOutcome run(WizardContext& ctx) override {
    for (;;) {
      ctx.state.set("safety.speed",
                    ctx.ask.ask("safety.speed", "Axis speed limit (m/s, or rad/s for rotary axes)",
                                ctx.state.get("safety.speed", "0.02")));
      ctx.state.set("safety.acceleration",
                    ctx.ask.ask("safety.acceleration", "Axis acceleration limit (per s^2)",
                                ctx.state.get("safety.acceleration", "0.5")));
      CollectOptions o = collect_options(ctx.state);
      o.dry_run = true;
      PipelineLog log;
      log.out = ctx.out;
      const CollectOutcome dry = collect_session(o, log);
      if (dry.status != "dry_run_ok") {
        say_check(ctx, false, "the safety guard refuses a motion of the plan: " + dry.message,
                  "plan again with a larger safe workspace or fewer obstacles in the way, or "
                  "lower the speed");
        if (ctx.ask.choose("safety.problem", "Retry with other limits, or stop here",
                           {"retry", "quit"}, "quit") == "quit")
          return StepOutcome::stopped("the plan has motions the safety guard refuses");
        continue;
      }
      say_check(ctx, true, "every planned motion passes the safety guard");
      fmt::print(ctx.out,
                 "Before the robot moves: is the cell clear of people and loose objects, is the "
                 "emergency stop in reach? During the collection Ctrl-C stops the robot at once "
                 "(resume later with `robocal wizard --resume {}`); kill -USR1 pauses.\n",
                 ctx.state.folder.string());
      if (!ctx.ask.confirm("safety.confirm", "The cell is clear: may the robot move", false))
        return StepOutcome::stopped("not confirmed: nothing moved");
      return StepOutcome::done();
    }
  }
};

class CollectionStep final : public Step {
 public:
  std::string key() const override { return "collection"; }
  std::string title() const override { return "Collection"; }
  std::string what() const override {
    return "The robot is homed, then driven to each planned pose; at each, every camera takes "
           "its frames and the controller's axis readings are recorded. Each pose is written "
           "whole or not at all, so an interruption loses nothing.";
  }
  StepOutcome run(WizardContext& ctx) override {
    CollectOptions o = collect_options(ctx.state);
    o.resume = fs::exists(o.session / "session.yaml");
    if (o.resume &&
        !ctx.ask.confirm("collection.continue",
                         "Continue the interrupted collection (the robot moves again)", false))
      return StepOutcome::stopped("not confirmed: nothing moved");
    PipelineLog log;
    log.out = ctx.out;
    const CollectOutcome r = collect_session(o, log);
    if (r.status == "ok") {
      say_check(ctx, true, fmt::format("every planned pose is recorded in {}", o.session.string()));
      return StepOutcome::done();
    }
    if (r.status == "interrupted") return {StepOutcome::Kind::kInterrupted, r.message, r.signal};
    return StepOutcome::stopped("collection " + r.status + ": " + r.message);
  }
};

bool has_images(const fs::path& dir) {
  if (!fs::is_directory(dir)) return false;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.path().extension() == ".png") return true;
  return false;
}

class IdentifyStep final : public Step {
 public:
  std::string key() const override { return "identify"; }
  std::string title() const override { return "Identify the geometry"; }
  std::string what() const override {
    return "The board's pose is measured in every recorded pose (the cameras' intrinsics and "
           "their relative placement come from the session's calibration views), then the "
           "robot's geometry is fitted to the measurements.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const Session s = load_session(ctx.state.session());
    std::vector<std::string> missing;
    for (const auto& c : s.cameras)
      if (!has_images(s.path(s.intrinsics_views) / c.name))
        missing.push_back((s.path(s.intrinsics_views) / c.name).string());
    if (s.cameras.size() > 1 && !has_images(s.path(s.rig_views)))
      missing.push_back(s.path(s.rig_views).string());
    if (!missing.empty()) {
      std::string list;
      for (const auto& m : missing) list += "\n    " + m;
      say_check(
          ctx, false,
          "the measurement needs calibration views that the session does not have yet:" + list,
          "the wizard cannot record calibration views live yet: record them (board "
          "images, app/SESSION.md) into those folders, then run `robocal wizard --resume " +
              ctx.state.folder.string() + "`");
      return StepOutcome::stopped("calibration views missing; the recorded poses are kept");
    }
    PipelineLog log;
    log.out = ctx.out;
    const auto measured = measure_session(ctx.state.session(), "", log);
    if (measured.value("status", "") != "ok")
      return StepOutcome::stopped("measure: " + measured.value("message", std::string("failed")));
    const auto ident = identify_session(ctx.state.session(), "", log, "pose", true);
    if (ident.value("status", "") != "ok")
      return StepOutcome::stopped("identify: " + ident.value("message", std::string("failed")));
    say_check(ctx, true, "the geometry is identified (session/results/identification.json)");
    return StepOutcome::done();
  }
};

class ValidateStep final : public Step {
 public:
  std::string key() const override { return "validate"; }
  std::string title() const override { return "Validate on held-out poses"; }
  std::string what() const override {
    return "Every K-th measured pose is left out of a second fit and predicted by it: the "
           "error on poses the fit never saw is what to expect in use.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const std::string every =
        ctx.ask.ask("validate.holdout_every", "Hold out every K-th pose", "4");
    const fs::path results = ctx.state.session() / "results";
    const fs::path json = results / "wizard_validation.json";
    const std::string measurements = (results / "measurements.yaml").string();
    const std::string robot = ctx.state.get("robot.file");
    const std::string json_path = json.string();
    const std::vector<const char*> argv = {
        "robocal", "identify",    "--measurements",  measurements.c_str(),
        "--robot", robot.c_str(), "--holdout-every", every.c_str(),
        "--quiet", "--json",      json_path.c_str()};
    const int code = run_cli(static_cast<int>(argv.size()), argv.data());
    if (code != 0 || !fs::exists(json))
      return StepOutcome::stopped(fmt::format("the held-out fit failed (exit {})", code));
    std::ifstream in(json);
    const auto j = nlohmann::json::parse(in);
    fmt::print(ctx.out, "Held-out validation: {}\n",
               j.value("validation", nlohmann::json{}).dump());
    say_check(ctx, true, "held-out validation written to " + json_path);
    return StepOutcome::done();
  }
};

class ExportStep final : public Step {
 public:
  std::string key() const override { return "export"; }
  std::string title() const override { return "Export"; }
  std::string what() const override {
    return "The calibrated robot written for the controller or another tool.";
  }
  StepOutcome run(WizardContext& ctx) override {
    std::string formats;
    for (const auto& f : export_formats()) {
      if (!formats.empty()) formats += ", ";
      formats += f;
    }
    for (;;) {
      const std::string format = ctx.ask.ask("export.format", "Format (" + formats + ")", "urdf");
      const fs::path out = ctx.state.folder / "export" / ("calibrated." + format);
      fs::create_directories(out.parent_path());
      try {
        export_robot({ctx.state.session().string(), format, out.string()});
        say_check(ctx, true, "written to " + out.string());
        return StepOutcome::done();
      } catch (const InputError& e) {
        say_check(ctx, false, e.what(), "choose a format that can describe this robot");
        if (ctx.ask.choose("export.problem", "Another format, or stop here", {"retry", "quit"},
                           "retry") == "quit")
          return StepOutcome::stopped(e.what());
      }
    }
  }
};

}  // namespace

std::unique_ptr<Step> safety_step() {
  return std::make_unique<SafetyStep>();
}
std::unique_ptr<Step> collection_step() {
  return std::make_unique<CollectionStep>();
}
std::unique_ptr<Step> identify_step() {
  return std::make_unique<IdentifyStep>();
}
std::unique_ptr<Step> validate_step() {
  return std::make_unique<ValidateStep>();
}
std::unique_ptr<Step> export_step() {
  return std::make_unique<ExportStep>();
}

}  // namespace robocal::app::wizard
