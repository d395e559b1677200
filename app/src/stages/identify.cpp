// The identify stage on a session: the base frame fitted to the measured poses, then the robot's
// geometry from the measured 6-D poses (pose route) and, camera-in-the-loop, from the corner
// pixels (pixel route). Writes results/identification.json and the calibrated robot files.
#include "cli/cli_common.hpp"
#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/results_transaction.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/identify_setup.hpp"
#include "stages/measure_steps.hpp"
#include "stages/pixel_bridge.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"

#include "robocal/calib/fit_gate.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/identification_json.hpp"
#include "robocal/calib/identification_summary.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/core/angles.hpp"
#include "robocal/core/files.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>

#include <map>
#include <set>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

std::string measure_first(const fs::path& dir) {
  return "run `robocal measure " + dir.string() + "` first";
}

// The camera-in-the-loop route on a session: the corner pixels of results/pixel_observations.json
// (the poses the pose route used, first frame per camera) with the measured rig's cameras, camera
// 0 as the world, camera 1.. poses estimated with the robot; started from the pose route's
// base-frame alignment. Returns the route's report (its estimate as {parameter: value}).
nlohmann::json identify_pixel_route(const Session& s, const calib::Mechanism& model,
                                    const calib::FramePredictor& predictor,
                                    const Eigen::VectorXd& start,
                                    const calib::SolveOptions& options,
                                    const std::map<std::string, Eigen::Isometry3d>& rig_T_target,
                                    const PipelineLog& log, const GateOptions& gates) {
  const ResultsLayout results{s.dir};
  const auto rig = read_rig_file(results.rig()).cameras;
  const auto target = board_points(load_board(s.path(s.ee_target)));
  std::vector<std::string> camera_names;
  camera_names.reserve(rig.size());
  for (const auto& c : rig) camera_names.push_back(c.name);
  const std::vector<PixelPose> poses =
      read_used_pixel_poses(results, camera_names, measure_first(s.dir));
  nlohmann::json report;
  // Every camera's corners count, partial views of the board included. (Until the detector
  // dropped the AprilTags cut by the image border, a camera needed half the board: on the
  // Gantry-Tau's array, demo --seed 1, corners of such tags 10 px off took this route from 0.030
  // to 0.160 px RMS. With the detector fixed, all corners give 0.029 px, and 25.9 against
  // 29.3 µm held-out.)
  const PixelBridgeOptions bridge;
  const auto route = identify_from_pixels(predictor, start, options, rig, target, poses, bridge);
  const auto& r = route.result;
  say(log,
      "  pixels (camera-in-the-loop): {}: {} poses, {} parameters (robot + camera poses), {} "
      "iterations, {:.2f} s, reprojection {:.3f} px RMS\n",
      calib::to_string(r.status), r.residuals.poses.size(), r.estimated.size(), r.iterations,
      r.solve_seconds, route.fit_pixels.rms_px);
  report["result"] = calib::to_json(r);
  report["reprojection_rms_px"] = route.fit_pixels.rms_px;
  report["skipped"] = route.input.skipped;
  report["estimate"] = params_json(model, route.robot_estimate);
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t c = 0; c < route.world_T_camera.size() && c < rig.size(); ++c)
    cams.push_back(
        {{"camera", rig[c].name}, {"world_T_camera", pose_to_json(route.world_T_camera[c])}});
  report["cameras"] = cams;
  const bool usable = r.status == calib::IdentificationStatus::kConverged ||
                      r.status == calib::IdentificationStatus::kNotConverged;
  report["status"] = usable ? "ok" : "failed";
  if (!usable) report["message"] = r.message;
  // The robot's unmodelled error as the cameras see it (the pixels a metre spans at the board).
  const double pixels_per_metre = median_pixels_per_metre(rig, poses, rig_T_target);
  report["pixels_per_metre"] = pixels_per_metre;
  if (usable)
    apply_fit_gate(r, calib::fit_gate_options(model.unmodelled_error, pixels_per_metre), gates,
                   "pixels", report, log);
  return report;
}

// The calibrated file is the measurement model: which frame stands in for what.
std::string frames_note(const Session& s, const calib::Mechanism& model, int frame) {
  const std::string name = model.bodies.at(static_cast<std::size_t>(frame)).name;
  return s.target_mount.empty()
             ? "Measured frame: " + name + "."
             : "Frame " + name +
                   ": the end-effector board as mounted (session.yaml's target mount), not the "
                   "robot's own; `robocal export` writes the robot in its own base and tool "
                   "frames.";
}

}  // namespace

