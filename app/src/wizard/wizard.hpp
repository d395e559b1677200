#pragma once
// `robocal wizard`: the guided flow of shared/reference/product.md, one step after another
// (step.hpp), its state in the wizard folder (wizard_state.hpp) so that --resume continues at
// the step that was interrupted.
#include <string>

namespace robocal::app::wizard {

struct WizardOptions {
  std::string folder;  // new wizard folder, or the one to resume
  bool resume = false;
  std::string answers;  // --answers FILE
  bool accept_defaults = false;
};

// Exit codes (also in --help): 0 every step done; 1 a step stopped (it said why and what to
// do; everything is kept, --resume continues there); 2 bad command line; 3 a bad input file (the
// answers file, a wizard folder that is not one); 5 a question has no answer and there is no
// terminal to ask (the error names the key); 130 / 143 interrupted by Ctrl-C / SIGTERM.
inline constexpr int kExitNeedsAnswer = 5;

int run_wizard(const WizardOptions& options);

}  // namespace robocal::app::wizard
