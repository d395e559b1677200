// The report stage: gathers a session's results (through session/results_files.hpp) and calib's
// statistics of them into one page for people (summary/report_page.hpp), written atomically to
// results/report.html. Needs a successful identification; held-out validation (against a
// simulation's truth, validation.json; measured by the cameras, held_out.json), measured poses and
// camera observations add their figures when the session has them.
#include "cli/cli_common.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"
#include "summary/report_page.hpp"
#include "summary/svg_plot.hpp"
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

// A parameter as the page names it: the label identification.json gives it (the robot file's
// words), with its raw name for the tooltip. Every parameter name on the page goes through here.
class ParameterNames {
 public:
  explicit ParameterNames(const ParameterAccount& account) : account_(account) {
    for (std::size_t i = 0; i < account.names.size(); ++i) index_[account.names[i]] = i;
  }
  [[nodiscard]] ReportName operator()(const std::string& name) const {
    const auto it = index_.find(name);
    return {it == index_.end() ? name : account_.labels[it->second], name};
  }
  [[nodiscard]] ReportSentence operator()(const ParameterSentence& sentence) const {
    ReportSentence out;
    for (const auto& part : sentence)
      out.push_back(part.parameter < 0
                        ? ReportName{part.text, ""}
                        : (*this)(account_.names.at(static_cast<std::size_t>(part.parameter))));
    return out;
  }

 private:
  const ParameterAccount& account_;
  std::map<std::string, std::size_t> index_;
};

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

// The accuracy table's rows for the two kinds of held-out poses.
constexpr const char* kTruthRow = "held-out poses, against the truth";
constexpr const char* kMeasuredRow = "held-out poses, measured by the cameras";

// Why a held-out record does not belong to the session's current measurements ("" when it
// does): each held-out pose must still be a used measured pose, measured where the record says.
std::string stale_held_out(const HeldOutRecord& record, const std::vector<MeasuredPose>& measured) {
  std::map<std::string, Eigen::Vector3d> at;
  for (const auto& m : measured) at[m.pose] = m.rig_T_target.translation();
  for (const auto& p : record.poses) {
    const auto it = at.find(p.pose);
    if (it == at.end())
      return "its held-out pose " + p.pose + " is not among the used measured poses now";
    // The record keeps the measured position at full precision: any change is a new measurement.
    if ((it->second - p.measured).norm() > 1e-9)
      return "its held-out pose " + p.pose + " has been measured again since";
  }
  return "";
}

void add_parameters(ReportData& d, const IdentificationFile& ident,
                    const nlohmann::json& analysis) {
  const nlohmann::json empty = nlohmann::json::array();
  const ParameterNames named(ident.parameters);
  const nlohmann::json& identifiability =
      analysis.value("identifiability", nlohmann::json::object());
  std::map<std::string, std::vector<ReportName>> stands_for;
  for (const auto& red : identifiability.value("redundancies", empty))
    for (const auto& partner : red.value("partners", empty))
      stands_for[partner.value("name", "")].push_back(named(red.value("parameter", "")));
  std::map<std::string, bool> correlated;
  const nlohmann::json& uncertainty = analysis.value("uncertainty", nlohmann::json::object());
  std::vector<ReportCorrelation> correlations;
  for (const auto& c : uncertainty.value("strongly_correlated", empty)) {
    correlated[c.value("first", "")] = correlated[c.value("second", "")] = true;
    correlations.push_back(
        {named(c.value("first", "")), named(c.value("second", "")), c.value("correlation", 0.0)});
  }
  std::stable_sort(correlations.begin(), correlations.end(),
                   [](const auto& a, const auto& b) { return std::abs(a.r) > std::abs(b.r); });
  if (correlations.size() > 25) correlations.resize(25);
  d.correlations = correlations;
  const nlohmann::json units = ident.report.value("parameter_units", nlohmann::json::object());
  for (const auto& p : analysis.value("parameters", empty)) {
    if (!p.value("estimated", false)) continue;
    const std::string name = p.value("name", "");
    const auto [factor, unit] = display_unit(units.value(name, ""));
    ReportParameter row;
    row.name = named(name);
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
  // The counts and reasons in the words every summary uses (summary/validation_summary.hpp).
  const ParameterWords words = parameter_words(ident.parameters);
  d.parameter_counts = words.identified;
  d.held_counts = words.held;
  for (const auto& sentence : words.reasons) d.not_identified.push_back(named(sentence));
  for (const auto& sentence : words.notes) d.identification_notes.push_back(named(sentence));
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

// The session's validation against the truth when it succeeded (none otherwise). A validation
// without per-pose points (written by an older robocal) is refused: the page would show empty
// per-pose plots under held-out headings.
std::optional<ValidationFile> successful_validation(const ResultsLayout& results) {
  std::optional<ValidationFile> validation;
  if (fs::exists(results.report("validation"))) {
    validation = read_validation(results, "");
    if (validation->status != "ok") validation.reset();
  }
  if (validation && validation->points.empty() && !validation->report.contains("held_out_points"))
    throw InputError(results.report("validation").string() +
                     ": this validation has no per-pose held-out points (written by an older "
                     "robocal); run `robocal validate` on the session again, then the report");
  return validation;
}

// The accuracy rows and per-pose errors from held-out poses against the truth (a simulation,
// `robocal validate`), with the regions' rows when the validation split them.
void add_truth_accuracy(ReportData& d, nlohmann::json& summary, const ValidationFile& validation) {
  const nlohmann::json& v = validation.report;
  d.accuracy.push_back(accuracy_row(kTruthRow, v));
  if (v.contains("held_out_by_region")) {
    d.accuracy.push_back(
        accuracy_row("inside the measured region", v.at("held_out_by_region").at("inside")));
    d.accuracy.push_back(
        accuracy_row("outside the measured region", v.at("held_out_by_region").at("outside")));
  }
  d.accuracy_note =
      "Held-out poses against the truth (`robocal validate`, a simulated session): robot "
      "positions the calibration never saw, compared with the true robot. Inside the measured "
      "region (between the measured poses) the model interpolates; outside it extrapolates, "
      "and the error usually grows.";
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
          v.value("held_out_drawn", validation.points.size()), kNoAnswerMeaning, which,
          validation.points.size());
  }
  d.per_pose_source = "held-out poses (against the truth)";
  for (const auto& p : validation.points) {
    d.error_before.push_back(p.nominal_error.norm());
    d.error_after.push_back(p.calibrated_error.norm());
  }
}

