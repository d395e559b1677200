#include "wizard/wizard.hpp"

#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "wizard/step.hpp"

#include <fmt/core.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>

namespace robocal::app::wizard {

namespace fs = std::filesystem;

void say_check(const WizardContext& ctx, bool ok, const std::string& text,
               const std::string& advice) {
  fmt::print(ctx.out, "check: {} - {}\n", ok ? "ok" : "PROBLEM", text);
  if (!ok && !advice.empty()) fmt::print(ctx.out, "  what to do: {}\n", advice);
  std::fflush(ctx.out);
}

// Every key a step asks (steps_*.cpp, live_views.cpp), so that an answers file's key that no
// question asks is refused before the first step. A new question adds its key here.
std::vector<std::string> answer_keys() {
  return {"robot.model",
          "robot.goal",
          "controller.steps_per_mm",
          "controller.steps_per_degree",
          "controller.link",
          "controller.probed_link",
          "controller.home",
          "controller.problem",
          "controller.firmware_geometry",
          "cameras.list",
          "cameras.target",
          "cameras.size",
          "cameras.problem",
          "cell.file",
          "intrinsics.board",
          "intrinsics.problem",
          "intrinsics.*",
          "intrinsics.*.view",
          "plan.count",
          "plan.pool",
          "plan.problem",
          "safety.speed",
          "safety.acceleration",
          "safety.confirm",
          "safety.problem",
          "collection.speed",
          "collection.continue",
          "identify.views",
          "identify.rig_view",
          "validate.holdout_every",
          "validate.problem",
          "export.format",
          "export.problem",
          "export.gcode",
          "export.gcode_problem",
          "handeye.mount"};
}

std::vector<std::unique_ptr<Step>> all_steps() {
  std::vector<std::unique_ptr<Step>> s;
  s.push_back(robot_step());
  s.push_back(controller_step());
  s.push_back(cameras_step());
  s.push_back(cell_step());
  s.push_back(intrinsics_step());
  s.push_back(plan_step());
  s.push_back(safety_step());
  s.push_back(collection_step());
  s.push_back(identify_step());
  s.push_back(validate_step());
  s.push_back(export_step());
  s.push_back(hand_eye_step());
  return s;
}

namespace {

WizardState start_state(const WizardOptions& o) {
  if (o.resume) return load_state(o.folder);
  if (fs::exists(fs::path(o.folder) / "wizard.yaml"))
    throw InputError(o.folder + ": a wizard run is already there; continue it with --resume " +
                     o.folder);
  if (fs::exists(o.folder) && !fs::is_empty(o.folder))
    throw InputError(o.folder + ": exists and is not empty; give a new folder");
  fs::create_directories(o.folder);
  WizardState s;
  s.folder = fs::absolute(o.folder);
  s.save();
  return s;
}

}  // namespace

int run_wizard(const WizardOptions& o) {
  std::FILE* out = stdout;
  // The answers are checked before the folder is made or resumed: a refused file changes nothing.
  std::map<std::string, std::string> answers;
  if (!o.answers.empty()) {
    answers = load_answers(o.answers);
    reject_unknown_answers(answers, o.answers, answer_keys());
  }
  WizardState state = start_state(o);
  state.folder = fs::absolute(state.folder);
  const bool interactive = ::isatty(STDIN_FILENO) != 0;
  Prompter ask(std::move(answers), interactive, o.accept_defaults, out);
  WizardContext ctx{ask, state, out};
  const auto steps = all_steps();
  const std::string resume_hint = fmt::format("robocal wizard --resume {}", state.folder.string());
  if (o.resume)
    fmt::print(out, "Resuming the wizard in {}{}\n", state.folder.string(),
               state.current.empty() ? std::string() : fmt::format(" at step '{}'", state.current));
  int n = 0;
  for (const auto& step : steps) {
    if (!step->applies(state)) continue;
    ++n;
    // Counted on the route chosen so far (the robot step's goal decides which steps follow).
    const auto total = std::count_if(steps.begin(), steps.end(),
                                     [&state](const auto& s) { return s->applies(state); });
    if (state.is_done(step->key())) {
      if (o.resume) fmt::print(out, "Step {}/{} {}: done before\n", n, total, step->title());
      continue;
    }
    state.current = step->key();
    state.save();
    fmt::print(out, "\n== Step {}/{}: {} ==\n{}\n", n, total, step->title(), step->what());
    std::fflush(out);
    StepOutcome r;
    try {
      r = step->run(ctx);
    } catch (const MissingAnswer& e) {
      state.save();
      fmt::print(stderr,
                 "wizard: {}\nwizard: stopped at step '{}'; nothing is lost: add the "
                 "answer and run `{}`\n",
                 e.what(), step->key(), resume_hint);
      return kExitNeedsAnswer;
    } catch (const OperatorQuit& e) {
      state.save();
      fmt::print(out, "\nStopped at step '{}' ({}). Continue with `{}`\n", step->key(), e.what(),
                 resume_hint);
      return kExitFailure;
    } catch (const InputError& e) {
      state.save();
      fmt::print(stderr, "wizard: step '{}': {}\nwizard: correct it and run `{}`\n", step->key(),
                 e.what(), resume_hint);
      return kExitBadInput;
    }
    state.save();
    if (r.kind == StepOutcome::Kind::kInterrupted) {
      fmt::print(out,
                 "\nInterrupted at step '{}': the robot was stopped and every recorded pose "
                 "is kept. Continue with `{}`\n",
                 step->key(), resume_hint);
      return 128 + r.signal;
    }
    if (r.kind == StepOutcome::Kind::kStopped) {
      fmt::print(out,
                 "\nStopped at step '{}': {}\nEverything so far is kept in {}. Continue with "
                 "`{}`\n",
                 step->key(), r.message, state.folder.string(), resume_hint);
      return kExitFailure;
    }
    state.done.push_back(step->key());
    state.current.clear();
    state.save();
  }
  fmt::print(out, "\nAll steps done. The session is in {}, the {} in {}.\n",
             state.session().string(), hand_eye_only(state) ? "transforms" : "export",
             (state.folder / "export").string());
  return kExitOk;
}

}  // namespace robocal::app::wizard
