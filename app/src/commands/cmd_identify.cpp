// `robocal identify`: identify a robot's geometry from a measurements file (format:
// testdata/measurements/README.md). Writes the JSON result and, on success, the calibrated robot
// file. Also `--simulate` to write a synthetic measurements file from a perturbed robot.
#include "cli/cli_common.hpp"
#include "cli/command_registry.hpp"
#include "robocal/calib/bed_plane.hpp"
#include "robocal/calib/identification_json.hpp"
#include "robocal/calib/identification_summary.hpp"
#include "robocal/calib/measurement_advice.hpp"
#include "robocal/calib/measurements_file.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/staging.hpp"
#include "robocal_version.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/identify_setup.hpp"
#include "stages/stages.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <memory>

namespace robocal::app {
namespace {

using namespace robocal::calib;

// What the validation errors of `poses` are of: positions (points, poses), probe heights, or both.
std::string errors_of(const std::vector<PoseMeasurement>& poses) {
  bool position = false;
  bool height = false;
  for (const auto& p : poses)
    for (const auto& o : p.observations) {
      position = position || std::holds_alternative<PointObservation>(o) ||
                 std::holds_alternative<PoseObservation>(o);
      height = height || std::holds_alternative<ProbeHeightObservation>(o);
    }
  if (height && !position) return "probe height";
  if (height) return "position and probe height";
  return "position";
}

struct IdentifyOptions {
  std::string session;
  std::string robot;
  std::string measurements;
  std::string json;            // "" = stdout in file mode, none in session mode
  std::string route = "both";  // session mode: pose | pixel | both
  std::string out_robot;
  std::vector<std::string> free_patterns;
  std::vector<std::string> fix_patterns;
  bool priors = false;     // measurements-file mode: opt in
  bool no_priors = false;  // session mode: opt out
  std::string robust = "none";
  double robust_scale = 3.0;
  int multi_start = 0;
  int holdout_every = 0;
  int kfold = 0;
  unsigned seed = 1;
  // --simulate: write measurements instead of identifying.
  std::string simulate;
  int poses = 60;
  double point_sigma = 20e-6;
  double length_sigma = 0.5e-3;
  double angle_sigma_deg = 0.2;
  std::string kind = "point";
  double pixel_sigma = 0.1;
  bool free_intrinsics = false;
  bool quiet = false;               // no terminal summary
  bool stated_noise = false;        // keep the stated noise for the covariance (do not scale)
  bool bed_tilt = false;            // estimate the bed's slopes with the geometry (probe heights)
  bool accept_implausible = false;  // session mode: keep a result that fails the fit gate
};

// Simulation target: a 3x3 grid of 4 cm pitch in the measured frame plus one corner 2 cm off
// its plane (a non-coplanar target constrains the frame's orientation from every view).
std::vector<Eigen::Vector3d> grid_target() {
  std::vector<Eigen::Vector3d> pts;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j) pts.emplace_back(0.04 * i, 0.04 * j, 0.0);
  pts.emplace_back(0.0, 0.0, 0.02);
  return pts;
}

int run_simulate(const IdentifyOptions& o) {
  const std::string robot_file = resolve_robot(o.robot);  // a file or a library robot
  const Mechanism model = load_robot(robot_file);
  const MechanismPredictor pred(model);
  std::mt19937 rng(o.seed);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  const Eigen::VectorXd truth = perturb_parameters(
      nominal, tolerance_sigmas(model, o.length_sigma, o.angle_sigma_deg * M_PI / 180.0), rng);
  const auto qs = sample_actuators(pred, {nominal, truth}, static_cast<std::size_t>(o.poses), rng);
  SimulationOptions sim;
  sim.position_sigma = o.point_sigma;
  if (o.kind == "pose")
    sim.kind = SimulatedObservation::kPose;
  else if (o.kind == "probe")
    sim.kind = SimulatedObservation::kProbeHeight;
  else if (o.kind != "point" && o.kind != "pixel")
    throw UsageError("--kind must be point, pose, probe or pixel (got '" + o.kind + "')");
  MeasurementsFile file;
  file.robot = model.name;
  nlohmann::json cameras_json;
  if (o.kind == "pixel") {
    // Two cameras placed around the working volume; the file states camera 0 at its true pose
    // (the gauge) and camera 1 off by a few millimetres, as a rig calibration would leave it.
    std::vector<Eigen::Vector3d> reach;
    for (const auto& q : qs) {
      FramePrediction fp;
      std::string why;
      if (pred.predict(nominal, q, -1, false, fp, why)) reach.emplace_back(fp.pose.translation());
    }
    if (reach.empty()) throw InputError("no reachable pose to place the cameras around");
    file.cameras = cameras_below(reach);
    const Eigen::Isometry3d true_camera1 = file.cameras[1].world_T_camera;
    file.cameras[1].world_T_camera.translation() += Eigen::Vector3d(3e-3, -2e-3, 2e-3);
    const CameraRigPredictor rig(pred, file.cameras);
    Eigen::VectorXd full_truth = rig.initial_parameters(truth);
    rig.set_camera(full_truth, 1, true_camera1);
    PixelSimulationOptions ps;
    ps.pixel_sigma = o.pixel_sigma;
    file.measurements = simulate_pixel_measurements(rig, full_truth, qs, grid_target(), ps, rng);
    for (const auto& c : file.cameras) cameras_json.push_back({{"name", c.name}});
    const Eigen::Vector3d p = true_camera1.translation();
    cameras_json[1]["true_position"] = {p.x(), p.y(), p.z()};
  } else {
    file.measurements = simulate_measurements(pred, truth, qs, sim, rng);
  }
  save_measurements_file(file, o.simulate);
  nlohmann::json truth_json;
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    truth_json[model.parameters[i].name] = truth(static_cast<Eigen::Index>(i));
  nlohmann::json doc = {{"measurements", o.simulate},
                        {"poses", file.measurements.poses.size()},
                        {"truth", truth_json}};
  if (!cameras_json.is_null()) doc["cameras"] = cameras_json;
  write_json(doc, o.json);
  return kExitOk;
}

// Session mode: results/measurements.yaml of a session folder -> results/identification.json
// and results/calibrated_robot.yaml.
int run_identify_session(const IdentifyOptions& o) {
  if (!is_session(o.session))
    throw InputError(o.session + ": not a session folder (no session.yaml; see app/SESSION.md)");
  PipelineLog log;
  log.out = human_stream(o.json);
  const auto report =
      identify_session(o.session, o.robot, log, o.route, !o.no_priors, {o.accept_implausible});
  if (!o.json.empty()) write_json(report, o.json);
  if (report.value("status", "") != "ok")
    fmt::print(stderr, "identification failed: {}\n", report.value("message", ""));
  return exit_code_of(report);
}

// The bed's estimated slopes (mm/m, with σ where estimated) for the JSON report.
nlohmann::json bed_json(const IdentificationResult& res, const BedPlanePredictor& bed) {
  nlohmann::json j = {{"plane", "z = tilt_x * x + tilt_y * y (world)"}};
  for (const auto& [name, value] : {std::pair{"bed.tilt_x", bed.tilt_x(res.estimate)},
                                    std::pair{"bed.tilt_y", bed.tilt_y(res.estimate)}}) {
    nlohmann::json t = {{"mm_per_m", 1e3 * value}, {"estimated", false}};
    const auto& names = res.uncertainty.names;
    const auto it = std::find(names.begin(), names.end(), name);
    if (res.uncertainty.ok && it != names.end()) {
      t["estimated"] = true;
      t["sigma_mm_per_m"] = 1e3 * res.uncertainty.sigma(it - names.begin());
    }
    j[std::string(name).substr(4)] = t;
  }
  return j;
}

nlohmann::json advice_json(const MeasurementAdvice& a) {
  auto position = [](const Eigen::Vector3d& p) { return std::vector<double>{p.x(), p.y(), p.z()}; };
  nlohmann::json list = nlohmann::json::array();
  for (const auto& s : a.suggestions) {
    nlohmann::json j = {{"kind", s.kind},
                        {"position_m", position(s.position)},
                        {"actuators", std::vector<double>(s.actuators.data(),
                                                          s.actuators.data() + s.actuators.size())},
                        {"identifiable_after", s.rank_after}};
    if (s.kind == "distance") j["second_position_m"] = position(s.position_b);
    list.push_back(j);
  }
  return {{"identifiable_now", a.rank_before},
          {"identifiable_with_more_data", a.rank_reachable},
          {"identifiable_with_suggestions", a.rank_after},
          {"suggestions", list},
          {"text", a.text}};
}

// The cameras of pixel observations in the JSON report: reprojection errors before and after on
// the fitted and held-out poses, and each camera's estimated pose (intrinsics where estimated).
void add_cameras_json(const CameraRigPredictor& rig, const IdentificationResult& res,
                      const Eigen::VectorXd& observed_nominal,
                      const std::vector<PoseMeasurement>& fit,
                      const std::vector<PoseMeasurement>& held, bool free_intrinsics,
                      nlohmann::json& doc) {
  auto pixels = [&](const std::vector<PoseMeasurement>& poses) {
    nlohmann::json j;
    const auto n = static_cast<Eigen::Index>(rig.parameter_count());
    for (const auto& [key, params] :
         {std::pair{"before", observed_nominal}, {"after", res.estimate.head(n).eval()}}) {
      const auto e = pixel_errors(rig, params, poses);
      j[key] = {{"observations", e.observations}, {"rms_px", e.rms_px}, {"max_px", e.max_px}};
    }
    return j;
  };
  doc["fit_pixels"] = pixels(fit);
  if (!held.empty()) doc["heldout_pixels"] = pixels(held);
  nlohmann::json cams = nlohmann::json::array();
  for (int c = 0; c < rig.camera_count(); ++c) {
    const Eigen::Isometry3d T = rig.world_T_camera(res.estimate, c);
    const Eigen::AngleAxisd aa(T.linear());
    const Eigen::Vector3d rv = aa.axis() * aa.angle();
    nlohmann::json j = {
        {"name", rig.cameras()[static_cast<std::size_t>(c)].name},
        {"gauge", c == rig.options().gauge_camera},
        {"position_m", {T.translation().x(), T.translation().y(), T.translation().z()}},
        {"rotation_vector_rad", {rv.x(), rv.y(), rv.z()}}};
    if (free_intrinsics) j["params"] = rig.camera_model(res.estimate, c).params;
    cams.push_back(j);
  }
  doc["cameras"] = cams;
}

// The terminal summary: the result in words, the validation on the fitted and held-out poses,
// the calibrated robot file written (if any) and what to measure next.
std::string summary_words(const FramePredictor& pred, const Eigen::VectorXd& nominal,
                          const IdentificationResult& res, const std::vector<PoseMeasurement>& fit,
                          const std::vector<PoseMeasurement>& held,
                          const std::string& calibrated_robot, const MeasurementAdvice& advice) {
  std::string text = summary_text(res);
  text += validation_line("fit poses", validate(pred, nominal, res.estimate, fit), errors_of(fit));
  if (!held.empty())
    text += validation_line("held-out poses", validate(pred, nominal, res.estimate, held),
                            errors_of(held));
  if (!calibrated_robot.empty())
    text += fmt::format("calibrated robot file: {}\n", calibrated_robot);
  return text + advice.text;
}

int run_identify(const IdentifyOptions& o) {
  if (o.robot.empty()) throw UsageError("--robot is required (or give a SESSION folder)");
  if (o.measurements.empty()) throw UsageError("--measurements is required (or --simulate)");
  const std::string robot_file = resolve_robot(o.robot);  // a file or a library robot
  const Mechanism model = load_robot(robot_file);
  const MeasurementsFile file = load_measurements_file(o.measurements);
  if (!file.robot.empty() && file.robot != model.name)
    throw InputError(fmt::format("{}: measurements are for robot '{}', the robot file is '{}'",
                                 o.measurements, file.robot, model.name));
  int frame = -1;
  if (!file.frame.empty()) {
    frame = model.body_index(file.frame);
    if (frame < 0)
      throw InputError(fmt::format("{}: frame '{}' is not a body of {}", o.measurements, file.frame,
                                   model.name));
  }
  // The problem as the session route builds it (stages/identify_setup.hpp): the base frame
  // placed where the measured 6-D poses put it, the priors and parameters chosen.
  IdentifyChoices choices;
  choices.priors = o.priors;
  choices.free_patterns = o.free_patterns;
  choices.fix_patterns = o.fix_patterns;
  choices.robust = o.robust;
  choices.robust_scale = o.robust_scale;
  choices.stated_noise = o.stated_noise;
  choices.multi_start = o.multi_start;
  choices.seed = o.seed;
  const IdentifyProblem problem =
      identify_problem(model, frame, model.nominal_parameters(), file.measurements, choices);
  SolveOptions opt = problem.options;
  const MechanismPredictor robot_pred(model, frame);
  // Pixel observations: the cameras join the model (camera parameters after the robot's; the
  // first camera is the gauge). Otherwise the robot alone.
  std::unique_ptr<CameraRigPredictor> rig;
  if (!file.cameras.empty()) {
    CameraRigOptions ro;
    ro.estimate_intrinsics = o.free_intrinsics;
    try {
      rig = std::make_unique<CameraRigPredictor>(robot_pred, file.cameras, ro);
    } catch (const std::invalid_argument& e) {
      throw InputError(fmt::format("{}: {}", o.measurements, e.what()));
    }
  }
  const FramePredictor& observed = rig ? static_cast<const FramePredictor&>(*rig) : robot_pred;
  const Eigen::VectorXd observed_nominal =
      rig ? rig->initial_parameters(problem.start) : problem.start;
  // --bed-tilt: the bed's two slopes join the unknowns, after everything else (bed_plane.hpp).
  const BedPlanePredictor bed(observed);
  const FramePredictor& pred = o.bed_tilt ? static_cast<const FramePredictor&>(bed) : observed;
  const Eigen::VectorXd nominal =
      o.bed_tilt ? bed.initial_parameters(observed_nominal) : observed_nominal;

  if (rig) opt = rig->solve_options(opt);
  if (o.bed_tilt) opt = bed.solve_options(opt);

  // Held-out validation: every k-th pose is kept out of the fit.
  Measurements fit = file.measurements;
  std::vector<PoseMeasurement> held;
  if (o.holdout_every > 1) {
    fit.poses.clear();
    for (std::size_t k = 0; k < file.measurements.poses.size(); ++k)
      ((k + 1) % static_cast<std::size_t>(o.holdout_every) == 0 ? held : fit.poses)
          .push_back(file.measurements.poses[k]);
  }
  const IdentificationResult res = identify(pred, nominal, fit, opt);
  nlohmann::json doc = to_json(res);
  doc["robot"] = o.robot;
  doc["measurements"] = o.measurements;
  doc["robocal"] = kVersion;
  doc["fit_validation"] = to_json(validate(pred, nominal, res.estimate, fit.poses));
  if (!held.empty())
    doc["heldout_validation"] = to_json(validate(pred, nominal, res.estimate, held));
  if (o.kfold > 1)
    doc["kfold"] = to_json(k_fold_validation(pred, nominal, file.measurements, o.kfold, opt));
  if (rig) add_cameras_json(*rig, res, observed_nominal, fit.poses, held, o.free_intrinsics, doc);
  if (o.bed_tilt) doc["bed"] = bed_json(res, bed);
  // Little data or nothing identifiable: what to measure next, and where.
  MeasurementAdvice advice;
  if (res.limited_data || res.status == IdentificationStatus::kNotIdentifiable) {
    const bool solved = res.status == IdentificationStatus::kConverged ||
                        res.status == IdentificationStatus::kNotConverged;
    // Suggested points are designed for this fit: its base-set preference decides what it
    // holds at nominal; with priors it estimates everything (MAP).
    AdviceOptions advice_options;
    advice_options.preference = opt.preference;
    advice_options.map_estimator = !opt.prior_sigma.empty();
    if (advice_options.map_estimator) advice_options.prior_sigma = opt.prior_sigma;
    advice = advise_like_the_data(robot_pred, pred, solved ? res.estimate : nominal,
                                  fit.poses.empty() ? file.measurements : fit, opt.candidates,
                                  advice_options);
    doc["advice"] = advice_json(advice);
  }

  // The session route's gate, in its words: a fit far beyond its stated noise is refused and no
  // calibrated robot file written (unless --accept-implausible).
  if (res.status == IdentificationStatus::kConverged ||
      res.status == IdentificationStatus::kNotConverged) {
    PipelineLog log;
    log.out = o.quiet ? nullptr : human_stream(o.json);
    apply_fit_gate(res, fit_gate_options(model.unmodelled_error, 0.0), {o.accept_implausible},
                   "measurements file", doc, log);
    // The session route's second gate: never a calibrated model worse than the nominal one.
    if (doc.value("status", "") != "implausible")
      (void)apply_nominal_gate(pred, nominal, res, fit.poses, "measurements file", doc, log);
  }
  const bool implausible = doc.value("status", "") == "implausible";
  const bool usable = !implausible && (res.status == IdentificationStatus::kConverged ||
                                       res.status == IdentificationStatus::kNotConverged);
  // The calibrated robot file and its report are written together or not at all
  // (core/staging.hpp): never a calibrated file without the report that explains it.
  core::StagedFiles files;
  if (usable && !o.out_robot.empty()) {
    std::vector<std::string> provenance = {
        fmt::format("Calibrated by robocal {} identify ({}).", kVersion, to_string(res.status)),
        fmt::format("Measurements: {} ({} poses used, {} excluded).", o.measurements,
                    res.residuals.poses.size(), res.excluded.size()),
        fmt::format("Estimated {} parameters; fit residual RMS {:.3g} m; predicted accuracy RMS "
                    "{:.3g} m.",
                    res.estimated.size(), res.residuals.position_rms,
                    res.predicted.position_rms_overall),
        fmt::format("Nominal model: {}.", robot_file)};
    // Camera parameters (after the robot's) are reported in the JSON, not in the robot file.
    const std::string text =
        calibrated_robot_text(robot_file, model, res.estimate, res.estimated, provenance);
    files.add(o.out_robot, text);
    doc["calibrated_robot"] = o.out_robot;
  }
  if (!o.json.empty() && o.json != "-") files.add(o.json, doc.dump(2) + "\n");
  files.commit();
  if (o.json == "-") write_json(doc, "-");
  if (res.status == IdentificationStatus::kInvalidInput)
    throw InputError(fmt::format("{}: {}", o.measurements, res.message));
  // The plain-words summary always (JSON only where asked); stderr when JSON takes stdout.
  if (!o.quiet)
    fmt::print(human_stream(o.json), "{}",
               summary_words(pred, nominal, res, fit.poses, held,
                             doc.contains("calibrated_robot") ? o.out_robot : "", advice));
  if (res.status == IdentificationStatus::kNotIdentifiable) {
    fmt::print(stderr, "identification refused: {}\n{}", res.message, advice.text);
    return kExitFailure;
  }
  if (!usable) {
    fmt::print(stderr, "identification failed: {}\n",
               implausible ? doc.value("message", "") : res.message);
    return kExitFailure;
  }
  return kExitOk;
}

// Each way of calling identify has its own options; one of another way has no effect and is
// refused (a --holdout-every given with a SESSION would otherwise report no held-out figures
// without a word).
void refuse_options_of_other_modes(const CLI::App& cmd, const IdentifyOptions& o) {
  if (!o.session.empty()) {
    refuse_options(cmd, {"--measurements", "--simulate",
                         "--kfold",        "--holdout-every",
                         "--free",         "--fix",
                         "--robust",       "--robust-scale",
                         "--multi-start",  "--seed",
                         "--out-robot",    "--bed-tilt",
                         "--stated-noise", "--free-intrinsics",
                         "--kind",         "--poses",
                         "--point-sigma",  "--pixel-sigma",
                         "--length-sigma", "--angle-sigma-deg"},
                   "with a SESSION folder (its options: --robot, --route, --json, --no-priors, "
                   "--accept-implausible)");
    return;
  }
  if (!o.simulate.empty()) {
    refuse_options(
        cmd,
        {"--measurements", "--route", "--no-priors", "--priors", "--accept-implausible", "--kfold",
         "--holdout-every", "--free", "--fix", "--robust", "--robust-scale", "--multi-start",
         "--out-robot", "--bed-tilt", "--stated-noise", "--free-intrinsics"},
        "with --simulate (it writes a measurements file and identifies nothing)");
    return;
  }
  refuse_options(cmd, {"--route", "--no-priors"},
                 "with --measurements (a SESSION's options; a measurements file is fitted without "
                 "priors unless --priors)");
}

}  // namespace

