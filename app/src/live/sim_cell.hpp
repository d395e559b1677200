#pragma once
// `robocal sim-cell`: a simulated cell to try the shop-floor loop on without hardware. The
// simulated controller (`robocal sim-controller`, its own process: G-code over TCP and a
// pseudo-terminal, holding a true robot that differs from the drawing) and the cell's cameras,
// served as GigE Vision cameras through Aravis' fake camera where the machine gives each its
// own address (otherwise as sim:FILE cameras the wizard renders itself, said so), each showing
// the board on the simulated robot's tool. The folder holds what an operator would have: the
// cell file, the cameras' datasheet intrinsics, the board files and a folder of calibration
// images; the simulator's secrets (true geometry, true cameras) are kept apart for validation.
// It prints what to answer in `robocal wizard` and runs until Ctrl-C.
#include <filesystem>
#include <string>

namespace robocal::app {

struct SimCellOptions {
  std::string robot = "rotary_delta";
  unsigned seed = 1;
  bool quick = false;
  // The truth without the realistic cell's unmodelled error and elastic sag (a rigid robot that
  // differs from its file only where the model can follow), as `robocal demo --idealised-truth`.
  bool idealised_truth = false;
  bool gige = true;  // serve the cameras through Aravis' fake camera where possible
  std::string out;   // the cell's folder (created; a folder of an earlier sim-cell of the
                     // same robot and seed is reused)
  std::string firmware = "marlin";  // or "rrf", or "klipper" (through Moonraker)
  // A delta printer's G-code: "native" (its firmware's own delta kinematics, as printers are
  // run) or "raw" (one G-code axis per motor); Klipper is always native.
  std::string gcode_mode = "native";
  std::string protocol = "gcode";  // or "open": the open link protocol with flange poses
  int tcp_port = 0;                // the controller's TCP port (0: any free one)
  double max_seconds = 0;          // stop after this long (0: at Ctrl-C)
};

// The folder's layout, for the command's own output and the tests.
struct SimCellLayout {
  std::filesystem::path dir;
  [[nodiscard]] std::filesystem::path cell_dir() const { return dir / "cell"; }
  [[nodiscard]] std::filesystem::path views() const { return dir / "calibration_views"; }
  [[nodiscard]] std::filesystem::path simulator() const { return dir / "simulator"; }
  [[nodiscard]] std::filesystem::path answers() const { return dir / "wizard_answers.yaml"; }
};

// Runs the cell until SIGINT/SIGTERM (or max_seconds); returns the exit code.
int run_sim_cell(const SimCellOptions& options);

}  // namespace robocal::app