// The accuracy row from held-out poses measured by the cameras (the wizard's validation step);
// their per-pose errors when there is no validation against the truth.
void add_measured_accuracy(ReportData& d, const HeldOutRecord& held_out, bool validated) {
  ReportAccuracy a;
  a.label = kMeasuredRow;
  a.poses = held_out.calibrated.poses;
  a.nominal_rms = held_out.nominal.rms_m;
  a.nominal_max = held_out.nominal.max_m;
  a.calibrated_rms = held_out.calibrated.rms_m;
  a.calibrated_max = held_out.calibrated.max_m;
  d.accuracy.push_back(a);
  d.accuracy_note += fmt::format(
      "{}Held-out poses measured by the cameras ({}): every {}th of the measured poses was "
      "left out of a second identification, made the same way from the other {}; that fit's "
      "model (after) and the nominal model with its base frame fitted (before) are compared "
      "with where the cameras measured the board. The figures include the cameras' own "
      "measurement error.",
      d.accuracy_note.empty() ? "" : " ", ResultsLayout::kHeldOut, held_out.every,
      held_out.fit_poses);
  if (!held_out.unanswered.empty())
    d.accuracy_note += fmt::format(
        " FAILURES: at {} of the held-out poses a model had no answer ({}); the figures are "
        "over the {} that both answer.",
        held_out.unanswered.size(), kNoAnswerMeaning, held_out.poses.size());
  if (!validated) {
    d.per_pose_source = "held-out poses (measured by the cameras)";
    for (const auto& p : held_out.poses) {
      d.error_before.push_back(p.nominal_error.norm());
      d.error_after.push_back(p.calibrated_error.norm());
    }
  }
}

// Without held-out poses: the fit's own residuals on the measured poses, said not to be an
// accuracy figure.
void add_fit_accuracy(ReportData& d, const IdentificationFile& ident,
                      const nlohmann::json& analysis) {
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
      "This session has no held-out validation, so these are the errors at the measured "
      "poses themselves: they show how well the model fits, not how accurate it is elsewhere. "
      "To measure accuracy on poses the calibration never saw, run the wizard's validation "
      "step (`robocal wizard --resume FOLDER`), which records it in " +
      std::string(ResultsLayout::kHeldOut) +
      "; a simulated session is validated against its truth by `robocal validate`.";
  d.per_pose_source = "measured poses (the fit's residual after calibration)";
  for (const auto& p : residuals.value("poses", nlohmann::json::array()))
    d.error_after.push_back(p.value("position_error_m", 0.0));
}

// The calibrated model's residual at each measured pose (measured board position minus the
// model's, camera 0's frame), where the model closes.
struct FitResiduals {
  std::vector<Eigen::Vector3d> positions, residuals;
};

