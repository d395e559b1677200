#pragma once
// The stages of a session (app/SESSION.md), one function each, each reading and writing a
// session folder: simulate -> measure -> identify -> validate. `robocal simulate / measure /
// identify / validate / batch / demo` are thin front ends over these; folder-mode `robocal rig`
// and `robocal measure --rig` run measure's steps (stages/measure_steps.hpp).
//
// Each stage returns its report (also written to results/<stage>.json) with "status":
//   "ok"        the stage produced its result
//   "failed"    it ran but the result is not acceptable (e.g. a camera calibration refused)
//   "implausible" a plausibility gate failed (GateOptions): the result must not be used
//   "no_truth"  validate only: the session has no truth/ folder (a recorded session)
// Bad input (missing or malformed files, a robot file that does not match) throws InputError.
#include "cli/command_registry.hpp"
#include "cli/progress.hpp"
#include "robocal/calib/fit_gate.hpp"
#include "stages/measure_steps.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app {

// Where a stage reports progress. out == nullptr: silent (parallel batch).
struct PipelineLog {
  std::FILE* out = stdout;
  StageClock* clock = nullptr;  // optional: sub-stages are timed on it
  int threads = 2;              // workers for rendering and detection
};

struct SimulateOptions {
  std::string robot = "rotary_delta";  // library robot name or robot file
  unsigned seed = 1;
  int poses = 60;
  // Calibration views: the intrinsics' error sets the rig frame itself (camera 0's), which every
  // measured pose inherits (a focal length 0.04 px off scales depth by 25 ppm: 30 µm at the
  // working volume), and the rig's baseline scales every stereo depth. With 96 views per camera
  // and 24 rig views the measured board positions share an offset of 12-22 µm from the truth
  // (seeds 1-3; app/SESSION.md, error budget); half as many views leave it near twice that.
  int intrinsic_views = 96;  // per camera
  int rig_views = 24;
  bool quick = false;  // 1280x960 images (CI)
  // The true robot also differs where the model cannot follow (parameters the robot file holds
  // fixed are perturbed too), as every real robot does; true: the idealised truth instead.
  bool idealised_truth = false;
  // Robot poses drawn at random (reachable, board in view) instead of planned by observability
  // (planner/): for comparison.
  bool random_poses = false;
  // Sensor read noise, grey levels (standard deviation); unset: the cell's (2). A low noise makes
  // small sessions for committed test data: noisy pixels do not compress (about 600 kB per quick
  // image at 2, a tenth of that at 0).
  std::optional<double> read_noise;
  std::filesystem::path out;
};

// The plausibility gates (measure: board fits and readings; identify: convergence and fit
// residuals). A failed gate makes the stage report "implausible" (exit 1) and keeps its result
// from being used, unless the operator accepts it explicitly (recorded in the report).
struct GateOptions {
  bool accept_implausible = false;
};

// stages/simulate.cpp
nlohmann::json simulate_session(const SimulateOptions& options, const PipelineLog& log);

// Intrinsics already calibrated from a session's own calibration views, by camera name (the
// live demo calibrates them before collection, for the settled-frame test).
using CalibratedIntrinsics = std::map<std::string, IntrinsicsStep>;

// The rig calibrated from the rig views before measure (the live demo does it while the robot
// collects), with what it was made from: the cameras (intrinsics, identity poses), the corner
// sigma per camera, and each view's image files by name (view folder / file).
struct CalibratedRig {
  std::vector<vision::RigCamera> cameras;
  std::vector<double> corner_sigma_px;
  std::vector<std::string> files;
  RigStep step;
};

// The rig's inputs as measure makes them from the intrinsics: each camera at the identity, its
// corner sigma the calibration's residual sigma (at least 0.01 px).
void rig_inputs(const std::vector<std::string>& names,
                const std::vector<vision::IntrinsicCalibrationResult>& intrinsics,
                std::vector<vision::RigCamera>& cameras, std::vector<double>& corner_sigma_px);
// The rig views' image files by name ("view_000/cam0.png", ...), as CalibratedRig::files.
std::vector<std::string> rig_view_files(const std::vector<ImageSet>& views);
// The rig calibrated from `rig_views` (a session's rig folder layout) with measure's inputs for
// `intrinsics`, silently and on `threads` workers.
CalibratedRig calibrate_rig_before_measure(const std::vector<std::string>& names,
                                           const CalibratedIntrinsics& intrinsics,
                                           const std::filesystem::path& rig_views,
                                           const vision::TargetBoard& board, int threads);

// Detections of pose images made before measure (the live demo makes them while the robot
// collects: the later shots of the cameras whose first shot showed no board, which collect's
// settled-frame test leaves out), by pose folder name; measure takes an entry only for the very
// image it was made from.
using EarlyDetections = std::map<std::string, vision::DetectionRecord>;

// The detections measure would make of the images in `pose_folder` that its record leaves out
// and that measure would detect in full (a later shot of a camera whose first shot showed no
// board), as record entries.
vision::DetectionRecord detect_unrecorded_shots(const std::filesystem::path& pose_folder,
                                                const vision::TargetBoard& board);

