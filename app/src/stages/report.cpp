// The report stage: gathers a session's results (through session/results_files.hpp) and calib's
// statistics of them into one page for people (summary/report_page.hpp), written atomically to
// results/report.html. Needs a successful identification; validation (truth), measured poses and
// camera observations add their figures when the session has them.
#include "cli/cli_common.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"
#include "summary/report_page.hpp"
#include "summary/validation_summary.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/residual_diagnostics.hpp"
#include "robocal/vision/camera_io.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numbers>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

// The name a person reads for a parameter: the robot file's plain-word label, with the
// parameter's own name after it so the row can be found in the JSON and the robot file.
std::string parameter_display_name(const calib::Mechanism& model, const std::string& name) {
  const int index = model.parameter_index(name);
  if (index < 0) return name;
  const std::string& label = model.parameter_display_name(static_cast<std::size_t>(index));
  return label == name ? name : label + " (" + name + ")";
}

constexpr std::size_t kHistogramBins = 30;
constexpr int kMapCells = 14;
constexpr std::size_t kCornersPerCamera = 6000;  // bounds the page size; coverage stays visible

calib::Histogram error_histogram(const std::vector<double>& errors) {
  double hi = 0.0;
  for (const double e : errors) hi = std::max(hi, e);
  return calib::histogram(errors, kHistogramBins, 0.0, hi > 0.0 ? hi * 1.0001 : 1e-6);
}

// Top view: x across the image, z away from the camera; side view: z, y down the image.
Eigen::Vector2d top(const Eigen::Vector3d& p) {
  return {p.x(), p.z()};
}
Eigen::Vector2d side(const Eigen::Vector3d& p) {
  return {p.z(), p.y()};
}

// Display units: mm for lengths, degrees for angles, the bare ratio for scales.
std::pair<double, std::string> display_unit(const std::string& unit) {
  if (unit == "length") return {1e3, "mm"};
  if (unit == "angle") return {180.0 / std::numbers::pi, "°"};
  return {1.0, ""};
}

ReportAccuracy accuracy_row(const std::string& label, const nlohmann::json& part) {
  ReportAccuracy a;
  a.label = label;
  a.poses = part.value("held_out_poses", part.at("calibrated").value("poses", std::size_t{0}));
  if (part.contains("nominal")) {
    a.nominal_rms = part.at("nominal").value("rms_m", 0.0);
    a.nominal_max = part.at("nominal").value("max_m", 0.0);
  }
  a.calibrated_rms = part.at("calibrated").value("rms_m", 0.0);
  a.calibrated_max = part.at("calibrated").value("max_m", 0.0);
  return a;
}

