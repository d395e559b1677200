// Safety confirmation (every planned motion checked by the guard first: collect's dry run),
// collection (collect_session: progress, pause, Ctrl-C, resume), identify (measure + identify
// stages), validation on held-out poses and the export.
#include "cli/cli_common.hpp"
#include "live/collect.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/held_out_errors.hpp"
#include "robocal/core/files.hpp"
#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/results_layout.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/export_stage.hpp"
#include "stages/stages.hpp"
#include "summary/svg_plot.hpp"
#include "summary/validation_summary.hpp"
#include "wizard/live_views.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace robocal::app::wizard {
namespace {

namespace fs = std::filesystem;

// A first run's speed: slow enough to stop by hand, fast enough that a plan of 30 poses takes
// minutes (rotary axes: 0.25 rad/s moves a 0.5 m arm's end at 0.12 m/s; linear axes 50 mm/s).
bool robot_has_linear_axes(const WizardState& s) {
  return actuator_unit(load_robot(s.get("robot.file"))) != "rad";
}
std::string default_speed(const WizardState& s) {
  return robot_has_linear_axes(s) ? "0.05" : "0.25";
}
std::string default_acceleration(const WizardState& s) {
  return robot_has_linear_axes(s) ? "0.5" : "2";
}

CollectOptions collect_options(const WizardState& s) {
  CollectOptions o;
  o.session = s.session();
  o.robot = s.get("robot.file");
  o.cell = (s.folder / "cell.yaml").string();
  o.plan = s.get("plan.file");
  o.link = s.get("controller.link");
  o.steps_per_mm = std::stod(s.get("controller.steps_per_mm", "80"));
  o.steps_per_degree = std::stod(s.get("controller.steps_per_degree", "100"));
  o.firmware_geometry =
      robotio::geometry_choice_from_string(s.get("controller.firmware_geometry", "ask"))
          .value_or(robotio::GeometryChoice::kAsk);
  o.speed = std::stod(s.get("safety.speed", default_speed(s)));
  o.acceleration = std::stod(s.get("safety.acceleration", default_acceleration(s)));
  std::istringstream in(s.get("cameras.list"));
  std::string item;
  while (in >> item) {
    const auto eq = item.find('=');
    o.cameras.push_back({item.substr(0, eq), item.substr(eq + 1)});
  }
  o.yes = true;  // the wizard asked (safety step, and again before a resumed collection)
  o.say_next_step = false;
  return o;
}

// How long the plan's motions take at the speed asked, in words.
std::string duration_words(double seconds) {
  if (seconds < 90) return fmt::format("{:.0f} s", seconds);
  if (seconds < 5400) return fmt::format("{:.0f} min", seconds / 60);
  return fmt::format("{:.1f} h", seconds / 3600);
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
      const bool linear = robot_has_linear_axes(ctx.state);
      ctx.state.set("safety.speed",
                    ctx.ask.ask("safety.speed",
                                linear ? "Axis speed limit (m/s)" : "Axis speed limit (rad/s)",
                                ctx.state.get("safety.speed", default_speed(ctx.state))));
      ctx.state.set(
          "safety.acceleration",
          ctx.ask.ask(
              "safety.acceleration",
              linear ? "Axis acceleration limit (m/s²)" : "Axis acceleration limit (rad/s²)",
              ctx.state.get("safety.acceleration", default_acceleration(ctx.state))));
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
      const double seconds = dry.summary.value("motion_seconds", 0.0);
      fmt::print(ctx.out,
                 "At this speed the robot's motions take about {} in all (homing and the "
                 "cameras' time at each pose come on top); 'speed' below sets another.\n",
                 duration_words(seconds));
      fmt::print(ctx.out,
                 "Before the robot moves: is the cell clear of people and loose objects, is the "
                 "emergency stop in reach? During the collection Ctrl-C stops the robot at once "
                 "(resume later with `robocal wizard --resume {}`); kill -USR1 pauses.\n",
                 ctx.state.folder.string());
      // No default: moving the robot is the operator's decision, typed.
      const std::string answer = ctx.ask.choose(
          "safety.confirm", "The cell is clear: may the robot move (or another speed, or stop)",
          {"yes", "speed", "no"}, "");
      if (answer == "no") return StepOutcome::stopped("not confirmed: nothing moved");
      if (answer == "yes") return StepOutcome::done();
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
    const bool resume = fs::exists(ctx.state.session() / "session.yaml");
    if (resume) {
      // A resumed collection may go on at another speed (the safety step's limits, asked again
      // of an operator; a script without that answer keeps its safety step's speed).
      if (ctx.ask.interactive() || ctx.ask.has_answer("collection.speed"))
        ctx.state.set("safety.speed",
                      ctx.ask.ask("collection.speed",
                                  robot_has_linear_axes(ctx.state) ? "Axis speed limit (m/s)"
                                                                   : "Axis speed limit (rad/s)",
                                  ctx.state.get("safety.speed", default_speed(ctx.state))));
      ctx.state.save();
      if (ctx.ask.choose("collection.continue",
                         "Continue the interrupted collection (the robot moves again)",
                         {"yes", "no"}, "") != "yes")
        return StepOutcome::stopped("not confirmed: nothing moved");
    }
    CollectOptions o = collect_options(ctx.state);
    o.resume = resume;
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

// The calibration views the session lacks: each camera's intrinsic views, and (two or more
// cameras) the rig views.
std::vector<std::string> missing_views(const Session& s) {
  std::vector<std::string> missing;
  for (const auto& c : s.cameras)
    if (!has_images(s.path(s.intrinsics_views) / c.name))
      missing.push_back((s.path(s.intrinsics_views) / c.name).string());
  if (s.cameras.size() > 1 && !has_images(s.path(s.rig_views)))
    missing.push_back(s.path(s.rig_views).string());
  return missing;
}

// A folder of calibration views laid out as app/SESSION.md says (intrinsics/ and rig/ inside):
// the one the intrinsics step's image folders came from (FOLDER/intrinsics/<camera>), if any;
// otherwise 'live' at a terminal, 'quit' without one.
std::string views_folder_guess(const WizardState& state) {
  for (const auto& [key, value] : state.values) {
    if (key.rfind("intrinsics.", 0) != 0 || key.size() < 6 ||
        key.compare(key.size() - 6, 6, ".views") != 0)
      continue;
    const fs::path folder = fs::path(value).parent_path().parent_path();
    if (fs::path(value).parent_path().filename() == "intrinsics" &&
        fs::is_directory(folder / "rig"))
      return folder.string();
  }
  return ::isatty(STDIN_FILENO) != 0 ? "live" : "quit";
}

class IdentifyStep final : public Step {
 public:
  bool applies(const WizardState& state) const override { return !hand_eye_only(state); }
  std::string key() const override { return "identify"; }
  std::string title() const override { return "Identify the geometry"; }
  std::string what() const override {
    return "The board's pose is measured in every recorded pose (the cameras' intrinsics and "
           "their relative placement come from the session's calibration views), then the "
           "robot's geometry is fitted to the measurements.";
  }
  StepOutcome run(WizardContext& ctx) override {
    Session s = load_session(ctx.state.session());
    // Views of a calibration board other than the one on the robot (the intrinsics step's
    // board): the session names it, so measure detects that board in them.
    const std::string board_file = ctx.state.get("intrinsics.board");
    if (!board_file.empty() && fs::is_regular_file(board_file) &&
        core::read_text_file(board_file) != core::read_text_file(s.path(s.calibration_target)) &&
        s.calibration_target == s.ee_target) {
      s.calibration_target = "targets/calibration.yaml";
      core::write_file_atomic(s.path(s.calibration_target), core::read_text_file(board_file),
                              core::Overwrite::kRefuse);
      core::write_file_atomic(s.dir / "session.yaml", session_to_yaml(s));
    }
    // The views the intrinsics step calibrated each camera from (taken live, or a folder given
    // there) are the session's intrinsic views: copied in where the session has none.
    for (const auto& c : s.cameras) {
      const fs::path from = ctx.state.get("intrinsics." + c.name + ".views");
      const fs::path to = s.path(s.intrinsics_views) / c.name;
      if (!from.empty() && has_images(from) && !has_images(to)) {
        fs::create_directories(to.parent_path());
        fs::copy(from, to, fs::copy_options::recursive | fs::copy_options::skip_existing);
      }
    }
    for (std::vector<std::string> missing = missing_views(s); !missing.empty();
         missing = missing_views(s)) {
      std::string list;
      for (const auto& m : missing) list += "\n    " + m;
      fmt::print(ctx.out,
                 "The measurement needs calibration views the session does not have yet:{}\n"
                 "Give a folder that holds them as app/SESSION.md lays them out "
                 "(intrinsics/<camera>/*.png, rig/view_NNN/<camera>.png; the wizard copies "
                 "them into the session), 'live' to take the rig views now (the board held "
                 "where the cameras see it at once), or 'quit' to stop and resume later.\n",
                 list);
      const std::string views = ctx.ask.ask("identify.views", "Folder with the calibration views",
                                            views_folder_guess(ctx.state));
      if (views == "quit")
        return StepOutcome::stopped("calibration views missing; the recorded poses are kept");
      if (views == "live") {
        if (has_images(s.path(s.rig_views))) {
          fmt::print(ctx.out,
                     "  the rig views are there; the intrinsic views are missing: take "
                     "them with the intrinsics step (resume it) or give a folder\n");
          continue;
        }
        std::vector<std::pair<std::string, std::string>> cameras;
        for (const auto& c : s.cameras)
          cameras.emplace_back(c.name, camera_source(ctx.state, c.name));
        std::string why;
        try {
          const auto [width, height] = camera_frame_size(ctx.state);
          if (!take_live_rig_views(ctx, cameras, load_board(s.path(s.calibration_target)), width,
                                   height, s.path(s.rig_views), why))
            return StepOutcome::stopped(why);
        } catch (const std::exception& e) {
          say_check(ctx, false, std::string("live rig views: ") + e.what(),
                    "check the cameras (the cameras step) and the board file, then retry");
        }
        continue;
      }
      if (!fs::is_directory(fs::path(views) / "intrinsics")) {
        fmt::print(ctx.out, "  {}: no intrinsics/ folder in it\n", views);
        continue;
      }
      // Recorded data is written once: only what the session does not have is copied.
      const fs::path into = ctx.state.session() / "calibration";
      fs::create_directories(into);
      for (const char* sub : {"intrinsics", "rig"})
        if (fs::is_directory(fs::path(views) / sub) && !fs::exists(into / sub))
          fs::copy(fs::path(views) / sub, into / sub, fs::copy_options::recursive);
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

// The session without its held-out poses (every K-th used pose), for the fit that must not see
// them: the session's description (session.yaml, robot, cameras, targets) by copy, and the
// identify step's board measurements of the other poses. Those do not depend on the held-out
// poses (intrinsics and rig come from the calibration views, each pose is measured on its own),
// and the identification reads nothing else, so neither the images (poses, calibration views)
// are copied nor measured again. The fit session is the wizard's own scratch, never a recording.
std::set<std::string> make_fit_session(const fs::path& session, const fs::path& fit,
                                       const std::vector<MeasuredPose>& used, int every) {
  std::set<std::string> held;
  for (std::size_t k = 0; k < used.size(); ++k)
    if ((k + 1) % static_cast<std::size_t>(every) == 0) held.insert(used[k].pose);
  const Session s = load_session(session);
  // First component of a session-relative folder ("calibration" of "calibration/intrinsics").
  const auto top = [](const std::string& folder) { return fs::path(folder).begin()->string(); };
  const std::set<std::string> images = {top(s.poses), top(s.intrinsics_views), top(s.rig_views),
                                        "results"};
  fs::remove_all(fit);
  fs::create_directories(fit);
  for (const auto& e : fs::directory_iterator(session))
    if (images.count(e.path().filename().string()) == 0)
      fs::copy(e.path(), fit / e.path().filename(), fs::copy_options::recursive);
  const ResultsLayout from{session}, to{fit};
  nlohmann::json measured = read_json_file(from.measured_poses(), "run the identify step first");
  nlohmann::json kept = nlohmann::json::array();
  for (const auto& p : measured.at("poses"))
    if (held.count(p.value("pose", std::string())) == 0) kept.push_back(p);
  measured["poses"] = kept;
  fs::create_directories(to.measured_poses().parent_path());
  write_json(measured, to.measured_poses().string());
  return held;
}

// The held-out record of the fit session `fit` (identified without the poses in `held`): at
// each held-out pose, where the cameras measured the board and each model's error there.
HeldOutRecord held_out_record(const fs::path& fit, const std::vector<MeasuredPose>& used,
                              const std::set<std::string>& held, int every) {
  const SessionRobot robot = session_robot(load_session(fit), "");
  const IdentificationFile id = read_identification(ResultsLayout{fit}, robot.model, "");
  HeldOutRecord record;
  record.every = every;
  record.fit_poses = used.size() - held.size();
  for (const auto& p : used) {
    if (held.count(p.pose) == 0) continue;
    const auto cal = calib::forward_kinematics(robot.model, id.estimate, p.actuators, robot.frame);
    const auto nom = calib::forward_kinematics(robot.model, id.start, p.actuators, robot.frame);
    if (!cal.closure.ok() || !nom.closure.ok()) {
      record.unanswered.push_back(p.pose);
      continue;
    }
    const Eigen::Vector3d measured = p.rig_T_target.translation();
    record.poses.push_back(
        {p.pose, measured, nom.pose.translation() - measured, cal.pose.translation() - measured});
  }
  return record;
}

class ValidateStep final : public Step {
 public:
  bool applies(const WizardState& state) const override { return !hand_eye_only(state); }
  std::string key() const override { return "validate"; }
  std::string title() const override { return "Validate on held-out poses"; }
  std::string what() const override {
    return "Every K-th measured pose is left out of a second identification; the model fitted "
           "without them predicts where the board was at those poses, and the cameras say "
           "where it really was. That error, on poses the fit never saw, is what to expect in "
           "use.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const std::string every_text =
        ctx.ask.ask("validate.holdout_every", "Hold out every K-th measured pose", "4");
    const int every = std::max(2, std::atoi(every_text.c_str()));
    const ResultsLayout results{ctx.state.session()};
    const auto used = read_used_measured_poses(results, "run the identify step first");
    const fs::path fit = ctx.state.folder / "validation" / "fit_session";
    const auto held = make_fit_session(ctx.state.session(), fit, used, every);
    if (held.empty())
      return StepOutcome::stopped(
          fmt::format("{} measured poses: too few to hold every {}th out; record more poses",
                      used.size(), every));
    fmt::print(ctx.out, "Fitting without {} of the {} measured poses...\n", held.size(),
               used.size());
    PipelineLog log;
    log.out = nullptr;  // the same identification as the identify step, quietly
    const auto ident = identify_session(fit, "", log, "pose", true);
    if (ident.value("status", "") != "ok")
      return StepOutcome::stopped(
          "the fit without the held-out poses failed: " + ident.value("message", std::string("?")) +
          "; record more poses (a larger plan)");
    // Into the session's results, where the report (the export step) reads it.
    write_held_out(results, held_out_record(fit, used, held, every));
    const HeldOutRecord record = read_held_out(results, "");
    const auto& cal = record.calibrated;
    const auto& nom = record.nominal;
    // Lengths as the report page writes them (µm below a millimetre), so the two agree.
    fmt::print(ctx.out,
               "On {} held-out poses, measured by the cameras ({}):\n"
               "  calibrated model: {} RMS, {} max\n"
               "  nominal model (base frame fitted): {} RMS, {} max\n",
               cal.poses, ResultsLayout::kHeldOut, svg::length(cal.rms_m), svg::length(cal.max_m),
               svg::length(nom.rms_m), svg::length(nom.max_m));
    if (!record.unanswered.empty())
      fmt::print(ctx.out, "  {} held-out poses left out: a model has no answer there ({})\n",
                 record.unanswered.size(), kNoAnswerMeaning);
    const bool better = cal.poses > 0 && cal.rms_m < nom.rms_m;
    say_check(ctx, better,
              better ? "the calibration predicts poses it never saw better than the nominal model"
                     : "the calibration does not predict the held-out poses better than the "
                       "nominal model",
              "record more poses (a larger plan), check that the board is rigidly fixed, and "
              "run the wizard again");
    if (!better && ctx.ask.choose("validate.problem", "Export anyway, or stop here",
                                  {"continue", "quit"}, "quit") == "quit")
      return StepOutcome::stopped("the validation on held-out poses failed");
    return StepOutcome::done();
  }
};

// The formats that can describe this session's calibrated robot (a dry run of each writer).
std::vector<std::string> formats_for(const fs::path& session) {
  std::vector<std::string> fit;
  for (const auto& f : export_formats()) {
    try {
      export_robot({session.string(), f, ""});
      fit.push_back(f);
    } catch (const InputError&) {
      // The format cannot describe this robot (the export step says which can).
    }
  }
  return fit;
}

class ExportStep final : public Step {
 public:
  bool applies(const WizardState& state) const override { return !hand_eye_only(state); }
  std::string key() const override { return "export"; }
  std::string title() const override { return "Export"; }
  std::string what() const override {
    return "The report page, the calibrated robot written for the controller or another tool, "
           "and G-code programs rewritten for this robot.";
  }
  StepOutcome run(WizardContext& ctx) override {
    const fs::path session = ctx.state.session();
    try {
      const auto page = report_session(session, PipelineLog{nullptr});
      say_check(ctx, true, "report page: " + page.value("page", std::string()));
    } catch (const InputError& e) {
      say_check(ctx, false, std::string("no report page: ") + e.what(),
                "`robocal report " + session.string() + "` says what is missing");
    }
    const std::optional<std::string> format = export_to_format(ctx, session);
    if (!format) return StepOutcome::stopped("no export was written");
    return rewrite_programs(ctx, session, *format)
               ? StepOutcome::done()
               : StepOutcome::stopped("a G-code program was refused");
  }

 private:
  // The format written ("none" when the operator wants none or no format fits); nullopt when the
  // operator stopped.
  static std::optional<std::string> export_to_format(WizardContext& ctx, const fs::path& session) {
    const std::vector<std::string> fit = formats_for(session);
    const fs::path own = ResultsLayout{session}.calibrated_robot();
    if (fit.empty()) {
      say_check(ctx, true,
                "no controller format (Klipper, Marlin, RepRapFirmware, URDF, DH) describes this "
                "robot; the calibrated robot file is " +
                    own.string() + ", which `robocal compensate` and `robocal kin` read");
      return std::string("none");
    }
    std::string formats;
    for (const auto& f : fit) formats += (formats.empty() ? "" : ", ") + f;
    // The settings for the firmware the link talked to, when it can take them.
    const std::string own_firmware = ctx.state.get("controller.export_format");
    const std::string proposed =
        std::find(fit.begin(), fit.end(), own_firmware) != fit.end() ? own_firmware : fit.front();
    for (;;) {
      const std::string format =
          ctx.ask.ask("export.format", "Format (" + formats + ", or none)", proposed);
      ctx.state.set("export.format", format);  // what was exported, for the record
      if (format == "none") return format;
      const fs::path out = ctx.state.folder / "export" / ("calibrated." + format);
      fs::create_directories(out.parent_path());
      try {
        const nlohmann::json written = export_robot({session.string(), format, out.string()});
        say_check(ctx, true, "written to " + out.string());
        if (written.contains("residual_rms_m"))
          say_firmware_residual(ctx, written, session, format);
        return format;
      } catch (const InputError& e) {
        say_check(ctx, false, e.what(), "choose one of: " + formats);
        if (ctx.ask.choose("export.problem", "Another format, or stop here", {"retry", "quit"},
                           "retry") == "quit")
          return std::nullopt;
      }
    }
  }

  // What the firmware's smaller delta model keeps of the calibration, beside the full model, and
  // the route that carries the rest.
  static void say_firmware_residual(const WizardContext& ctx, const nlohmann::json& written,
                                    const fs::path& session, const std::string& format) {
    fmt::print(ctx.out,
               "With these settings the firmware's own delta model is {:.0f} µm RMS ({:.0f} µm at "
               "worst) from the calibrated robot over the workspace (set to the robot file's "
               "drawing: {:.0f} µm RMS).\n",
               written.value("residual_rms_m", 0.0) * 1e6,
               written.value("residual_max_m", 0.0) * 1e6,
               written.value("nominal_rms_m", 0.0) * 1e6);
    if (written.contains("model_fit_rms_m"))
      fmt::print(ctx.out,
                 "robocal's full calibrated model follows the measurements to {:.1f} µm RMS.\n",
                 written.value("model_fit_rms_m", 0.0) * 1e6);
    fmt::print(ctx.out,
               "For the rest, G-code programs rewritten for the printer running these settings "
               "(next question, or `robocal compensate {} --firmware {} --gcode PROGRAM --out "
               "OUT`) follow the full model.\n",
               session.string(), format);
  }

  // G-code programs rewritten so that the controller puts the tool where the program meant
  // (robocal compensate --gcode): against the firmware settings just exported when they are a
  // printer's (the printer then runs them), else against the robot file's drawing.
  static bool rewrite_programs(WizardContext& ctx, const fs::path& session,
                               const std::string& exported) {
    for (;;) {
      const std::string program = ctx.ask.ask(
          "export.gcode", "A G-code program to rewrite for this robot (empty: none)", "");
      if (program.empty()) return true;
      CompensateOptions o;
      o.session = session;
      o.gcode = program;
      if (exported == "klipper" || exported == "marlin" || exported == "rrf") o.firmware = exported;
      o.out =
          ctx.state.folder / "export" / (fs::path(program).stem().string() + ".compensated.gcode");
      fs::create_directories(o.out.parent_path());
      try {
        const auto r = compensate_session(o, PipelineLog{nullptr});
        say_check(ctx, true,
                  fmt::format("{} moves rewritten to {} (largest correction {:.1f} µm)",
                              r.value("moves", 0), o.out.string(),
                              r.value("max_correction_m", 0.0) * 1e6));
        return true;
      } catch (const InputError& e) {
        say_check(ctx, false, e.what(), "fix the program (the line is named) or give another");
        if (ctx.ask.choose("export.gcode_problem", "Another program, or stop here",
                           {"retry", "quit"}, "retry") == "quit")
          return false;
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
