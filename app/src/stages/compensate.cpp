// The compensate stage: a session's calibrated robot turned into commands for a controller that
// knows only the nominal model (calib/compensation.hpp, calib/gcode_program.hpp). Reads the
// session's robot and results/identification.json; writes only the output file the user named.
#include "cli/cli_common.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"
#include "session/session_robot.hpp"
#include "stages/stage_log.hpp"
#include "stages/stages.hpp"

#include "robocal/calib/compensation.hpp"
#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/gcode_program.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <sstream>

namespace robocal::app {

namespace fs = std::filesystem;

namespace {

struct Target {
  int line = 0;  // in the targets file
  std::vector<double> values;
};

// Values a target needs: the task's coordinates (calib's TaskSpace).
std::size_t task_values(const calib::Mechanism& model) {
  switch (model.task.type) {
    case calib::TaskType::kPosition:
      return 3;
    case calib::TaskType::kPose:
      return 6;
    case calib::TaskType::kJoint:
      return 1;
  }
  return 3;
}

std::string task_words(const calib::Mechanism& model) {
  switch (model.task.type) {
    case calib::TaskType::kPosition:
      return "x y z (m)";
    case calib::TaskType::kPose:
      return "x y z (m) and a rotation vector rx ry rz (rad)";
    case calib::TaskType::kJoint:
      return "the value of joint '" +
             model.bodies[static_cast<std::size_t>(model.task.joint)].name + "'";
  }
  return "";
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  const auto b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

// CSV: one target per line, values separated by commas (or spaces); '#' comments, blank lines
// and a header line (first field not a number) are skipped.
std::vector<Target> read_targets_csv(const std::string& text, const std::string& source) {
  std::vector<Target> targets;
  std::istringstream in(text);
  std::string raw;
  int number = 0;
  bool first_content = true;
  while (std::getline(in, raw)) {
    ++number;
    std::string line = raw.substr(0, raw.find('#'));
    std::replace(line.begin(), line.end(), ',', ' ');
    line = trim(line);
    if (line.empty()) continue;
    std::istringstream fields(line);
    std::string field;
    Target t;
    t.line = number;
    bool header = false;
    while (fields >> field) {
      double v = 0.0;
      const auto [end, ec] = std::from_chars(field.data(), field.data() + field.size(), v);
      if (ec != std::errc() || end != field.data() + field.size() || !std::isfinite(v)) {
        if (first_content && t.values.empty()) {
          header = true;
          break;
        }
        throw InputError(fmt::format("{}:{}: '{}' is not a number", source, number, field));
      }
      t.values.push_back(v);
    }
    first_content = false;
    if (!header) targets.push_back(t);
  }
  return targets;
}

// YAML: `targets:` a list of value lists.
std::vector<Target> read_targets_yaml(const std::string& text, const std::string& source) {
  const YAML::Node root = core::load_yaml_text(text, source);
  const core::YamlContext ctx{source};
  if (!root.IsMap()) ctx.fail(root, "expected a mapping with 'targets:'");
  const YAML::Node list = ctx.require(root, "targets");
  if (!list.IsSequence()) ctx.fail(list, "'targets' must be a list of [x, y, z, ...] lists");
  std::vector<Target> targets;
  for (const auto& node : list)
    targets.push_back({node.Mark().line + 1, ctx.to_doubles(node, "target")});
  return targets;
}

std::vector<Target> read_targets(const fs::path& path, const calib::Mechanism& model) {
  const std::string text = core::read_text_file(path);
  const std::string ext = path.extension().string();
  std::vector<Target> targets = ext == ".yaml" || ext == ".yml"
                                    ? read_targets_yaml(text, path.string())
                                    : read_targets_csv(text, path.string());
  if (targets.empty()) throw InputError(path.string() + ": no targets in the file");
  for (const Target& t : targets)
    if (t.values.size() != task_values(model))
      throw InputError(fmt::format("{}:{}: {} values, but a target of {} is {}", path.string(),
                                   t.line, t.values.size(), model.name, task_words(model)));
  return targets;
}

calib::TaskTarget task_target(const calib::Mechanism& model, const std::vector<double>& v) {
  calib::TaskTarget t;
  if (model.task.type == calib::TaskType::kJoint) {
    t.joint_value = v[0];
    return t;
  }
  t.pose.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  if (model.task.type == calib::TaskType::kPose)
    t.pose.linear() = calib::rotation_exp(Eigen::Vector3d(v[3], v[4], v[5]));
  return t;
}

std::string csv_text(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// The task-space command for the nominal controller, in the targets' own units.
std::vector<double> commanded_values(const calib::Mechanism& model,
                                     const calib::CompensatedTarget& c) {
  if (model.task.type == calib::TaskType::kJoint) return {};
  const Eigen::Vector3d p = c.commanded.translation();
  std::vector<double> v = {p.x(), p.y(), p.z()};
  if (model.task.type == calib::TaskType::kPose) {
    const Eigen::Vector3d r = calib::rotation_log(c.commanded.linear());
    v.insert(v.end(), {r.x(), r.y(), r.z()});
  }
  return v;
}

struct Models {
  SessionRobot robot;
  calib::CompensationModels compensation;
  std::string route;
};

Models session_models(const CompensateOptions& o) {
  const Session s = load_session(o.session);
  Models m{session_robot(s, o.robot_override), {}, o.route};
  const ResultsLayout results{o.session};
  const IdentificationFile ident = read_identification(
      results, m.robot.model,
      "the session has no identification results: run `robocal identify` (or `robocal demo`) "
      "on it first");
  if (ident.status != "ok")
    throw InputError(results.identification().string() +
                     ": the identification did not succeed, so there is no calibrated model to "
                     "compensate with");
  Eigen::VectorXd estimate = ident.estimate;
  if (o.route == "pixel") {
    if (!ident.pixel_estimate)
      throw InputError(results.identification().string() +
                       ": no camera-in-the-loop (pixel route) estimate; use --route pose");
    estimate = *ident.pixel_estimate;
  }
  const Eigen::VectorXd file_nominal = m.robot.model.nominal_parameters();
  m.compensation.nominal = file_nominal;
  m.compensation.calibrated = calib::calibrated_in_robot_frame(
      m.robot.model, estimate, file_nominal, s.target_mount.empty() ? -1 : m.robot.frame);
  if (!o.firmware.empty()) {
    // The controller runs the settings `robocal export` fits to this calibrated robot (the same
    // fit: the model's values are the calibrated ones, as export reads them): compensate for
    // what they leave, in the firmware's coordinates.
    const calib::DeltaFirmware firmware = o.firmware == "marlin" ? calib::DeltaFirmware::kMarlin
                                          : o.firmware == "rrf"
                                              ? calib::DeltaFirmware::kReprapFirmware
                                              : calib::DeltaFirmware::kKlipper;
    if (const std::string why = calib::firmware_delta_mismatch(m.robot.model, firmware);
        !why.empty())
      throw InputError(fmt::format("--firmware {}: {}", o.firmware, why));
    calib::Mechanism calibrated_model = m.robot.model;
    for (std::size_t i = 0; i < calibrated_model.parameters.size(); ++i)
      calibrated_model.parameters[i].value =
          m.compensation.calibrated[static_cast<Eigen::Index>(i)];
    const calib::FirmwareDeltaFit fit =
        calib::fit_firmware_delta(calibrated_model, m.compensation.calibrated, firmware);
    try {
      const calib::FirmwareController c =
          calib::firmware_delta_controller(m.robot.model, m.compensation.calibrated, fit);
      m.compensation.nominal = c.controller;
      m.compensation.calibrated = c.calibrated;
    } catch (const std::invalid_argument& e) {
      throw InputError(fmt::format("--firmware {}: {}", o.firmware, e.what()));
    }
  }
  return m;
}

nlohmann::json compensate_targets(const CompensateOptions& o, Models& m, const PipelineLog& log) {
  const calib::Mechanism& model = m.robot.model;
  const std::vector<Target> targets = read_targets(o.targets, model);
  std::string out = fmt::format(
      "# robocal compensate: {} targets of {} through the calibrated robot of {} ({} route)\n"
      "# actuators: readings to command (encoder units); commanded: the same readings as a "
      "task-space command for a controller that knows only the nominal model\n"
      "line,verdict",
      targets.size(), o.targets.string(), o.session.string(), m.route);
  for (const int b : model.actuated) out += "," + model.bodies[static_cast<std::size_t>(b)].name;
  static const std::array<const char*, 6> kCommanded = {"x", "y", "z", "rx", "ry", "rz"};
  const std::size_t n_commanded =
      model.task.type == calib::TaskType::kJoint ? 0 : task_values(model);
  for (std::size_t k = 0; k < n_commanded; ++k) out += fmt::format(",commanded_{}", kCommanded[k]);
  out += ",problem\n";
  nlohmann::json rows = nlohmann::json::array();
  int refused = 0;
  std::vector<calib::TaskTarget> task_targets;
  task_targets.reserve(targets.size());
  for (const Target& t : targets) task_targets.push_back(task_target(model, t.values));
  const std::vector<calib::CompensatedTarget> answers =
      calib::compensate_targets(m.compensation, task_targets);
  for (std::size_t k = 0; k < targets.size(); ++k) {
    const Target& t = targets[k];
    const calib::CompensatedTarget& c = answers[k];
    out += fmt::format("{},{}", t.line, calib::to_string(c.verdict));
    nlohmann::json row = {{"line", t.line}, {"verdict", calib::to_string(c.verdict)}};
    if (c.usable()) {
      for (Eigen::Index a = 0; a < c.ik.actuator_readings.size(); ++a)
        out += fmt::format(",{:.9g}", c.ik.actuator_readings[a]);
      const std::vector<double> commanded = commanded_values(model, c);
      for (const double v : commanded) out += fmt::format(",{:.9g}", v);
      row["actuators"] =
          std::vector<double>(c.ik.actuator_readings.data(),
                              c.ik.actuator_readings.data() + c.ik.actuator_readings.size());
      row["commanded"] = commanded;
      row["mode_distance"] = c.ik.mode.distance;
    } else {
      ++refused;
      out += std::string(model.actuated.size() + n_commanded, ',');
      // Always on stderr: the commands may take stdout, and a refusal must not pass unseen.
      if (log.out != nullptr)
        fmt::print(stderr, "{}:{}: {}: {}\n", o.targets.string(), t.line,
                   calib::to_string(c.verdict), c.problem);
    }
    if (!c.problem.empty()) row["problem"] = c.problem;
    out += "," + (c.problem.empty() ? std::string() : csv_text(c.problem)) + "\n";
    rows.push_back(row);
  }
  if (o.out.empty())
    fmt::print("{}", out);
  else
    core::write_file_atomic(o.out, out);
  return {{"stage", "compensate"}, {"mode", "targets"}, {"targets", targets.size()},
          {"refused", refused},    {"rows", rows},      {"status", refused == 0 ? "ok" : "failed"}};
}

// What the controller's G-code axes are: the user's word (--axes), else the robot file's.
calib::GcodeAxes gcode_axes(const CompensateOptions& o, const SessionRobot& robot) {
  // A printer firmware with delta settings computes the robot's kinematics: X Y Z is the nozzle.
  if (!o.firmware.empty()) {
    if (o.axes == "actuators")
      throw UsageError("--firmware " + o.firmware +
                       " runs delta kinematics (X Y Z = the nozzle): not with --axes actuators");
    return calib::GcodeAxes::kTool;
  }
  if (o.axes == "tool") return calib::GcodeAxes::kTool;
  if (o.axes == "actuators") return calib::GcodeAxes::kActuators;
  if (!o.axes.empty()) throw UsageError("--axes " + o.axes + ": expected tool or actuators");
  if (robot.model.controller.gcode_axes != calib::GcodeAxes::kUnknown)
    return robot.model.controller.gcode_axes;
  throw InputError(fmt::format(
      "{}: the robot file does not say what its controller's G-code axes are, so the program "
      "cannot be written in the units the controller reads: add `controller: {{gcode_axes: "
      "tool}}` (the firmware computes this robot's kinematics: X Y Z = the tool position) or "
      "`controller: {{gcode_axes: actuators}}` (one axis per actuator, mm or degrees), or give "
      "--axes tool|actuators",
      robot.file));
}

nlohmann::json compensate_gcode(const CompensateOptions& o, Models& m, const PipelineLog& log) {
  if (o.out.empty()) throw UsageError("--gcode needs --out FILE for the rewritten program");
  std::error_code ec;
  if (fs::exists(o.out) && fs::equivalent(o.out, o.gcode, ec))
    throw InputError(o.out.string() + ": is the program itself; write the rewrite elsewhere");
  const calib::GcodeProgram program =
      calib::parse_gcode(core::read_text_file(o.gcode), o.gcode.string());
  calib::GcodeRewriteOptions options;
  options.tolerance = o.tolerance;
  options.axes = gcode_axes(o, m.robot);
  const calib::GcodeRewrite rewrite = calib::rewrite_gcode(program, m.compensation, options);
  std::string header;
  if (options.axes == calib::GcodeAxes::kActuators) {
    std::string words;
    for (const auto& a : calib::gcode_actuator_axes(m.robot.model, m.compensation.nominal))
      words += fmt::format("{}{} = {} ({})", words.empty() ? "" : ", ", a.letter, a.body,
                           a.revolute ? "degrees" : "mm");
    header = fmt::format(
        "; robocal compensate: {} rewritten for a controller whose axes are the actuators of {} "
        "({}), so that the calibrated robot of {} ({} route) follows the program within {:.1f} "
        "um\n; axis words are actuator positions, not tool positions; F is the axes' rate that "
        "keeps each piece's meant time\n",
        o.gcode.filename().string(), m.robot.model.name, words, o.session.string(), m.route,
        o.tolerance * 1e6);
  } else {
    header = fmt::format(
        "; robocal compensate: {} rewritten for a controller with {}, so that the calibrated "
        "robot of {} ({} route) follows the program within {:.1f} um\n",
        o.gcode.filename().string(),
        o.firmware.empty()
            ? "the nominal model of " + m.robot.model.name
            : fmt::format("`robocal export {} --format {}`'s settings (coordinates: the "
                          "firmware's frame)",
                          o.session.string(), o.firmware),
        o.session.string(), m.route, o.tolerance * 1e6);
  }
  core::write_file_atomic(o.out, header + rewrite.text);
  say(log,
      "{}: {} moves written as {} (largest correction {:.1f} um; predicted tool error along the "
      "straight pieces {:.2f} um, arcs add their chords' sagitta, at most half the tolerance)\n",
      o.out.string(), rewrite.stats.moves, rewrite.stats.emitted_moves,
      rewrite.stats.max_correction * 1e6, rewrite.stats.max_deviation * 1e6);
  return {{"stage", "compensate"},
          {"mode", "gcode"},
          {"axes", options.axes == calib::GcodeAxes::kActuators ? "actuators" : "tool"},
          {"controller_model", o.firmware.empty() ? "robot file" : o.firmware},
          {"program", o.gcode.string()},
          {"out", o.out.string()},
          {"tolerance_m", o.tolerance},
          {"moves", rewrite.stats.moves},
          {"emitted_moves", rewrite.stats.emitted_moves},
          {"max_correction_m", rewrite.stats.max_correction},
          {"max_predicted_deviation_m", rewrite.stats.max_deviation},
          {"status", "ok"}};
}

}  // namespace

nlohmann::json compensate_session(const CompensateOptions& options, const PipelineLog& log) {
  Models models = session_models(options);
  models.compensation.model = &models.robot.model;  // after the move out of session_models
  stage(log, "compensate");
  return options.gcode.empty() ? compensate_targets(options, models, log)
                               : compensate_gcode(options, models, log);
}

}  // namespace robocal::app