void apply_fit_gate(const calib::IdentificationResult& result, const calib::FitGateOptions& options,
                    const GateOptions& gates, const std::string& route, nlohmann::json& report,
                    const PipelineLog& log) {
  const calib::FitVerdict verdict = calib::judge_identification(result, options);
  report["fit_gate"] = {{"plausible", verdict.plausible},
                        {"overridden", !verdict.plausible && gates.accept_implausible},
                        {"max_noise_scale", options.max_noise_scale},
                        {"model_error_m", options.model_error_m},
                        {"model_error_rad", options.model_error_rad},
                        {"model_error_px", options.model_error_px}};
  if (verdict.plausible) return;
  report["fit_gate"]["reason"] = verdict.reason;
  say(log, "  {} RESULT NOT PLAUSIBLE: {}\n", route, verdict.reason);
  if (gates.accept_implausible) {
    say(log, "  accepted anyway (--accept-implausible)\n");
    return;
  }
  report["status"] = "implausible";
  report["message"] = verdict.reason;
}

bool apply_nominal_gate(const calib::FramePredictor& predictor, const Eigen::VectorXd& nominal,
                        const calib::IdentificationResult& result,
                        const std::vector<calib::PoseMeasurement>& poses, const std::string& route,
                        nlohmann::json& report, const PipelineLog& log) {
  // The poses the fit used: an excluded outlier is explained by neither model.
  std::set<std::string> excluded;
  for (const calib::ExcludedPose& e : result.excluded) excluded.insert(e.id);
  std::vector<calib::PoseMeasurement> used;
  for (const calib::PoseMeasurement& p : poses)
    if (excluded.count(p.id) == 0) used.push_back(p);
  const calib::ErrorStatistics before = calib::prediction_errors(predictor, nominal, used);
  const calib::ErrorStatistics after = calib::prediction_errors(predictor, result.estimate, used);
  const bool position = before.position_rms > 0.0 || after.position_rms > 0.0;
  const double b = position ? before.position_rms : before.orientation_rms;
  const double a = position ? after.position_rms : after.orientation_rms;
  if (before.poses == 0 || (b == 0.0 && a == 0.0)) return true;  // nothing 6-D to compare on
  const bool worse = a > 1.01 * b + 1e-7;
  const std::string what = position ? "position" : "orientation";
  auto shown = [&](double v) {
    return position ? fmt::format("{:.1f} µm", v * 1e6)
                    : fmt::format("{:.4f} deg", core::degrees(v));
  };
  report["nominal_gate"] = {{"passed", !worse},
                            {"compared_on", what + "_rms"},
                            {"poses", used.size()},
                            {"nominal_rms", b},
                            {"calibrated_rms", a}};
  if (!worse) return true;
  const std::string reason = fmt::format(
      "the calibrated model predicts the measurements worse than the nominal one ({} RMS {} "
      "against {} over the {} poses of the fit): the fit was led astray by the measurements "
      "(angles in degrees where radians are stated? images of one pose swapped?), so no "
      "calibrated robot file is written and the nominal model stays the better one",
      what, shown(a), shown(b), used.size());
  report["nominal_gate"]["reason"] = reason;
  say(log, "  {} RESULT WORSE THAN THE NOMINAL MODEL: {}\n", route, reason);
  report["status"] = "implausible";
  report["message"] = reason;
  return false;
}

