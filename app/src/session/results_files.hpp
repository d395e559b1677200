#pragma once
// The session's results files (app/SESSION.md): one type, one writer and one reader for each.
// Paths come from ResultsLayout; nothing else spells a results file name.
#include "session/results_layout.hpp"

#include "robocal/calib/identification.hpp"
#include "robocal/calib/mechanism.hpp"
#include "robocal/vision/observations.hpp"
#include "robocal/vision/pose_measurement.hpp"
#include "robocal/vision/rig_calibration.hpp"

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace robocal::app {

// ---- rig.json (session `measure` and `robocal rig`; read by measure --rig, identify, validate)

struct RigFile {
  std::vector<vision::RigCamera> cameras;  // camera_T_world = camera_T_rig
  std::vector<double> baseline_m;          // per camera (0 when the file has none)
  double corner_sigma_px = 0.0;            // the calibration's corner noise; 0 = unknown
};
// The rig's cameras as the file lists them: name, camera model, camera_T_rig, covariance.
nlohmann::json rig_cameras_json(const std::vector<vision::RigCamera>& rig);
// A calibration result as a rig file: ok, message, reference, target, rms, variance factor,
// corner_sigma_px, cameras (with baseline and its sigma). Callers add their diagnostics.
nlohmann::json rig_file_json(const vision::RigCalibrationResult& rig, const std::string& reference,
                             const std::string& target, double corner_sigma_px);
// Throws InputError naming the file and the field.
RigFile read_rig_file(const std::filesystem::path& path);

// ---- measured_poses.json (measure; read by identify and validate)

// The measured board pose as the files write it: rig_T_target (rvec/tvec), rig_T_target_matrix
// (3x4, full precision), the 6x6 covariance and its convention, quality flags, chi2, dof, rms_px,
// corners, motion_chi2. Only for a measurement with a pose (status kOk or kMoving); else an
// empty object.
nlohmann::json pose_measurement_to_json(const vision::PoseMeasurement& m);
// One robot pose's entry: pose, status, usable, message, problems, frames and the above
// (folder-mode `measure` writes the same fields).
nlohmann::json pose_measurement_json(const std::string& pose, const vision::PoseMeasurement& m,
                                     const std::vector<std::string>& problems, std::size_t frames);

struct MeasuredPoseRecord {
  std::string pose;
  vision::PoseMeasurement measurement;
  std::vector<std::string> problems;
  std::size_t frames = 0;
  double timestamp = 0.0;
  std::optional<Eigen::VectorXd> actuators;  // none: the readings were unusable
  std::string excluded;                      // why it is not used; empty: used
};
void write_measured_poses(const ResultsLayout& results,
                          const std::vector<MeasuredPoseRecord>& poses);

struct MeasuredPose {
  std::string pose;
  Eigen::VectorXd actuators;
  Eigen::Isometry3d rig_T_target = Eigen::Isometry3d::Identity();  // full precision
  Eigen::Matrix<double, 6, 6> covariance;  // as measured: [d_theta; d_t] (vision's order)
  double rms_px = 0.0;                     // the board pose fit's reprojection RMS
};
// The poses marked used, at full precision. Throws InputError (missing file: `hint`).
std::vector<MeasuredPose> read_used_measured_poses(const ResultsLayout& results,
                                                   const std::string& hint);
// The used poses as calib measurements (pose observations with their covariance).
std::vector<calib::PoseMeasurement> to_pose_measurements(const std::vector<MeasuredPose>& poses);

// ---- pixel_observations.json (measure; read by identify's camera-in-the-loop route)

// Per frame and camera, the detected corners [id, u, v, sigma] (sigma <= 0 -> default_sigma)
// and the per-tag joint corner covariances. skip_empty leaves out cameras that saw nothing.
nlohmann::json corner_observations_json(const std::vector<std::vector<vision::CameraFrame>>& frames,
                                        const std::vector<std::string>& camera_names,
                                        double default_sigma, bool skip_empty);

struct PixelPoseRecord {
  std::string pose;
  bool used = false;
  std::optional<Eigen::VectorXd> actuators;  // none: excluded (why in `excluded`)
  std::string excluded;
  nlohmann::json observations;  // corner_observations_json
};
struct PixelObservationsHeader {
  std::string robot_file, measured_frame, target;
};
void write_pixel_observations(const ResultsLayout& results, const PixelObservationsHeader& header,
                              const std::vector<PixelPoseRecord>& poses);

// One robot pose: its actuator readings and, per rig camera, the corners detected in its image
// (the camera-in-the-loop identification's input, stages/pixel_bridge.hpp).
struct PixelPose {
  std::string pose;
  Eigen::VectorXd actuators;
  std::vector<vision::CameraFrame> cameras;  // [rig camera]: frame 0's corners (empty: none)
};
// The used poses, frame 0 of each camera, in the order of `camera_names`.
std::vector<PixelPose> read_used_pixel_poses(const ResultsLayout& results,
                                             const std::vector<std::string>& camera_names,
                                             const std::string& hint);

// ---- identification.json (identify; read by validate and the summaries)

// How many of the model's parameters the identification (pose route) estimated, held and could
// not move: the one set of counts every summary prints (report page, closing summary, identify's
// terminal summary counts the same way). The identifiability analysis in the file is the first
// one, at the nominal model; a relinearised solve may estimate a few it held, so its own
// "N identifiable, M held" sentence is not these counts.
struct ParameterCounts {
  std::size_t total = 0;       // every parameter of the model
  std::size_t free = 0;        // free in the robot file: those identification may estimate
  std::size_t identified = 0;  // estimated from the measurements
  std::size_t held = 0;        // free but held at nominal: free - identified
  std::size_t no_effect = 0;   // of the held: no effect on any measurement
  [[nodiscard]] std::size_t fixed() const { return total - free; }  // fixed in the robot file
};

// The parameters as identification.json describes them, for summaries that explain them.
struct ParameterAccount {
  ParameterCounts counts;
  std::vector<std::string> names;      // every parameter, in the model's order
  std::vector<std::string> labels;     // the robot file's words for each (its name when none)
  std::vector<bool> identified;        // per parameter
  std::vector<std::string> no_effect;  // held parameters no measurement depends on (names)
  // Why each held parameter that moves the measurements is held (the identification's
  // sentence, raw names), in the analysis's order.
  std::vector<std::string> confounded;
  std::vector<std::string> weak;  // identified pairs the data barely separate (sentences)
  std::string relinearised;       // what the relinearised solve did ("": it did not run)
  bool underdetermined = false;   // fewer measurement equations than free parameters
  std::size_t equations = 0;
};
// From an identification report (identification.json's content, or identify's in-memory report);
// throws InputError naming `where` and the field when it lacks what a successful pose-route
// identification writes.
ParameterAccount parameter_account(const nlohmann::json& identification, const std::string& where);

struct IdentificationFile {
  nlohmann::json report;                          // as written
  std::string status;                             // "ok" | "failed"
  Eigen::VectorXd start;                          // the model identification started from
  Eigen::VectorXd estimate;                       // the pose route's estimate
  std::optional<Eigen::VectorXd> pixel_estimate;  // the camera-in-the-loop route's, when ok
  ParameterAccount parameters;                    // read when status is ok
};
void write_identification(const ResultsLayout& results, const nlohmann::json& report);
// Why measure refused the session's measurements as implausible (results/measure.json's board
// fit gate), or "" when it did not (or has not run).
std::string measurement_refusal(const ResultsLayout& results);
// Throws InputError when missing or malformed; start/estimate are read only when status is ok.
IdentificationFile read_identification(const ResultsLayout& results, const calib::Mechanism& model,
                                       const std::string& hint);

// ---- validation.json (validate; read by the report)

// One held-out configuration: the true position (camera 0's frame) and each model's error there.
struct HeldOutPoint {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d nominal_error = Eigen::Vector3d::Zero();     // nominal model - truth
  Eigen::Vector3d calibrated_error = Eigen::Vector3d::Zero();  // calibrated model - truth
  std::optional<bool> inside_measured_region;                  // none: region unknown
};
struct ValidationFile {
  nlohmann::json report;             // as written (summary figures, held_out_by_region, ...)
  std::string status;                // "ok" | "failed"
  std::vector<HeldOutPoint> points;  // empty: written before validate recorded them
};
// Throws InputError when missing (`hint`) or malformed (naming the field).
ValidationFile read_validation(const ResultsLayout& results, const std::string& hint);

// ---- held_out.json (the wizard's validation step; read by the report)

// Held-out validation measured by the cameras: every K-th used pose is left out of a second
// identification (the same procedure as the session's), and the model fitted without them is
// compared with where the cameras measured the board at those poses. It needs no truth, so a real
// cell has it; validation.json (`robocal validate`) compares with a simulation's truth instead.
struct HeldOutPose {
  std::string pose;
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();  // board position measured, camera 0's frame
  Eigen::Vector3d nominal_error = Eigen::Vector3d::Zero();     // nominal model - measured
  Eigen::Vector3d calibrated_error = Eigen::Vector3d::Zero();  // model fitted without - measured
};
struct HeldOutFigures {
  std::size_t poses = 0;
  double rms_m = 0.0, max_m = 0.0;
};
struct HeldOutRecord {
  int every = 0;                        // every K-th used pose was held out
  std::size_t fit_poses = 0;            // the poses the fit without them used
  std::vector<HeldOutPose> poses;       // those both models answer
  std::vector<std::string> unanswered;  // held-out poses a model could not answer
  // Over `poses`: the model fitted without them, and the nominal model with its base frame
  // fitted to the same poses. Computed by the writer from `poses`; read back as written.
  HeldOutFigures calibrated, nominal;
};
// Computes the figures from `record.poses` and writes results/held_out.json (replacing it: it
// judges the session's current measurements).
void write_held_out(const ResultsLayout& results, const HeldOutRecord& record);
// Throws InputError when missing (`hint`) or malformed (naming the file and field).
HeldOutRecord read_held_out(const ResultsLayout& results, const std::string& hint);

// ---- demo.json (demo; its stage times are read by the report)

// The demo's time per stage ("seconds"), in the file's order; empty when the session has no
// demo.json. Throws InputError when it is malformed.
std::vector<std::pair<std::string, double>> read_demo_seconds(const ResultsLayout& results);

// ---- report.html (report; a page for people, never read back)

void write_report_page(const ResultsLayout& results, const std::string& html);

// ---- truth/truth.json (simulate; read by validate only)

struct TruthCamera {
  std::string name;
  vision::CameraModel model;
  Eigen::Isometry3d camera_T_world = Eigen::Isometry3d::Identity();
};
struct TruthPose {
  std::string pose;
  Eigen::VectorXd true_actuators;
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();
};
// How the simulation drew its truth (informative: nothing computes with it).
struct TruthPerturbation {
  double length_sigma_m = 0.0;  // 1-σ tolerances the true robot was drawn with
  double angle_sigma_rad = 0.0;
  // The actuator readings' Gaussian noise and quantisation step (joint units) where the
  // simulation made the readings itself; absent where a simulated controller reports them.
  std::optional<double> actuator_noise;
  std::optional<double> actuator_step;
  std::string source;  // which simulator holds the truth
};
struct TruthFile {
  std::vector<TruthCamera> cameras;
  std::vector<TruthPose> poses;
  Eigen::VectorXd nominal, truth;  // robot parameters
  TruthPerturbation perturbation;
  // Elastic deflection of the true robot (simcell's elastic_deflection), m per m^2; 0 in files
  // written before it existed (a rigid truth).
  double elastic_sag = 0.0;
};
void write_truth(const ResultsLayout& results, const calib::Mechanism& model,
                 const TruthFile& truth);
TruthFile read_truth(const ResultsLayout& results, const calib::Mechanism& model);

}  // namespace robocal::app
