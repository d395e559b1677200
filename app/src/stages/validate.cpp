// The validate stage: a simulated session's calibrated robot against its hidden truth (truth/,
// which no other stage reads), on held-out configurations the fit never saw.
#include "cli/cli_common.hpp"
#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/results_transaction.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "simcell/simulated_cell.hpp"
#include "stages/measured_region.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"
#include "summary/validation_summary.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/held_out_errors.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/vision/camera_io.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <random>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// Validation certifies the calibrated robot file a user takes away, not only the estimate inside
// identification.json: the file must read as a robot file and hold that estimate. Values are
// written to read back exactly (calibrated_robot_file.hpp); 1e-9 (m or rad) allows the decimal
// text of derived values.
void check_calibrated_file(const fs::path& file, const calib::Mechanism& model,
                           const Eigen::VectorXd& estimate) {
  const std::string again = "run `robocal identify` on the session again";
  if (!fs::exists(file))
    throw InputError(
        fmt::format("{}: missing, although results/identification.json says the "
                    "identification succeeded; {}",
                    file.string(), again));
  calib::Mechanism written;
  try {
    written = calib::load_robot_file(file.string());
  } catch (const std::exception& e) {
    throw InputError(
        fmt::format("{}: cannot be read as a robot file ({}); {}", file.string(), e.what(), again));
  }
  const Eigen::VectorXd values = written.nominal_parameters();
  if (values.size() != estimate.size())
    throw InputError(
        fmt::format("{}: {} parameters, the identified model has {}: the file is not "
                    "this session's calibrated robot; {}",
                    file.string(), values.size(), estimate.size(), again));
  constexpr double kTolerance = 1e-9;
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    if (std::abs(values(i) - estimate(i)) <= kTolerance) continue;
    throw InputError(fmt::format(
        "{}: {} is {:.9g} in the file but {:.9g} in results/identification.json: the file was "
        "edited or comes from another run; {}",
        file.string(), model.parameter_display_name(static_cast<std::size_t>(i)), values(i),
        estimate(i), again));
  }
}

nlohmann::json stats_json(const calib::PositionErrorStats& e, int failures = 0) {
  return {{"rms_m", e.rms}, {"max_m", e.max}, {"poses", e.n}, {"failures", failures}};
}

// The cameras' intrinsics against the truth, one row per calibrated camera.
nlohmann::json cameras_vs_truth(const Session& s, const ResultsLayout& results,
                                const TruthFile& truth_file, const PipelineLog& log) {
  nlohmann::json cams = nlohmann::json::array();
  for (std::size_t c = 0; c < s.cameras.size() && c < truth_file.cameras.size(); ++c) {
    const fs::path f = results.camera(s.cameras[c].name);
    if (!fs::exists(f)) continue;
    const auto est = vision::load_camera_file(f);
    const auto& true_model = truth_file.cameras[c].model;
    const double projection = vision::projection_difference_px(est, true_model);
    cams.push_back({{"camera", s.cameras[c].name},
                    {"fx", est.params[0]},
                    {"fx_true", true_model.params[0]},
                    {"projection_vs_truth_px", projection}});
    say(log, "  {}: fx {:.2f} px (true {:.2f}), model vs truth {:.4f} px RMS\n", s.cameras[c].name,
        est.params[0], true_model.params[0], projection);
  }
  return cams;
}

// The rig's baseline against the truth, when the session has a rig of more than one camera.
void add_rig_vs_truth(nlohmann::json& report, const ResultsLayout& results,
                      const TruthFile& truth_file, const PipelineLog& log) {
  if (!fs::exists(results.rig()) || truth_file.cameras.size() <= 1) return;
  const RigFile rig = read_rig_file(results.rig());
  const auto centre = [](const Eigen::Isometry3d& camera_T_world) {
    return Eigen::Vector3d(camera_T_world.inverse().translation());
  };
  const double true_baseline =
      (centre(truth_file.cameras[1].camera_T_world) - centre(truth_file.cameras[0].camera_T_world))
          .norm();
  const double baseline = rig.baseline_m.at(1);
  report["rig"] = {{"baseline_m", baseline},
                   {"baseline_true_m", true_baseline},
                   {"baseline_error_m", baseline - true_baseline}};
  say(log, "  baseline {:.5f} m (true {:.5f} m, error {:+.1f} µm)\n", baseline, true_baseline,
      (baseline - true_baseline) * 1e6);
}

