#pragma once
// One step of the guided flow (shared/reference/product.md): it explains what it does, asks its
// questions, does its work through the libraries, checks its own result and says what to do when
// something is off. Steps keep what later steps need in the wizard state (wizard_state.hpp).
#include "wizard/prompter.hpp"
#include "wizard/wizard_state.hpp"

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace robocal::app::wizard {

struct WizardContext {
  Prompter& ask;
  WizardState& state;
  std::FILE* out;
};

struct StepOutcome {
  // done: go on. stopped: the operator chose to stop, or the step cannot go on (message says why
  // and what to do); everything is kept and --resume starts this step again. interrupted: a
  // signal stopped it (collection: Ctrl-C / SIGTERM), exit 128 + signal.
  enum class Kind { kDone, kStopped, kInterrupted };
  Kind kind = Kind::kDone;
  std::string message;
  int signal = 0;
  static StepOutcome done() { return {}; }
  static StepOutcome stopped(std::string why) { return {Kind::kStopped, std::move(why), 0}; }
};

class Step {
 public:
  virtual ~Step() = default;
  Step() = default;
  Step(const Step&) = delete;
  Step& operator=(const Step&) = delete;
  Step(Step&&) = delete;
  Step& operator=(Step&&) = delete;

  [[nodiscard]] virtual std::string key() const = 0;    // prompt prefix and state name
  [[nodiscard]] virtual std::string title() const = 0;  // one line, plain words
  [[nodiscard]] virtual std::string what() const = 0;   // what the step does and why
  // Whether the step belongs to the route the operator chose (robot.goal): a hand-eye
  // calibration has no identification, validation or robot export.
  [[nodiscard]] virtual bool applies(const WizardState& /*state*/) const { return true; }
  virtual StepOutcome run(WizardContext& ctx) = 0;
};

// The operator chose to locate only the cameras and the board (robot.goal: handeye).
inline bool hand_eye_only(const WizardState& state) {
  return state.get("robot.goal") == "handeye";
}

// The steps, in the order they run (steps_*.cpp).
std::vector<std::unique_ptr<Step>> all_steps();
// The keys an answers file may hold (glob patterns; * is a camera name).
std::vector<std::string> answer_keys();

// steps_setup.cpp
std::unique_ptr<Step> robot_step();
std::unique_ptr<Step> controller_step();
std::unique_ptr<Step> cameras_step();
// steps_cell.cpp
std::unique_ptr<Step> intrinsics_step();
std::unique_ptr<Step> cell_step();
std::unique_ptr<Step> plan_step();
// steps_run.cpp
std::unique_ptr<Step> safety_step();
std::unique_ptr<Step> collection_step();
std::unique_ptr<Step> identify_step();
std::unique_ptr<Step> validate_step();
std::unique_ptr<Step> export_step();
// steps_hand_eye.cpp
std::unique_ptr<Step> hand_eye_step();

// Prints "check: ok - text" or "check: PROBLEM - text" and advice.
void say_check(const WizardContext& ctx, bool ok, const std::string& text,
               const std::string& advice = "");

}  // namespace robocal::app::wizard