namespace {

// The camera-in-the-loop route after the pose route's success (`route` pixel or both): its
// report in report["pixel_route"] and, when it stands, its calibrated robot file.
void add_pixel_route(const Session& s, const SessionRobot& robot,
                     const calib::FramePredictor& predictor, const Eigen::VectorXd& start,
                     const calib::SolveOptions& solve_options,
                     const Eigen::VectorXd& pose_route_estimate,
                     const std::map<std::string, Eigen::Isometry3d>& rig_T_target,
                     const std::string& route, const ResultsLayout& results, const PipelineLog& log,
                     const GateOptions& gates, nlohmann::json& report) {
  const calib::Mechanism& model = robot.model;
  report["pixel_route"] =
      identify_pixel_route(s, model, predictor, start, solve_options, rig_T_target, log, gates);
  // Not converged from the robot file: again from the pose route's estimate (priors still
  // centred on the robot file). On the Gantry-Tau's camera array (demo --seed 2) the first
  // wandered for 200 iterations to 7.8 px, the second converged in 14 to 0.045 px. Not the
  // first start for every route: on the Delta (seed 1) it stops in a flat valley at a higher
  // cost (18056 against 17904; 44.5 against 35.6 µm held-out).
  if (report["pixel_route"]["result"].value("status", "") != "converged") {
    say(log,
        "  the camera-in-the-loop route did not converge from the robot file; again from the "
        "pose route's estimate\n");
    calib::SolveOptions again = solve_options;
    again.start = pose_route_estimate;
    nlohmann::json second =
        identify_pixel_route(s, model, predictor, start, again, rig_T_target, log, gates);
    if (second["result"].value("status", "") == "converged") {
      second["restarted_from_pose_route"] = true;
      report["pixel_route"] = std::move(second);
    }
  }
  const auto& pr = report["pixel_route"];
  // Asked for alone, the route's verdict is the identification's. Beside the pose route (the
  // default, whose model is the export), it is a second opinion: when it cannot explain its
  // pixels or fails, its model is not written and the pose route's stands, said so.
  if (pr.value("status", "") != "ok" && route == "both") {
    report["warnings"].push_back(
        "camera-in-the-loop route " + pr.value("status", std::string("failed")) + ": " +
        pr.value("message", std::string()) + "; its model is not written, the pose route's is");
    say(log,
        "  the camera-in-the-loop route's model is not written; the pose route's "
        "({}) stands\n",
        ResultsLayout::kCalibratedRobot);
  } else if (pr.value("status", "") == "implausible") {
    report["status"] = "implausible";
    report["message"] = "camera-in-the-loop route: " + pr.value("message", "");
  }
  if (pr.value("status", "") == "ok") {
    const Eigen::VectorXd pixel_estimate =
        params_from_json(model, pr.at("estimate"), results.identification().string());
    const std::string text = calibrated_robot_text(
        robot.file, model, pixel_estimate, {},
        {fmt::format("Calibrated by robocal {} identify (camera-in-the-loop, from corner "
                     "pixels) from session {}.",
                     kVersion, s.dir.filename().string()),
         fmt::format("Reprojection RMS {:.3f} px.", pr.value("reprojection_rms_px", 0.0)),
         "World frame: the session's rig frame (camera " + s.cameras[0].name + ").",
         frames_note(s, model, robot.frame)});
    core::write_file_atomic(results.calibrated_robot_pixels(), text);
    report["pixel_route"]["calibrated_robot"] = ResultsLayout::kCalibratedRobotPixels;
  }
}

}  // namespace