// What the measured board poses say about the frame held-out truth is compared in.
struct MeasuredFrame {
  // The measured positions of the used poses: they span the measured region
  // (measured_region.hpp).
  std::vector<Eigen::Vector3d> positions;
  // Camera 0's frame as its calibration realises it (every measurement and calibrated model lives
  // there; calib::realised_frame), fitted on the measured poses; the true camera 0 frame where
  // there are none.
  Eigen::Isometry3d frame_T_world;
};

// The measured board poses against the truth (camera 0's frame), and the realised camera 0 frame
// they fit.
MeasuredFrame add_measured_poses_vs_truth(nlohmann::json& report, const ResultsLayout& results,
                                          const TruthFile& truth_file,
                                          const Eigen::Isometry3d& cam0_T_world,
                                          const PipelineLog& log) {
  MeasuredFrame out{{}, cam0_T_world};
  if (!fs::exists(results.measured_poses())) return out;
  std::map<std::string, Eigen::Isometry3d> true_poses;
  for (const auto& p : truth_file.poses) true_poses[p.pose] = p.world_T_board;
  std::vector<Eigen::Vector3d> measured, expected;
  for (const auto& p : read_used_measured_poses(results, "")) {
    out.positions.emplace_back(p.rig_T_target.translation());
    const auto it = true_poses.find(p.pose);
    if (it == true_poses.end()) continue;
    measured.emplace_back(p.rig_T_target.translation());
    expected.emplace_back(cam0_T_world * it->second.translation());
  }
  const auto stats = calib::position_error_stats(measured, expected);
  report["measured_poses_vs_truth"] = stats_json(stats);
  say(log, "  board position measured vs truth: {:.1f} µm RMS over {} poses\n", stats.rms * 1e6,
      stats.n);
  if (const auto realised = calib::realised_frame(measured, expected)) {
    out.frame_T_world = *realised * cam0_T_world;
    std::vector<Eigen::Vector3d> carried;
    carried.reserve(expected.size());
    for (const auto& e : expected) carried.emplace_back(*realised * e);
    const auto in_frame = calib::position_error_stats(measured, carried);
    const double turn = Eigen::AngleAxisd(realised->linear()).angle();
    const double shift = realised->translation().norm();
    report["camera_frame"] = {
        {"definition",
         "held-out truth is compared in camera 0's frame as its calibration realises it: the "
         "rigid transform carrying the measured poses' true positions onto their measured ones"},
        {"turn_rad", turn},
        {"shift_m", shift},
        {"measured_poses_vs_truth_in_it", stats_json(in_frame)}};
    say(log,
        "  camera 0's frame as calibrated lies {:.1f} µrad and {:.1f} µm from the true one; in "
        "it the board positions are {:.1f} µm RMS from the truth\n",
        turn * 1e6, shift * 1e6, in_frame.rms * 1e6);
  }
  return out;
}

// Where a model's answer is on the intended assembly mode (assembly_mode.hpp): an answer on
// another mode (refused by the solver) or at a mode boundary is no answer.
bool answers(const calib::ForwardResult& fk) {
  return fk.closure.ok() && fk.closure.status != calib::SolveStatus::kOtherMode &&
         fk.closure.mode.verdict != calib::ModeVerdict::kOther &&
         fk.closure.mode.verdict != calib::ModeVerdict::kAmbiguous;
}

// The held-out configurations and each model's prediction there.
struct HeldOutPredictions {
  int evaluated = 0;  // configurations the true robot answers
  // Per model: how often it cannot answer.
  int nominal_failures = 0, calibrated_failures = 0, pixel_failures = 0;
  // Where every model answers: the region split and the worst configurations compare them.
  std::vector<Eigen::Vector3d> truth, nominal, calibrated, pixel;
  std::vector<Eigen::Vector3d> truth_in_true_frame;  // the same, in the true camera 0 frame
  std::vector<Eigen::VectorXd> configurations;
};

