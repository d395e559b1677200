#pragma once
// What the wizard has done so far, in WIZARD_FOLDER/wizard.yaml (written atomically after every
// step and every answer), so `robocal wizard --resume WIZARD_FOLDER` continues at the step that
// was interrupted. Layout of the wizard folder:
//   wizard.yaml        this state: steps done, the step in progress, values (answers and results)
//   cell.yaml          the cell the plan and collection use (the operator's, with the cameras'
//                      intrinsics files of the intrinsics step)
//   plan.yaml, plan.svg  the plan and its preview
//   session/           the recorded session (app/SESSION.md), written by collection
//   export/            the calibrated robot for the controller
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace robocal::app::wizard {

struct WizardState {
  std::filesystem::path folder;
  std::vector<std::string> done;              // step keys, in order
  std::string current;                        // the step in progress ("" = none)
  std::map<std::string, std::string> values;  // answers (step.prompt) and results (step.fact)

  [[nodiscard]] bool is_done(const std::string& step) const;
  [[nodiscard]] std::string get(const std::string& key, const std::string& fallback = "") const;
  void set(const std::string& key, const std::string& value) { values[key] = value; }
  [[nodiscard]] std::filesystem::path file() const { return folder / "wizard.yaml"; }
  [[nodiscard]] std::filesystem::path session() const { return folder / "session"; }
  void save() const;
};

// Reads WIZARD_FOLDER/wizard.yaml; InputError naming the file when it is missing or malformed.
WizardState load_state(const std::filesystem::path& folder);

}  // namespace robocal::app::wizard
