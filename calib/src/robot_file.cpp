// YAML robot description -> Mechanism. The loader is the only place that knows the file format;
// every error names file, line and problem.
#include "robocal/calib/robot_file.hpp"

#include "robot_file_parse.hpp"
#include "robot_units.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <fstream>
#include <map>
#include <sstream>

namespace robocal::calib {
namespace {

using namespace robot_yaml;  // the reader's parts (robot_file_parse.hpp)

// The file's own settings before its bodies: name, default rotation order, default σ per unit
// and the unmodelled error it declares.
struct FileDefaults {
  std::string rotation_order = "xyz";
  std::map<std::string, double> sigma = {{"length", 1e-3}, {"angle", 1e-2}, {"scale", 1e-3}};
};

FileDefaults parse_header(const YAML::Node& root, const std::string& source, Mechanism& m) {
  if (!root["robot"]) fail(source, root, "missing 'robot' (the robot's name)");
  m.name = text(source, root["robot"], "robot");
  if (root["description"]) m.description = text(source, root["description"], "description");
  FileDefaults defaults;
  std::string& default_order = defaults.rotation_order;
  if (root["rotation_order"]) {
    default_order = text(source, root["rotation_order"], "rotation_order");
    if (default_order != "xyz" && default_order != "zyx")
      fail(source, root["rotation_order"], "rotation_order must be xyz or zyx");
  }
  std::map<std::string, double>& sigma_defaults = defaults.sigma;
  if (const YAML::Node s = root["sigma_defaults"]) {
    check_keys(source, s, "sigma_defaults", {"length", "angle", "scale"});
    for (const auto& kv : s) {
      const double v = number(source, kv.second, "sigma_defaults." + kv.first.Scalar());
      if (v <= 0) fail(source, kv.second, "sigma must be > 0");
      sigma_defaults[kv.first.Scalar()] = v;
    }
  }

  if (const YAML::Node u = root["unmodelled_error"]) {
    check_keys(source, u, "unmodelled_error", {"position", "rotation"});
    m.unmodelled_error.line = u.Mark().line + 1;
    // Beyond 10 mm / 0.1 rad a "calibration" could not be told from a wrong model.
    const struct {
      const char* key;
      double* value;
      double most;
      const char* unit;
    } entries[] = {{"position", &m.unmodelled_error.position, 1e-2, "m"},
                   {"rotation", &m.unmodelled_error.rotation, 0.1, "rad"}};
    for (const auto& e : entries) {
      if (!u[e.key]) continue;
      const double v = number(source, u[e.key], std::string("unmodelled_error.") + e.key);
      if (!(v >= 0.0 && v <= e.most))
        fail(source, u[e.key],
             fmt::format("unmodelled_error.{} must be in [0, {}] ({}); {} given", e.key, e.most,
                         e.unit, v));
      *e.value = v;
    }
  }
  return defaults;
}

// The file top-down: its settings, the bodies, then the sections that refer to bodies.
Mechanism parse(const YAML::Node& root, const std::string& source) {
  if (!root.IsMap()) fail(source, root, "a robot file must be a YAML mapping");
  check_keys(source, root, "robot file",
             {"robot", "description", "source", "rotation_order", "sigma_defaults", "tool", "task",
              "closed_form", "workspace", "bodies", "closures", "rods", "assembly_mode", "labels",
              "unmodelled_error", "controller"});
  Mechanism m;
  m.source = source;
  const FileDefaults defaults = parse_header(root, source, m);
  parse_bodies(root, source, defaults.rotation_order, defaults.sigma, m);
  parse_closures(root, source, defaults.sigma, m);
  parse_tool_and_task(root, source, m);
  parse_controller(root, source, m);
  parse_closed_form(root, source, m);
  parse_workspace(root, source, m);
  parse_assembly_mode(root["assembly_mode"], source, m);
  parse_labels(root["labels"], source, m);
  return m;
}

}  // namespace

Mechanism parse_robot_yaml(const std::string& text_in, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text_in);
  } catch (const YAML::Exception& e) {
    throw RobotFileError(source + ":" + std::to_string(e.mark.line + 1) +
                         ": malformed YAML: " + e.msg);
  }
  try {
    Mechanism m = parse(root, source);
    check_robot_units(m, source);
    return m;
  } catch (const YAML::Exception& e) {
    throw RobotFileError(source + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
}

Mechanism load_robot_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw RobotFileError(path + ": cannot open robot file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_robot_yaml(buffer.str(), path);
}

void apply_parameter_override(const Mechanism& model, Eigen::VectorXd& params,
                              const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos)
    throw RobotFileError("--set " + assignment + ": expected NAME=VALUE");
  const std::string name = assignment.substr(0, eq);
  const int index = model.parameter_index(name);
  if (index < 0) {
    std::string hint;
    const std::string prefix = name.substr(0, name.find('.'));
    int shown = 0;
    for (const Parameter& p : model.parameters)
      if (p.name.rfind(prefix + ".", 0) == 0 && shown++ < 8) hint += " " + p.name;
    throw RobotFileError(model.source + ": --set " + assignment + ": no parameter named '" + name +
                         "' in robot '" + model.name + "'" +
                         (hint.empty() ? "" : " (parameters of '" + prefix + "':" + hint + ")"));
  }
  try {
    params[index] = evaluate_expression(assignment.substr(eq + 1));
  } catch (const std::invalid_argument& e) {
    throw RobotFileError(model.source + ": --set " + assignment + ": " + e.what());
  }
}

}  // namespace robocal::calib