// Held-out configurations the fit never saw (no images needed): nominal (base frame fitted) and
// calibrated model against the true robot, in camera 0's frame.
HeldOutPredictions predict_held_out(const SessionRobot& robot, const IdentificationFile& ident,
                                    const TruthFile& truth_file,
                                    const calib::MechanismPredictor& true_predictor,
                                    const Eigen::Isometry3d& frame_T_world,
                                    const Eigen::Isometry3d& cam0_T_world, int held_out,
                                    std::mt19937& validation_rng) {
  const calib::Mechanism& model = robot.model;
  const Eigen::VectorXd& truth = truth_file.truth;
  const std::optional<Eigen::VectorXd>& pixel_estimate = ident.pixel_estimate;
  // Drawn from the true robot alone: which configurations judge a model must not depend on the
  // model judged. Where a model cannot answer (its loops do not close, or only on another
  // assembly mode), that is a failure of the model, counted in its figures.
  const auto configurations = calib::sample_actuators(
      true_predictor, {truth}, static_cast<std::size_t>(held_out), validation_rng);
  HeldOutPredictions out;
  const auto record = [](int& failures, const calib::ForwardResult& fk) {
    if (!answers(fk)) ++failures;
  };
  int truth_unanswered = 0;
  for (const auto& q : configurations) {
    auto true_fk = calib::forward_kinematics(model, truth, q, robot.frame);
    true_fk.pose = elastic_deflection(true_fk.pose, truth_file.elastic_sag);
    if (!answers(true_fk)) {
      ++truth_unanswered;  // sample_actuators checked it; kept for completeness
      continue;
    }
    const auto nominal_fk = calib::forward_kinematics(model, ident.start, q, robot.frame);
    const auto calibrated_fk = calib::forward_kinematics(model, ident.estimate, q, robot.frame);
    const auto pixel_fk = pixel_estimate
                              ? calib::forward_kinematics(model, *pixel_estimate, q, robot.frame)
                              : calibrated_fk;
    const Eigen::Vector3d t = frame_T_world * true_fk.pose.translation();
    record(out.nominal_failures, nominal_fk);
    record(out.calibrated_failures, calibrated_fk);
    if (pixel_estimate) record(out.pixel_failures, pixel_fk);
    if (!answers(nominal_fk) || !answers(calibrated_fk) || !answers(pixel_fk)) continue;
    out.truth.push_back(t);
    out.truth_in_true_frame.emplace_back(cam0_T_world * true_fk.pose.translation());
    out.nominal.emplace_back(nominal_fk.pose.translation());
    out.calibrated.emplace_back(calibrated_fk.pose.translation());
    out.pixel.emplace_back(pixel_fk.pose.translation());
    out.configurations.push_back(q);
  }
  out.evaluated = static_cast<int>(configurations.size()) - truth_unanswered;
  return out;
}

// Says which models could not answer at some held-out configurations, and how few were drawn.
void say_unanswered(const HeldOutPredictions& p, bool pixel, int held_out, const PipelineLog& log) {
  const auto say_failures = [&](const char* name, int failures) {
    if (failures > 0)
      say(log,
          "  {} model: cannot answer at {} of {} held-out configurations ({}); counted as "
          "failures\n",
          name, failures, p.evaluated, kNoAnswerMeaning);
  };
  say_failures("nominal", p.nominal_failures);
  say_failures("calibrated", p.calibrated_failures);
  if (pixel) say_failures("camera-in-the-loop calibrated", p.pixel_failures);
  if (p.evaluated < held_out)
    say(log, "  only {} of {} requested held-out configurations could be drawn from the truth\n",
        p.evaluated, held_out);
}

// Each model's held-out errors against the truth.
struct ModelErrors {
  calib::HeldOutErrors nominal, calibrated, pixel;
};