void add_parameters(ReportData& d, const calib::Mechanism& model, const IdentificationFile& ident,
                    const nlohmann::json& analysis) {
  const nlohmann::json empty = nlohmann::json::array();
  const nlohmann::json& identifiability =
      analysis.value("identifiability", nlohmann::json::object());
  std::map<std::string, std::vector<std::string>> stands_for;
  for (const auto& red : identifiability.value("redundancies", empty))
    for (const auto& partner : red.value("partners", empty))
      stands_for[partner.value("name", "")].push_back(
          parameter_display_name(model, red.value("parameter", "")));
  std::map<std::string, bool> correlated;
  const nlohmann::json& uncertainty = analysis.value("uncertainty", nlohmann::json::object());
  std::vector<ReportCorrelation> correlations;
  for (const auto& c : uncertainty.value("strongly_correlated", empty)) {
    correlated[c.value("first", "")] = correlated[c.value("second", "")] = true;
    correlations.push_back({parameter_display_name(model, c.value("first", "")),
                            parameter_display_name(model, c.value("second", "")),
                            c.value("correlation", 0.0)});
  }
  std::stable_sort(correlations.begin(), correlations.end(),
                   [](const auto& a, const auto& b) { return std::abs(a.r) > std::abs(b.r); });
  if (correlations.size() > 25) correlations.resize(25);
  d.correlations = correlations;
  const nlohmann::json units = ident.report.value("parameter_units", nlohmann::json::object());
  for (const auto& p : analysis.value("parameters", empty)) {
    ++d.parameters_total;
    if (!p.value("estimated", false)) continue;
    const std::string name = p.value("name", "");
    const auto [factor, unit] = display_unit(units.value(name, ""));
    ReportParameter row;
    row.name = parameter_display_name(model, name);
    row.unit = unit;
    row.nominal = p.value("nominal", 0.0) * factor;
    row.value = p.value("value", 0.0) * factor;
    row.change = p.value("change", 0.0) * factor;
    row.ci95 = p.value("ci_half_width", 0.0) * factor;
    if (const auto it = stands_for.find(name); it != stands_for.end()) row.stands_for = it->second;
    row.strongly_correlated = correlated.count(name) > 0;
    d.parameters.push_back(row);
  }
  // Most significant change first: what calibration corrected most surely.
  std::stable_sort(d.parameters.begin(), d.parameters.end(), [](const auto& a, const auto& b) {
    return std::abs(a.change) / std::max(a.ci95, 1e-12) >
           std::abs(b.change) / std::max(b.ci95, 1e-12);
  });
  for (const auto& m : identifiability.value("messages", empty))
    if (m.is_string()) d.not_identified.push_back(m.get<std::string>());
  d.held_at_nominal = ident.report.value("held_at_nominal", std::size_t{0});
}

void add_cameras(ReportData& d, const Session& s, const ResultsLayout& results,
                 const std::map<std::string, double>& rms_by_pose) {
  if (s.cameras.empty() || !fs::exists(results.pixel_observations())) return;
  std::vector<std::string> names;
  for (const auto& c : s.cameras) names.push_back(c.name);
  const auto poses = read_used_pixel_poses(results, names, "");
  std::size_t total = 0;
  for (const auto& p : poses)
    for (const auto& f : p.cameras) total += f.corners.size();
  const std::size_t stride = std::max<std::size_t>(1, total / kCornersPerCamera);
  for (std::size_t c = 0; c < names.size(); ++c) {
    ReportCamera cam;
    cam.name = names[c];
    if (fs::exists(results.camera(names[c]))) {
      const auto model = vision::load_camera_file(results.camera(names[c]));
      cam.width = model.width;
      cam.height = model.height;
    }
    std::size_t k = 0;
    for (const auto& p : poses) {
      if (c >= p.cameras.size() || p.cameras[c].corners.empty()) continue;
      Eigen::Vector2d centre = Eigen::Vector2d::Zero();
      for (const auto& corner : p.cameras[c].corners) {
        centre += corner.pixel;
        if (k++ % stride == 0) cam.corners.push_back(corner.pixel);
        cam.width = std::max(cam.width, static_cast<int>(std::ceil(corner.pixel.x())));
        cam.height = std::max(cam.height, static_cast<int>(std::ceil(corner.pixel.y())));
      }
      const auto rms = rms_by_pose.find(p.pose);
      if (rms == rms_by_pose.end()) continue;
      cam.pose_centres.emplace_back(centre / static_cast<double>(p.cameras[c].corners.size()));
      cam.pose_rms_px.push_back(rms->second);
    }
    d.cameras.push_back(cam);
  }
}

}  // namespace