// The residual diagnostics against position and, on the poses whose loads the calibrated model
// gives (a unit weight at the tool, calib::tool_weight_loads), against actuator load.
FitResiduals add_residual_diagnostics(ReportData& d, const SessionRobot& robot,
                                      const IdentificationFile& ident,
                                      const std::vector<MeasuredPose>& measured) {
  FitResiduals fit;
  std::vector<Eigen::Vector3d> load_residuals;
  std::vector<Eigen::VectorXd> loads;
  const calib::MechanismPredictor tool_predictor(robot.model);
  for (const auto& m : measured) {
    const auto fk =
        calib::forward_kinematics(robot.model, ident.estimate, m.actuators, robot.frame);
    if (!fk.closure.ok()) continue;
    fit.positions.emplace_back(m.rig_T_target.translation());
    fit.residuals.emplace_back(m.rig_T_target.translation() - fk.pose.translation());
    Eigen::VectorXd load;
    if (calib::tool_weight_loads(tool_predictor, ident.estimate, m.actuators, load)) {
      loads.push_back(load);
      load_residuals.push_back(fit.residuals.back());
    }
  }
  if (fit.positions.size() >= 4)
    d.diagnostics.push_back({"measured poses: measured minus calibrated model, vs position",
                             calib::residual_position_trends(fit.positions, fit.residuals)});
  if (loads.size() >= 4)
    d.diagnostics.push_back({"measured poses: measured minus calibrated model, vs actuator load",
                             calib::residual_load_trends(loads, load_residuals)});
  return fit;
}

// One error map (top and side views) from errors at positions; `before` may be empty.
void add_error_map(ReportData& d, const std::vector<Eigen::Vector3d>& positions,
                   const std::vector<double>& after, const std::vector<double>& before, int cells) {
  std::vector<Eigen::Vector2d> t, sd;
  for (const auto& p : positions) {
    t.push_back(top(p));
    sd.push_back(side(p));
  }
  d.has_map = true;
  d.top_after = calib::error_grid(t, after, cells, cells);
  d.side_after = calib::error_grid(sd, after, cells, cells);
  if (!before.empty()) {
    d.top_before = calib::error_grid(t, before, cells, cells);
    d.side_before = calib::error_grid(sd, before, cells, cells);
  }
}

// The error map of held-out configurations, each at its `position` with both models' errors.
template <typename Point>
void add_held_out_map(ReportData& d, const std::vector<Point>& points,
                      Eigen::Vector3d Point::*position, int cells) {
  std::vector<Eigen::Vector3d> positions;
  std::vector<double> after, before;
  for (const Point& p : points) {
    positions.push_back(p.*position);
    after.push_back(p.calibrated_error.norm());
    before.push_back(p.nominal_error.norm());
  }
  add_error_map(d, positions, after, before, cells);
}

// Error maps over the workspace (held-out positions, camera 0's frame): the truth's when
// validated (many configurations), else the camera-measured held-out poses, else the fit's
// residuals at the measured poses; and the measured poses drawn over them.
void add_error_maps(ReportData& d, const std::optional<ValidationFile>& validation,
                    const std::optional<HeldOutRecord>& held_out, const FitResiduals& fit,
                    const std::vector<MeasuredPose>& measured) {
  if (validation && !validation->points.empty()) {
    d.map_source = "held-out poses (against the truth)";
    add_held_out_map(d, validation->points, &HeldOutPoint::position, kMapCells);
  } else if (held_out && !held_out->poses.empty()) {
    d.map_source = "held-out poses (measured by the cameras)";
    add_held_out_map(d, held_out->poses, &HeldOutPose::measured, kMapCells / 2);
  } else if (!fit.positions.empty()) {
    // No held-out poses: the fit's residuals at the measured poses are the only errors with a
    // position.
    std::vector<double> after;
    after.reserve(fit.residuals.size());
    for (const auto& r : fit.residuals) after.push_back(r.norm());
    d.map_source = "measured poses (the fit's residual; no held-out poses in this session)";
    add_error_map(d, fit.positions, after, {}, kMapCells / 2);
  }
  for (const auto& m : measured) {
    d.measured_top.push_back(top(m.rig_T_target.translation()));
    d.measured_side.push_back(side(m.rig_T_target.translation()));
  }
}