// The held-out figures: the models compared on the same configurations, those every model
// answers. A configuration a model cannot answer is its failure, counted beside its figures.
ModelErrors add_held_out_figures(nlohmann::json& report, const HeldOutPredictions& p, bool pixel,
                                 int held_out, unsigned seed) {
  ModelErrors f;
  f.nominal = calib::held_out_errors(p.nominal, p.truth);
  f.calibrated = calib::held_out_errors(p.calibrated, p.truth);
  report["held_out_poses"] = p.truth.size();
  report["held_out_requested"] = held_out;
  report["held_out_drawn"] = p.evaluated;
  report["held_out_drawn_from"] = "the true robot alone";
  report["seed"] = seed;
  report["unanswered"] = {{"nominal", p.nominal_failures}, {"calibrated", p.calibrated_failures}};
  if (pixel) report["unanswered"]["calibrated_pixels"] = p.pixel_failures;
  report["nominal"] = stats_json(f.nominal.absolute, p.nominal_failures);
  report["calibrated"] = stats_json(f.calibrated.absolute, p.calibrated_failures);
  report["nominal_registered"] = stats_json(f.nominal.registered, p.nominal_failures);
  report["calibrated_registered"] = stats_json(f.calibrated.registered, p.calibrated_failures);
  if (pixel) {
    f.pixel = calib::held_out_errors(p.pixel, p.truth);
    report["calibrated_pixels"] = stats_json(f.pixel.absolute, p.pixel_failures);
    report["calibrated_pixels_registered"] = stats_json(f.pixel.registered, p.pixel_failures);
  }
  // The same against the true camera 0 frame, which no measurement sees: the difference is where
  // the cameras' calibration placed their world, extrapolated to each held-out pose.
  if (report.contains("camera_frame")) {
    nlohmann::json& in_true = report["camera_frame"]["held_out_in_true_frame"];
    in_true["calibrated"] = stats_json(
        calib::position_error_stats(p.calibrated, p.truth_in_true_frame), p.calibrated_failures);
    if (pixel)
      in_true["calibrated_pixels"] =
          stats_json(calib::position_error_stats(p.pixel, p.truth_in_true_frame), p.pixel_failures);
  }
  return f;
}

// Every held-out configuration's true position and each model's error vector there, for the
// report's per-pose figures, error maps and residual diagnostics (read by read_validation).
nlohmann::json held_out_points(const HeldOutPredictions& p, bool in_calibrated_frame) {
  nlohmann::json position = nlohmann::json::array(), nominal = nlohmann::json::array(),
                 calibrated = nlohmann::json::array();
  const auto row = [](const Eigen::Vector3d& v) { return nlohmann::json{v.x(), v.y(), v.z()}; };
  for (std::size_t k = 0; k < p.truth.size(); ++k) {
    position.push_back(row(p.truth[k]));
    nominal.push_back(row(p.nominal[k] - p.truth[k]));
    calibrated.push_back(row(p.calibrated[k] - p.truth[k]));
  }
  return {{"frame", in_calibrated_frame ? "camera 0 as calibrated" : "camera 0"},
          {"position_m", position},
          {"nominal_error_m", nominal},
          {"calibrated_error_m", calibrated}};
}

// Interpolation or extrapolation: where each held-out position lies relative to the measured
// region (the convex hull of the measured board positions). Far outside it, the model is
// extrapolated along directions the measured poses constrain weakly. Returns each held-out
// position's distance to the region (default values when nothing was measured).
std::vector<RegionDistance> add_measured_region(nlohmann::json& report,
                                                const std::vector<Eigen::Vector3d>& measured,
                                                const HeldOutPredictions& p, const ModelErrors& f,
                                                bool pixel) {
  std::vector<RegionDistance> region(p.truth.size());
  if (measured.empty()) return region;
  std::vector<bool> inside(p.truth.size());
  std::vector<double> outside_m(p.truth.size());
  for (std::size_t k = 0; k < p.truth.size(); ++k) {
    region[k] = distance_to_region(measured, p.truth[k]);
    inside[k] = region[k].inside;
    outside_m[k] = region[k].outside_m;
  }
  Eigen::Vector3d lo = measured[0], hi = measured[0];
  for (const auto& m : measured) {
    lo = lo.cwiseMin(m);
    hi = hi.cwiseMax(m);
  }
  report["measured_region"] = {
      {"definition",
       "convex hull of the measured end-effector board positions (results/measured_poses.json, "
       "used poses) in camera 0's frame; a held-out configuration is inside when its true board "
       "position lies in the hull (within inside_tolerance_m), outside otherwise; "
       "outside_measured_region_m (worst_held_out) and distance_*_m (held_out_by_region) are "
       "distances to the hull"},
      {"measured_poses", measured.size()},
      {"inside_tolerance_m", kRegionInsideTolerance},
      {"bounding_box_m", {{"min", {lo.x(), lo.y(), lo.z()}}, {"max", {hi.x(), hi.y(), hi.z()}}}}};
  std::vector<NamedPoints> predictions = {{"nominal", &p.nominal}, {"calibrated", &p.calibrated}};
  if (pixel) predictions.push_back({"calibrated_pixels", &p.pixel});
  // The registered figures keep the one transform fitted over all held-out configurations.
  const auto add_registered = [&](const char* name, const calib::HeldOutErrors& e) {
    if (e.registered_points.size() == p.truth.size())
      predictions.push_back({name, &e.registered_points});
  };
  add_registered("nominal_registered", f.nominal);
  add_registered("calibrated_registered", f.calibrated);
  if (pixel) add_registered("calibrated_pixels_registered", f.pixel);
  report["held_out_by_region"] = split_errors_by_region(inside, outside_m, p.truth, predictions);
  report["held_out_points"]["inside_measured_region"] = inside;
  return region;
}