CommandSpec identify_command() {
  return {"identify", "Identify the robot's geometry from a measurements file (or simulate one)",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<IdentifyOptions>();
            cmd.footer(
                "Two ways to call it:\n"
                "  robocal identify SESSION   a session folder measured by `robocal measure "
                "SESSION`: the base frame is first fitted to the measured poses, then the robot "
                "file's free parameters are identified; writes SESSION/results/"
                "identification.json and results/calibrated_robot.yaml (--robot: another robot "
                "file, checked against the session).\n"
                "  robocal identify --robot R --measurements M   any measurements file "
                "(testdata/measurements/README.md); the options below apply to this mode.\n"
                "With little data (fewer equations than free parameters) the identifiable "
                "combinations are estimated and the rest held at nominal (the gauge), said in "
                "words. Exit codes: 0 identified, 1 nothing identifiable or the solve failed "
                "(the summary says what to measure next), 2 bad command line, 3 bad robot or "
                "measurements file (file:line and the problem), 4 internal error.");
            cmd.add_option("session", o->session, "Session folder (app/SESSION.md)");
            cmd.add_option("--route", o->route,
                           "Session mode: identify from the measured 6-D poses (pose), or also "
                           "directly from the corner pixels with the camera poses estimated "
                           "(camera-in-the-loop; pixel and both run both and report both)")
                ->check(CLI::IsMember({"pose", "pixel", "both"}))
                ->capture_default_str();
            cmd.add_option("--robot", o->robot, "Robot file (YAML)");
            cmd.add_option("--measurements", o->measurements,
                           "Measurements file (testdata/measurements/README.md)");
            cmd.add_option("--json", o->json,
                           "Result JSON file ('-' = stdout; the summary then goes to stderr)");
            cmd.add_flag("--quiet", o->quiet, "No terminal summary");
            cmd.add_flag("--bed-tilt", o->bed_tilt,
                         "Probe heights are measured against a bed that may not be level: its two "
                         "slopes are estimated with the geometry (where the data cannot tell them "
                         "from the endstops, the bed is held level and the summary says so; a "
                         "printed part measured with a caliper separates them)");
            cmd.add_flag("--stated-noise", o->stated_noise,
                         "Keep the stated measurement noise for the uncertainties (e.g. it comes "
                         "from the detector's covariance). Default: the noise of each observation "
                         "type is estimated from the residuals and the covariance scaled by it; "
                         "both are reported");
            cmd.add_option("--out-robot", o->out_robot,
                           "Write the calibrated robot file here (only when the solve succeeds)");
            cmd.add_option("--free", o->free_patterns,
                           "Parameters to estimate (glob on names, repeatable; default: the robot "
                           "file's free parameters)");
            cmd.add_option("--fix", o->fix_patterns, "Parameters to hold (glob, repeatable)");
            cmd.add_flag("--priors", o->priors,
                         "Measurements file: use the robot file's tolerances as priors (MAP); a "
                         "SESSION always does unless --no-priors");
            cmd.add_flag("--no-priors", o->no_priors,
                         "SESSION: maximum likelihood from the measurements alone (default: the "
                         "robot file's tolerances as priors, base frame free)")
                ->excludes("--priors");
            cmd.add_option("--robust", o->robust, "Robust loss: none, huber or cauchy");
            cmd.add_option("--robust-scale", o->robust_scale, "Robust loss scale in sigmas")
                ->check(CLI::Range(0.1, 100.0))
                ->capture_default_str();
            cmd.add_option("--multi-start", o->multi_start, "Extra perturbed starts")
                ->check(CLI::Range(0, 1000));
            cmd.add_option("--holdout-every", o->holdout_every,
                           "Hold every k-th pose out of the fit and validate on it (0 = none)")
                ->check(CLI::Range(0, 1000000));
            cmd.add_option("--kfold", o->kfold, "k-fold cross-validation with k folds (0 = none)")
                ->check(CLI::Range(0, 1000));
            cmd.add_option("--seed", o->seed, "Random seed (multi-start, simulation)");
            cmd.add_option("--simulate", o->simulate,
                           "Write a synthetic measurements file from a randomly perturbed robot "
                           "instead of identifying");
            cmd.add_option("--poses", o->poses, "Simulation: number of poses")
                ->check(CLI::Range(1, 100000));
            cmd.add_option("--point-sigma", o->point_sigma, "Simulation: noise sigma (m)")
                ->check(CLI::Range(0.0, 1.0));
            cmd.add_option("--kind", o->kind,
                           "Simulation: point, pose, probe or pixel observations (pixel: two "
                           "simulated cameras)");
            cmd.add_option("--pixel-sigma", o->pixel_sigma, "Simulation: pixel noise sigma (px)")
                ->check(CLI::Range(0.0, 100.0));
            cmd.add_flag("--accept-implausible", o->accept_implausible,
                         "Write the calibrated robot file even when the fit gate fails (not "
                         "converged, residuals far beyond the measurement noise); recorded in the "
                         "JSON report (fit_gate.overridden)");
            cmd.add_flag(
                "--free-intrinsics", o->free_intrinsics,
                "Pixel observations: estimate the cameras' intrinsics too (default: held)");
            cmd.add_option("--length-sigma", o->length_sigma,
                           "Simulation: perturbation sigma of lengths (m)");
            cmd.add_option("--angle-sigma-deg", o->angle_sigma_deg,
                           "Simulation: perturbation sigma of angles (deg)");
            return [o, &cmd]() {
              refuse_options_of_other_modes(cmd, *o);
              if (!o->session.empty()) return run_identify_session(*o);
              if (o->robot.empty()) throw UsageError("--robot is required (or give a SESSION)");
              return o->simulate.empty() ? run_identify(*o) : run_simulate(*o);
            };
          }};
}

}  // namespace robocal::app