nlohmann::json identify_session(const fs::path& dir, const std::string& robot_override,
                                const PipelineLog& log, const std::string& route, bool priors,
                                const GateOptions& gates) {
  if (route != "pose" && route != "pixel" && route != "both")
    throw InputError("identification route '" + route + "': expected pose, pixel or both");
  const Session s = load_session(dir);
  const SessionRobot robot = session_robot(s, robot_override);
  // Written into a staged copy of results/ that replaces it when the identification reaches its
  // verdict (session/results_transaction.hpp). The copy starts without the files of an earlier
  // identification and the validation that judged it: none of them may stand beside this one's.
  const ResultsLayout current{dir};
  ResultsTransaction transaction(
      dir, {current.identification(), current.calibrated_robot(), current.calibrated_robot_pixels(),
            current.report("validation")});
  const ResultsLayout& results = transaction.staged();
  // The used poses of results/measured_poses.json, at full precision (measurements.yaml is the
  // same data for `robocal identify --measurements`, but its rotation vectors and inverted
  // covariances are not bit-exact, and the identification's choice among confounded parameters
  // is that sensitive).
  calib::Measurements measurements;
  const std::vector<MeasuredPose> measured = read_used_measured_poses(results, measure_first(dir));
  measurements.poses = to_pose_measurements(measured);
  std::map<std::string, Eigen::Isometry3d> rig_T_target;  // the board's measured poses, by pose
  for (const MeasuredPose& m : measured) rig_T_target[m.pose] = m.rig_T_target;
  stage(log, "identify");
  const calib::Mechanism& model = robot.model;
  nlohmann::json report{{"stage", "identify"}, {"session", dir.string()}};
  if (measurements.poses.size() < 3) {
    report["status"] = "failed";
    const std::string refused = measurement_refusal(results);
    report["message"] =
        refused.empty()
            ? fmt::format("{} usable poses: too few", measurements.poses.size())
            : "measure refused the measurements as implausible (" + refused +
                  "). Fix the cause and measure again, or `robocal measure --accept-implausible`";
    say(log, "identify failed: {}; the previous results are unchanged\n",
        report["message"].get<std::string>());
    return report;
  }
  // The robot's base frame in the camera world: first found by aligning the nominal model's
  // predictions with the measurements (what hand-eye calibration alone gives); the priors and
  // the base frame's freedom as for a measurements file (identify_setup.hpp).
  IdentifyChoices choices;
  choices.priors = priors;
  choices.threads = log.threads;
  const IdentifyProblem problem =
      identify_problem(model, robot.frame, robot.nominal, measurements, choices);
  const Eigen::VectorXd& start = problem.start;
  const calib::SolveOptions& solve_options = problem.options;
  calib::MechanismPredictor predictor(model, robot.frame);
  const auto start_errors = calib::prediction_errors(predictor, start, measurements.poses);
  say(log, "  nominal model with the fitted base frame: {:.1f} µm RMS, {:.4f} deg RMS\n",
      start_errors.position_rms * 1e6, core::degrees(start_errors.orientation_rms));
  report["nominal_fit"] = calib::to_json(start_errors);
  say(log, "  priors: {}\n",
      priors ? "the robot file's tolerances (MAP), base frame free"
             : "none (maximum likelihood from the measurements alone)");
  const auto result = calib::identify(predictor, start, measurements, solve_options);
  say(log,
      "  {}: {} of the {} free parameters identified, condition number {:.3g}, {} iterations, "
      "{:.2f} s\n",
      calib::to_string(result.status), result.estimated.size(), result.candidates.size(),
      result.identifiability.condition_number, result.iterations, result.solve_seconds);
  say(log, "  fit residual: {:.1f} µm RMS position, {:.4f} deg RMS orientation, {} outliers\n",
      result.residuals.position_rms * 1e6, core::degrees(result.residuals.orientation_rms),
      result.residuals.outliers);
  if (result.relinearisation.attempted) say(log, "  {}\n", result.relinearisation.message);
  report["result"] = calib::to_json(result);
  report["robot"] = fs::relative(robot.file, dir).generic_string();
  report["measurements"] = ResultsLayout::kMeasuredPoses;
  report["priors"] = priors;
  report["not_identified"] = result.identifiability.messages;
  if (result.relinearisation.attempted)
    report["not_identified"].push_back(result.relinearisation.message);
  // The same, with the robot file's labels for the parameter names (what the summary prints).
  report["not_identified_in_words"] = nlohmann::json::array();
  for (const auto& m : report["not_identified"])
    report["not_identified_in_words"].push_back(
        calib::in_plain_words(m.get<std::string>(), result));
  report["held_at_nominal"] = result.candidates.size() - result.estimated.size();
  report["start"] = params_json(model, start);
  report["estimate"] = params_json(model, result.estimate);
  report["parameter_units"] = nlohmann::json::object();
  report["parameter_sigma"] = nlohmann::json::object();
  for (const auto& p : model.parameters) {
    report["parameter_units"][p.name] = unit_name(p.unit);
    report["parameter_sigma"][p.name] = p.sigma;
  }
  report["software"] = std::string("robocal ") + kVersion;
  bool usable = result.status == calib::IdentificationStatus::kConverged ||
                result.status == calib::IdentificationStatus::kNotConverged;
  report["status"] = usable ? "ok" : "failed";
  if (!usable) report["message"] = result.message;
  if (usable) {
    apply_fit_gate(result, calib::fit_gate_options(model.unmodelled_error, 0.0), gates,
                   "pose route", report, log);
    usable =
        report["status"] == "ok" &&
        apply_nominal_gate(predictor, start, result, measurements.poses, "pose route", report, log);
  }
  if (usable) {
    const std::string text = calibrated_robot_text(
        robot.file, model, result.estimate, result.estimated,
        {fmt::format("Calibrated by robocal {} identify from session {} ({}).", kVersion,
                     dir.filename().string(), calib::to_string(result.status)),
         fmt::format("{} poses used, {} excluded; {} parameters estimated; fit residual RMS "
                     "{:.3g} m.",
                     result.residuals.poses.size(), result.excluded.size(), result.estimated.size(),
                     result.residuals.position_rms),
         "World frame: the session's rig frame (camera " + s.cameras[0].name + ").",
         frames_note(s, model, robot.frame)});
    core::write_file_atomic(results.calibrated_robot(), text);
    report["calibrated_robot"] = ResultsLayout::kCalibratedRobot;
  }
  if (usable && route != "pose")
    add_pixel_route(s, robot, predictor, start, solve_options, result.estimate, rig_T_target, route,
                    results, log, gates, report);
  // A solve that failed is no verdict on the data: the previous results stay.
  if (report["status"] == "failed") return report;
  write_identification(results, report);
  transaction.commit();
  return report;
}

}  // namespace robocal::app