// The worst held-out configurations with the true robot's task conditioning there
// (σ_min/σ_max of d(position)/d(actuators)): one pose near a singularity can carry most of the
// RMS, and the user should see that rather than a mean.
nlohmann::json worst_held_out(const HeldOutPredictions& p, bool pixel,
                              const std::vector<RegionDistance>& region, bool measured_region,
                              const calib::MechanismPredictor& true_predictor,
                              const Eigen::VectorXd& truth) {
  std::vector<std::size_t> order(p.truth.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  auto worst_of = [&](std::size_t k) {
    double e = (p.calibrated[k] - p.truth[k]).norm();
    if (pixel) e = std::max(e, (p.pixel[k] - p.truth[k]).norm());
    return e;
  };
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return worst_of(a) > worst_of(b); });
  nlohmann::json worst = nlohmann::json::array();
  for (std::size_t w = 0; w < std::min<std::size_t>(5, order.size()); ++w) {
    const std::size_t k = order[w];
    const Eigen::VectorXd& q = p.configurations[k];
    nlohmann::json row = {
        {"actuators", std::vector<double>(q.data(), q.data() + q.size())},
        {"calibrated_error_m", (p.calibrated[k] - p.truth[k]).norm()},
        {"task_conditioning", calib::task_conditioning(true_predictor, truth, q)}};
    if (pixel) row["calibrated_pixels_error_m"] = (p.pixel[k] - p.truth[k]).norm();
    if (measured_region) {
      row["inside_measured_region"] = region[k].inside;
      row["outside_measured_region_m"] = region[k].outside_m;
      row["nearest_measured_pose_m"] = region[k].nearest_measured_m;
    }
    worst.push_back(row);
  }
  return worst;
}

// Parameters: estimated change next to the true change, largest (in tolerance sigmas) first.
nlohmann::json parameter_changes(const calib::Mechanism& model, const IdentificationFile& ident,
                                 const TruthFile& truth_file) {
  const Eigen::VectorXd& start = ident.start;
  const Eigen::VectorXd& estimate = ident.estimate;
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (estimate[static_cast<Eigen::Index>(i)] != start[static_cast<Eigen::Index>(i)])
      order.push_back(i);
  const auto score = [&](std::size_t i) {
    const auto k = static_cast<Eigen::Index>(i);
    return std::abs(estimate[k] - start[k]) / std::max(model.parameters[i].sigma, 1e-12);
  };
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return score(a) > score(b); });
  // A parameter that stands in for confounded ones (identifiability redundancies name it as a
  // partner) carries their combination: its change is not comparable with its own true change.
  // The base frame is the cell's placement (camera 0 <- robot base), not a robot dimension.
  std::map<std::string, int> carries;
  const nlohmann::json no_redundancies = nlohmann::json::array();
  const nlohmann::json& ident_report = ident.report;
  const nlohmann::json& analysis =
      ident_report.contains("result") ? ident_report.at("result") : ident_report;
  const nlohmann::json& redundancies =
      analysis.contains("identifiability") &&
              analysis.at("identifiability").contains("redundancies")
          ? analysis.at("identifiability").at("redundancies")
          : no_redundancies;
  for (const auto& red : redundancies)
    for (const auto& partner : red.value("partners", nlohmann::json::array()))
      ++carries[partner.value("name", "")];
  nlohmann::json params = nlohmann::json::array();
  for (std::size_t i : order) {
    const auto k = static_cast<Eigen::Index>(i);
    const int body = model.parameters[i].body;
    const bool base_frame = body >= 0 && model.bodies[static_cast<std::size_t>(body)].parent < 0;
    const auto carried = carries.find(model.parameters[i].name);
    params.push_back({{"name", model.parameters[i].name},
                      {"label", calib::display_name(model.parameters[i])},
                      {"unit", unit_name(model.parameters[i].unit)},
                      {"estimated_change", estimate[k] - start[k]},
                      {"true_change", truth_file.truth[k] - truth_file.nominal[k]},
                      {"base_frame", base_frame},
                      {"stands_in_for", carried == carries.end() ? 0 : carried->second}});
  }
  return params;
}

}  // namespace