// stages/measure.cpp. robot_override: a robot file to use instead of the session's (checked
// against the session). `calibrated`: used instead of calibrating a camera again when computed
// from the same image files (the same names, as many); otherwise the camera is calibrated.
// `rig`: used instead of calibrating the rig again when made from the same inputs.
nlohmann::json measure_session(const std::filesystem::path& dir, const std::string& robot_override,
                               const PipelineLog& log, const GateOptions& gates = {},
                               const CalibratedIntrinsics& calibrated = {},
                               const CalibratedRig* rig = nullptr,
                               const EarlyDetections* early_detections = nullptr);
// stages/identify.cpp. route: "pose" (from the measured 6-D poses), "pixel" or "both" (also
// camera-in-the-loop from the corner pixels, started from the pose route's base-frame alignment;
// both reported). priors: the robot file's tolerances as priors (MAP) on every geometric
// parameter except the base frame (see app/SESSION.md); false = maximum likelihood from the
// measurements alone.
nlohmann::json identify_session(const std::filesystem::path& dir, const std::string& robot_override,
                                const PipelineLog& log, const std::string& route = "both",
                                bool priors = true, const GateOptions& gates = {});
// The fit gate (calib/fit_gate.hpp) on the result of identification `route` ("pose route",
// "measurements file"), recorded in report["fit_gate"]; unless it passes or
// gates.accept_implausible, report["status"] becomes "implausible" with the reason as its
// "message". Every way of identifying calls it, so a fit is refused in the same words whichever
// way its measurements came.
void apply_fit_gate(const calib::IdentificationResult& result, const calib::FitGateOptions& options,
                    const GateOptions& gates, const std::string& route, nlohmann::json& report,
                    const PipelineLog& log);
// The nominal gate: a calibrated model that predicts the measurements its fit used worse than the
// nominal model it started from (`nominal`) is no calibration: the fit was led astray (angles
// in degrees, swapped images). Compared on the measured frame's position RMS (orientation RMS
// when the measurements hold no position), with 1 % (and 0.1 µm or µrad) of slack; recorded in
// report["nominal_gate"]. When worse, report["status"] becomes "implausible" with the reason as
// its "message", whatever gates.accept_implausible says: the nominal model is the better one, so
// nothing calibrated is written. Returns whether it passed.
bool apply_nominal_gate(const calib::FramePredictor& predictor, const Eigen::VectorXd& nominal,
                        const calib::IdentificationResult& result,
                        const std::vector<calib::PoseMeasurement>& poses, const std::string& route,
                        nlohmann::json& report, const PipelineLog& log);
// stages/validate.cpp
nlohmann::json validate_session(const std::filesystem::path& dir, int held_out,
                                const PipelineLog& log);

// stages/compensate.cpp: the session's calibrated robot as commands for a controller that knows
// only the nominal model (calib/compensation.hpp). `targets`: a CSV or YAML list of task-space
// targets -> actuator readings and nominal-controller commands per target, with the verdict
// (written to `out`, stdout when empty; status "failed" when a target is refused). `gcode`: a
// program for the nominal model -> its rewrite (to `out`, atomically, only when every line could
// be compensated; otherwise InputError naming the line).
struct CompensateOptions {
  std::filesystem::path session;
  std::string robot_override;
  std::filesystem::path targets;
  std::filesystem::path gcode;
  std::filesystem::path out;
  double tolerance = 10e-6;    // m
  std::string route = "pose";  // identification route whose estimate is used: pose | pixel
  // G-code: what the controller's axis words are, "tool" or "actuators"; "" = the robot file's
  // `controller: {gcode_axes}` (refused when the file does not say either).
  std::string axes;
  // "klipper", "marlin" or "rrf": the controller runs `robocal export`'s settings for that
  // firmware (a linear delta), not the robot file's drawing; "" = the drawing.
  std::string firmware;
};
nlohmann::json compensate_session(const CompensateOptions& options, const PipelineLog& log);
// stages/report.cpp: results/report.html from the session's results (needs a successful
// identification; InputError naming what is missing otherwise). stage_seconds: the stages' times
// when the caller has them (empty: read from demo.json when the session has one).
nlohmann::json report_session(const std::filesystem::path& dir, const PipelineLog& log,
                              std::vector<std::pair<std::string, double>> stage_seconds = {});

// Exit code of a stage report: ok 0, failed 1, no_truth 3 (a missing input).
inline int exit_code_of(const nlohmann::json& report) {
  const std::string status = report.value("status", "failed");
  if (status == "ok") return kExitOk;
  if (status == "no_truth") return kExitBadInput;
  return kExitFailure;
}

// Where human-readable output goes: stdout, or stderr when the JSON report takes stdout.
inline std::FILE* human_stream(const std::string& json_path) {
  return json_path == "-" ? stderr : stdout;
}

}  // namespace robocal::app