// The verdict a person reads first: the accuracy on poses the fit never saw (against the truth,
// as the cameras measured them) or else the fit, and whether the remaining error looks like noise.
std::string verdict(const ReportData& d, bool validated, const HeldOutRecord* held_out) {
  const ReportAccuracy& all = d.accuracy.front();
  bool unmodelled = false;
  for (const auto& diag : d.diagnostics) unmodelled |= diag.trends.unmodelled_error_suspected();
  const auto from_to = [](const ReportAccuracy& a) {
    return fmt::format("from {} to {} RMS (worst {})",
                       a.nominal_rms ? svg::length(*a.nominal_rms) : std::string("?"),
                       svg::length(a.calibrated_rms), svg::length(a.calibrated_max));
  };
  const auto row = [&](const char* label) {
    return *std::find_if(d.accuracy.begin(), d.accuracy.end(),
                         [&](const ReportAccuracy& a) { return a.label == label; });
  };
  std::string out;
  if (validated)
    out = fmt::format(
        "Calibration brought the tool's position error on {} poses it never saw {}, against "
        "the simulated robot's truth.",
        all.poses, from_to(all));
  if (held_out)
    out += fmt::format(
        "{}Calibration brought the tool's position error on {} measured poses the fit never saw "
        "{}, as the cameras measured them.",
        out.empty() ? "" : " ", held_out->calibrated.poses, from_to(row(kMeasuredRow)));
  if (!validated && !held_out)
    out = fmt::format(
        "The calibrated model fits the {} measured poses to {} RMS (no held-out validation in "
        "this session).",
        all.poses, svg::length(all.calibrated_rms));
  out += unmodelled ? " Warning: the remaining error changes with position or with the "
                      "actuators' load, so something "
                      "in the robot or the measurement is not modelled (section 8)."
                    : " The remaining error looks like noise (section 8).";
  return out;
}

// The residual trends flagged as significant, per diagnostic, for the summary.
nlohmann::json diagnostics_json(const std::vector<ReportDiagnostics>& all) {
  nlohmann::json diagnostics = nlohmann::json::array();
  for (const auto& diag : all) {
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
  return diagnostics;
}

// The terminal summary: the verdict, each accuracy row, the significant trends, the page.
void say_report(const PipelineLog& log, const ReportData& d, const ResultsLayout& results,
                std::size_t page_bytes) {
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
      static_cast<double>(page_bytes) / 1024.0);
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

  const std::optional<ValidationFile> validation = successful_validation(results);
  std::vector<MeasuredPose> measured;
  if (fs::exists(results.measured_poses())) measured = read_used_measured_poses(results, "");
  // Held-out poses measured by the cameras (the wizard's validation step), when they were held
  // out of these measurements: a record from measurements made before is not shown as this
  // session's accuracy.
  std::optional<HeldOutRecord> held_out;
  std::string held_out_stale;
  if (fs::exists(results.held_out())) {
    held_out = read_held_out(results, "");
    held_out_stale = stale_held_out(*held_out, measured);
    if (!held_out_stale.empty()) held_out.reset();
  }

  // Accuracy and per-pose errors: held-out poses against the truth (a simulation, `robocal
  // validate`) and held-out poses measured by the cameras (the wizard) when the session has
  // them, else the fit's own residuals on the measured poses (not an accuracy figure: said so).
  nlohmann::json summary{{"stage", "report"}, {"session", dir.string()}};
  if (validation) add_truth_accuracy(d, summary, *validation);
  if (held_out) add_measured_accuracy(d, *held_out, validation.has_value());
  if (!validation && !held_out) add_fit_accuracy(d, ident, analysis);
  if (!held_out_stale.empty())
    d.accuracy_note += fmt::format(" The held-out poses of {} are not shown: {}.",
                                   ResultsLayout::kHeldOut, held_out_stale);
  if (!d.error_before.empty()) d.histogram_before = error_histogram(d.error_before);
  d.histogram_after = error_histogram(d.error_after);

  const FitResiduals fit = add_residual_diagnostics(d, robot, ident, measured);
  add_error_maps(d, validation, held_out, fit, measured);

  add_parameters(d, ident, analysis);
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

  d.verdict = verdict(d, validation.has_value(), held_out ? &*held_out : nullptr);
  const ReportAccuracy& all = d.accuracy.front();

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
  if (held_out)
    summary["held_out_measured"] = {{"poses", held_out->calibrated.poses},
                                    {"calibrated_rms_m", held_out->calibrated.rms_m},
                                    {"nominal_rms_m", held_out->nominal.rms_m}};
  else if (!held_out_stale.empty())
    summary["held_out_measured"] = {{"not_shown", held_out_stale}};
  const ParameterCounts& counts = ident.parameters.counts;
  summary["estimated_parameters"] = d.parameters.size();
  summary["parameters"] = {{"total", counts.total},           {"free", counts.free},
                           {"identified", counts.identified}, {"held_at_nominal", counts.held},
                           {"no_effect", counts.no_effect},   {"fixed", counts.fixed()}};
  summary["residual_diagnostics"] = diagnostics_json(d.diagnostics);
  summary["verdict"] = d.verdict;
  summary["seconds"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  say_report(log, d, results, html.size());
  return summary;
}

}  // namespace robocal::app