nlohmann::json validate_session(const fs::path& dir, int held_out, const PipelineLog& log) {
  const Session s = load_session(dir);
  const ResultsLayout results{dir};
  nlohmann::json report{{"stage", "validate"}, {"session", dir.string()}};
  if (!fs::is_directory(results.truth_dir()) || !fs::exists(results.truth())) {
    report["status"] = "no_truth";
    report["message"] = fmt::format(
        "{}: missing. This session has no ground truth (a recorded session, or truth/ was moved "
        "away), so there is nothing to validate against; held-out validation on measured poses "
        "is `robocal identify --holdout-every K` on results/measurements.yaml",
        results.truth_dir().string());
    say(log, "validate: {}\n", report["message"].get<std::string>());
    return report;
  }
  const SessionRobot robot = session_robot(s, "");
  const calib::Mechanism& model = robot.model;
  const IdentificationFile ident =
      read_identification(results, model, "run `robocal identify` on the session first");
  if (ident.status != "ok")
    throw InputError(results.identification().string() +
                     ": the identification did not succeed; nothing to validate");
  const bool pixel = ident.pixel_estimate.has_value();
  check_calibrated_file(results.calibrated_robot(), model, ident.estimate);
  if (pixel) check_calibrated_file(results.calibrated_robot_pixels(), model, *ident.pixel_estimate);
  const TruthFile truth_file = read_truth(results, model);
  const Eigen::Isometry3d cam0_T_world = truth_file.cameras.at(0).camera_T_world;
  stage(log, "validate");

  report["cameras"] = cameras_vs_truth(s, results, truth_file, log);
  add_rig_vs_truth(report, results, truth_file, log);
  const MeasuredFrame measured =
      add_measured_poses_vs_truth(report, results, truth_file, cam0_T_world, log);

  const calib::MechanismPredictor true_predictor(model, robot.frame);
  std::mt19937 validation_rng(s.seed + 7919);
  const HeldOutPredictions predictions =
      predict_held_out(robot, ident, truth_file, true_predictor, measured.frame_T_world,
                       cam0_T_world, held_out, validation_rng);
  say_unanswered(predictions, pixel, held_out, log);
  const ModelErrors figures =
      add_held_out_figures(report, predictions, pixel, held_out, s.seed + 7919);
  report["held_out_points"] = held_out_points(predictions, report.contains("camera_frame"));
  const std::vector<RegionDistance> region =
      add_measured_region(report, measured.positions, predictions, figures, pixel);
  report["worst_held_out"] = worst_held_out(predictions, pixel, region, !measured.positions.empty(),
                                            true_predictor, truth_file.truth);
  report["parameters"] = parameter_changes(model, ident, truth_file);

  report["status"] = figures.calibrated.absolute.n > 0 ? "ok" : "failed";
  report["improved"] = figures.calibrated.absolute.n > 0 &&
                       figures.calibrated.absolute.rms < figures.nominal.absolute.rms;
  // The verdict on the calibrated model ("failed": it answered no held-out configuration) goes
  // to results/ through a transaction like every stage's (session/results_transaction.hpp).
  ResultsTransaction transaction(dir, {results.report("validation")});
  write_json(report, transaction.staged().report("validation").string());
  transaction.commit();
  return report;
}

}  // namespace robocal::app