nlohmann::json report_session(const fs::path& dir, const PipelineLog& log,
                              std::vector<std::pair<std::string, double>> stage_seconds) {
  const auto started = std::chrono::steady_clock::now();
  const Session s = load_session(dir);
  const ResultsLayout results{dir};
  const SessionRobot robot = session_robot(s, "");
  const IdentificationFile ident = read_identification(
      results, robot.model,
      "the report shows an identification's results: run `robocal identify` on the session first");
  if (ident.status != "ok")
    throw InputError(results.identification().string() +
                     ": the identification did not succeed (status \"" + ident.status +
                     "\"), so there is no calibrated model to report; see its message");
  const nlohmann::json& analysis =
      ident.report.contains("result") ? ident.report.at("result") : ident.report;
  stage(log, "report");

  ReportData d;
  d.session = dir.string();
  d.robot = s.robot_name.empty() ? ident.report.value("robot", "robot") : s.robot_name;
  d.software = ident.report.value("software", "robocal");

  std::optional<ValidationFile> validation;
  if (fs::exists(results.report("validation"))) {
    validation = read_validation(results, "");
    if (validation->status != "ok") validation.reset();
  }
  // A validation.json from before per-pose points were written has the summary figures but no
  // points: the page would show empty per-pose plots under held-out headings. Say so instead.
  if (validation && validation->points.empty() && !validation->report.contains("held_out_points"))
    throw InputError(results.report("validation").string() +
                     ": this validation has no per-pose held-out points (written by an older "
                     "robocal); run `robocal validate` on the session again, then the report");
  std::vector<MeasuredPose> measured;
  if (fs::exists(results.measured_poses())) measured = read_used_measured_poses(results, "");

  // Accuracy and per-pose errors: held-out poses against the truth when validated, else the
  // fit's own residuals on the measured poses (not an accuracy figure: said in the note).
  nlohmann::json summary{{"stage", "report"}, {"session", dir.string()}};
  if (validation) {
    const nlohmann::json& v = validation->report;
    d.accuracy.push_back(accuracy_row("all held-out poses", v));
    if (v.contains("held_out_by_region")) {
      d.accuracy.push_back(
          accuracy_row("inside the measured region", v.at("held_out_by_region").at("inside")));
      d.accuracy.push_back(
          accuracy_row("outside the measured region", v.at("held_out_by_region").at("outside")));
    }
    d.accuracy_note =
        "Held-out poses are robot positions the calibration never saw, compared with the true "
        "robot. Inside the measured region (between the measured poses) the model interpolates; "
        "outside it extrapolates, and the error usually grows.";
    // Configurations a model could not answer are failures that the figures leave out: the
    // page says how many, as the terminal summary does.
    if (v.contains("unanswered") && v.at("unanswered").is_object()) {
      int total = 0;
      std::string which;
      for (const auto& [model, count] : v.at("unanswered").items()) {
        const int n = count.is_number_integer() ? count.get<int>() : 0;
        if (n == 0) continue;
        total += n;
        which += fmt::format("{}{} model {}", which.empty() ? "" : ", ", model, n);
      }
      summary["unanswered"] = v.at("unanswered");
      if (total > 0)
        d.accuracy_note += fmt::format(
            " FAILURES: of {} configurations drawn from the true robot, a model could not "
            "answer ({}) at {}; the figures are over the {} that every model answers.",
            v.value("held_out_drawn", validation->points.size()), kNoAnswerMeaning, which,
            validation->points.size());
    }
    d.per_pose_source = "held-out poses";
    for (const auto& p : validation->points) {
      d.error_before.push_back(p.nominal_error.norm());
      d.error_after.push_back(p.calibrated_error.norm());
    }
  } else {
    const nlohmann::json& residuals = analysis.value("residuals", nlohmann::json::object());
    ReportAccuracy a;
    a.label = "measured poses (fit)";
    a.poses = residuals.value("poses", nlohmann::json::array()).size();
    if (ident.report.contains("nominal_fit")) {
      a.nominal_rms = ident.report.at("nominal_fit").value("position_rms_m", 0.0);
      a.nominal_max = ident.report.at("nominal_fit").value("position_max_m", 0.0);
    }
    a.calibrated_rms = residuals.value("position_rms_m", 0.0);
    a.calibrated_max = residuals.value("position_max_m", 0.0);
    d.accuracy.push_back(a);
    d.accuracy_note =
        "This session has no held-out validation (no truth/), so these are the errors at the "
        "measured poses themselves: they show how well the model fits, not how accurate it is "
        "elsewhere. Check accuracy on poses the calibration never saw (`robocal identify "
        "--holdout-every K`).";
    d.per_pose_source = "measured poses (the fit's residual after calibration)";
    for (const auto& p : residuals.value("poses", nlohmann::json::array()))
      d.error_after.push_back(p.value("position_error_m", 0.0));
  }
  if (!d.error_before.empty()) d.histogram_before = error_histogram(d.error_before);
  d.histogram_after = error_histogram(d.error_after);

  // The calibrated model's residual at each measured pose (measured board position minus the
  // model's, camera 0's frame): the residual diagnostics, and the error map without truth.
  // The load test uses the poses whose loads the calibrated model gives (a unit weight at the
  // tool, calib::tool_weight_loads).
  std::vector<Eigen::Vector3d> fit_positions, fit_residuals, load_residuals;
  std::vector<Eigen::VectorXd> loads;
  const calib::MechanismPredictor tool_predictor(robot.model);
  for (const auto& m : measured) {
    const auto fk =
        calib::forward_kinematics(robot.model, ident.estimate, m.actuators, robot.frame);
    if (!fk.closure.ok()) continue;
    fit_positions.emplace_back(m.rig_T_target.translation());
    fit_residuals.emplace_back(m.rig_T_target.translation() - fk.pose.translation());
    Eigen::VectorXd load;
    if (calib::tool_weight_loads(tool_predictor, ident.estimate, m.actuators, load)) {
      loads.push_back(load);
      load_residuals.push_back(fit_residuals.back());
    }
  }
  if (fit_positions.size() >= 4)
    d.diagnostics.push_back({"measured poses: measured minus calibrated model, vs position",
                             calib::residual_position_trends(fit_positions, fit_residuals)});
  if (loads.size() >= 4)
    d.diagnostics.push_back({"measured poses: measured minus calibrated model, vs actuator load",
                             calib::residual_load_trends(loads, load_residuals)});

  // Error maps over the workspace (held-out positions, camera 0's frame).
  if (validation && !validation->points.empty()) {
    std::vector<Eigen::Vector2d> t, sd;
    std::vector<double> after, before;
    for (const auto& p : validation->points) {
      t.push_back(top(p.position));
      sd.push_back(side(p.position));
      after.push_back(p.calibrated_error.norm());
      before.push_back(p.nominal_error.norm());
    }
    d.has_map = true;
    d.map_source = "held-out poses";
    d.top_after = calib::error_grid(t, after, kMapCells, kMapCells);
    d.side_after = calib::error_grid(sd, after, kMapCells, kMapCells);
    d.top_before = calib::error_grid(t, before, kMapCells, kMapCells);
    d.side_before = calib::error_grid(sd, before, kMapCells, kMapCells);
  } else if (!fit_positions.empty()) {
    // No truth: the fit's residuals at the measured poses are the only errors with a position.
    std::vector<Eigen::Vector2d> t, sd;
    std::vector<double> after;
    for (std::size_t k = 0; k < fit_positions.size(); ++k) {
      t.push_back(top(fit_positions[k]));
      sd.push_back(side(fit_positions[k]));
      after.push_back(fit_residuals[k].norm());
    }
    d.has_map = true;
    d.map_source = "measured poses (the fit's residual; no held-out poses in this session)";
    d.top_after = calib::error_grid(t, after, kMapCells / 2, kMapCells / 2);
    d.side_after = calib::error_grid(sd, after, kMapCells / 2, kMapCells / 2);
  }
  for (const auto& m : measured) {
    d.measured_top.push_back(top(m.rig_T_target.translation()));
    d.measured_side.push_back(side(m.rig_T_target.translation()));
  }

  add_parameters(d, robot.model, ident, analysis);
  std::map<std::string, double> rms_by_pose;
  for (const auto& m : measured) rms_by_pose[m.pose] = m.rms_px;
  add_cameras(d, s, results, rms_by_pose);

  // Held-out errors are not tested: a parameter's estimation error itself makes them vary
  // smoothly with position (extrapolation), so a trend there says nothing about the model.

  // Timings: the session's stages (when known) and the solver's own time.
  if (stage_seconds.empty()) stage_seconds = read_demo_seconds(results);
  d.timings = stage_seconds;
  d.timings.emplace_back("identification solver (pose route)",
                         analysis.value("solve_seconds", 0.0));
  if (ident.report.contains("pixel_route") && ident.report.at("pixel_route").contains("result"))
    d.timings.emplace_back("identification solver (camera-in-the-loop route)",
                           ident.report.at("pixel_route").at("result").value("solve_seconds", 0.0));

  // The verdict a person reads first.
  const ReportAccuracy& all = d.accuracy.front();
  bool unmodelled = false;
  for (const auto& diag : d.diagnostics) unmodelled |= diag.trends.unmodelled_error_suspected();
  d.verdict =
      validation
          ? fmt::format(
                "Calibration brought the tool's position error on {} poses it "
                "never saw from {} to {} RMS (worst {}).",
                all.poses, all.nominal_rms ? fmt::format("{:.3f} mm", *all.nominal_rms * 1e3) : "?",
                fmt::format("{:.3f} mm", all.calibrated_rms * 1e3),
                fmt::format("{:.3f} mm", all.calibrated_max * 1e3))
          : fmt::format(
                "The calibrated model fits the {} measured poses to {:.3f} mm RMS "
                "(no held-out validation in this session).",
                all.poses, all.calibrated_rms * 1e3);
  d.verdict += unmodelled ? " Warning: the remaining error changes with position or with the "
                            "actuators' load, so something "
                            "in the robot or the measurement is not modelled (section 8)."
                          : " The remaining error looks like noise (section 8).";

  d.timings.emplace_back(
      "this report",
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
  const std::string html = render_report_page(d);
  write_report_page(results, html);

  summary["status"] = "ok";
  summary["page"] = results.report_page().string();
  summary["bytes"] = html.size();
  summary["held_out_poses"] = validation ? validation->points.size() : 0;
  summary["calibrated_rms_m"] = all.calibrated_rms;
  if (all.nominal_rms) summary["nominal_rms_m"] = *all.nominal_rms;
  summary["estimated_parameters"] = d.parameters.size();
  nlohmann::json diagnostics = nlohmann::json::array();
  for (const auto& diag : d.diagnostics) {
    nlohmann::json flagged = nlohmann::json::array();
    for (const auto& t : diag.trends.trends)
      if (t.significant)
        flagged.push_back(
            {{"residual", std::string(1, "xyz"[t.component])},
             {"variable", diag.trends.variables[static_cast<std::size_t>(t.variable)]},
             {"correlation", t.correlation.r},
             {"p_value", t.correlation.p_value},
             {"change_over_workspace_m", t.amplitude}});
    diagnostics.push_back({{"source", diag.source},
                           {"poses", diag.trends.n},
                           {"unmodelled_error_suspected", diag.trends.unmodelled_error_suspected()},
                           {"flagged", flagged}});
  }
  summary["residual_diagnostics"] = diagnostics;
  summary["verdict"] = d.verdict;
  summary["seconds"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  say(log, "  {}\n", d.verdict);
  for (const auto& a : d.accuracy)
    say(log, "    {:<30} {:>5} poses: {} -> {:.1f} µm RMS\n", a.label, a.poses,
        a.nominal_rms ? fmt::format("{:.1f} µm", *a.nominal_rms * 1e6) : "?",
        a.calibrated_rms * 1e6);
  for (const auto& diag : d.diagnostics)
    for (const auto& t : diag.trends.trends)
      if (t.significant)
        say(log, "    trend: {} error along {} changes with {} by {:.1f} µm (r {:+.2f})\n",
            diag.source, "xyz"[t.component],
            diag.trends.variables[static_cast<std::size_t>(t.variable)], t.amplitude * 1e6,
            t.correlation.r);
  say(log, "  page: {} ({:.0f} kB)\n", results.report_page().string(),
      static_cast<double>(html.size()) / 1024.0);
  return summary;
}

}  // namespace robocal::app
