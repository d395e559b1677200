// The sections of a robot file after its bodies: closures and rods, tool and task, controller,
// closed form, workspace, assembly mode and labels.
#include "robot_file_parse.hpp"

#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace robocal::calib::robot_yaml {
namespace {

// The body a node names (`what` says which field), an error when it is missing or unknown.
int body_ref(const std::string& source, const Mechanism& m, const YAML::Node& n,
             const std::string& what) {
  if (!n) fail(source, n, what + " missing");
  const std::string name = text(source, n, what);
  const int i = m.body_index(name);
  if (i < 0) fail(source, n, what + " names a missing body '" + name + "'");
  return i;
}

// Assembly-mode invariants by type name, with the number of bodies each takes.
struct InvariantShape {
  InvariantKind kind;
  std::size_t bodies;
};

const std::map<std::string, InvariantShape> kInvariantKinds = {
    {"side", {InvariantKind::kSide, 2}},         {"turn", {InvariantKind::kTurn, 3}},
    {"parallel", {InvariantKind::kParallel, 4}}, {"triple", {InvariantKind::kTriple, 6}},
    {"joint", {InvariantKind::kJoint, 1}},       {"tilt", {InvariantKind::kTilt, 2}},
};

ModeInvariant parse_invariant(const YAML::Node& n, const std::string& source, const Mechanism& m) {
  check_keys(source, n, "assembly_mode invariant",
             {"name", "type", "bodies", "axis", "max_angle", "sign"});
  ModeInvariant inv;
  inv.line = line_of(n);
  if (!n["name"]) fail(source, n, "assembly_mode invariant needs a 'name'");
  inv.name = text(source, n["name"], "invariant name");
  const std::string what = "assembly_mode invariant '" + inv.name + "'";
  if (!n["type"])
    fail(source, n, what + " needs a 'type' (side, turn, parallel, triple, joint, tilt)");
  const std::string type = text(source, n["type"], what + ": type");
  const auto shape = kInvariantKinds.find(type);
  if (shape == kInvariantKinds.end())
    fail(source, n["type"], what + ": type must be side, turn, parallel, triple, joint or tilt");
  inv.kind = shape->second.kind;
  const std::vector<std::string> names = string_list(source, n["bodies"], what + ": bodies");
  if (names.size() != shape->second.bodies)
    fail(source, n["bodies"].IsDefined() ? n["bodies"] : n,
         what + ": type " + type + " needs " + std::to_string(shape->second.bodies) +
             " bodies, got " + std::to_string(names.size()));
  for (const std::string& b : names) {
    const int i = m.body_index(b);
    if (i < 0) {
      std::string message = what;
      message += " names a missing body '";
      message += b;
      message += "'";
      fail(source, n["bodies"], message);
    }
    inv.bodies.push_back(i);
  }
  if (inv.kind == InvariantKind::kJoint &&
      m.bodies[static_cast<std::size_t>(inv.bodies[0])].joint == JointType::kFixed)
    fail(source, n["bodies"], what + ": a joint invariant needs a moving joint");
  if (n["axis"]) {
    if (inv.kind != InvariantKind::kSide && inv.kind != InvariantKind::kTilt)
      fail(source, n["axis"], what + ": axis is for types side and tilt");
    inv.axis = vec3(source, n["axis"], what + ": axis");
    if (inv.axis.norm() < 1e-12) fail(source, n["axis"], what + ": axis must not be zero");
    inv.axis.normalize();
  }
  if (inv.kind == InvariantKind::kTilt) {
    if (!n["max_angle"]) fail(source, n, what + ": type tilt needs 'max_angle' (rad)");
    inv.max_angle = number(source, n["max_angle"], what + ": max_angle");
    if (!(inv.max_angle > 0.0 && inv.max_angle < M_PI))
      fail(source, n["max_angle"], what + ": max_angle must be in (0, pi)");
  } else if (n["max_angle"]) {
    fail(source, n["max_angle"], what + ": max_angle is for type tilt");
  }
  if (!n["sign"]) fail(source, n, what + " needs 'sign: 1' or 'sign: -1' (the intended side)");
  inv.sign = number(source, n["sign"], what + ": sign");
  if (inv.sign != 1.0 && inv.sign != -1.0) fail(source, n["sign"], what + ": sign must be 1 or -1");
  return inv;
}

// Words for a parameter key of a convention: what the number is to someone holding the robot.
std::string key_words(const std::string& convention, const std::string& key) {
  static const std::map<std::string, std::string> kCommon = {
      {"encoder_offset", "encoder zero"}, {"encoder_scale", "encoder scale"}, {"length", "length"}};
  static const std::map<std::string, std::string> kXyzRpy = {
      {"x", "x offset"},        {"y", "y offset"},         {"z", "z offset"},
      {"roll", "tilt about x"}, {"pitch", "tilt about y"}, {"yaw", "turn about z"}};
  static const std::map<std::string, std::string> kMcpc = {
      {"a1", "tilt about x"}, {"a2", "tilt about y"}, {"a3", "turn about z"},
      {"d1", "x offset"},     {"d2", "y offset"},     {"d3", "z offset"}};
  static const std::map<std::string, std::string> kDh = {{"theta", "joint angle zero"},
                                                         {"d", "offset along the joint axis"},
                                                         {"a", "link length"},
                                                         {"alpha", "link twist"},
                                                         {"beta", "twist about y"}};
  if (const auto it = kCommon.find(key); it != kCommon.end()) return it->second;
  const auto& table = convention == "mcpc" ? kMcpc : (convention == "xyz_rpy" ? kXyzRpy : kDh);
  if (const auto it = table.find(key); it != table.end()) return it->second;
  return key;
}

}  // namespace

void parse_closures(const YAML::Node& root, const std::string& source,
                    const std::map<std::string, double>& sigma_defaults, Mechanism& m) {
  std::set<std::string> closure_names;
  if (const YAML::Node cl = root["closures"]) {
    if (!cl.IsSequence()) fail(source, cl, "closures must be a list");
    for (const auto& c : cl) {
      check_keys(source, c, "closure", {"name", "type", "a", "b"});
      Closure closure;
      closure.line = line_of(c);
      closure.name = c["name"] ? text(source, c["name"], "name")
                               : "closure" + std::to_string(m.closures.size() + 1);
      if (!c["a"]) fail(source, c, "closure '" + closure.name + "': missing 'a'");
      if (!c["b"]) fail(source, c, "closure '" + closure.name + "': missing 'b'");
      closure.body_a = body_ref(source, m, c["a"], "closure '" + closure.name + "': a");
      closure.body_b = body_ref(source, m, c["b"], "closure '" + closure.name + "': b");
      const std::string type = c["type"] ? text(source, c["type"], "type") : "position";
      if (type == "position") {
        closure.type = ClosureType::kPosition;
      } else if (type == "pose") {
        closure.type = ClosureType::kPose;
      } else if (type == "position_axis") {
        closure.type = ClosureType::kPositionAxis;
      } else {
        fail(source, c["type"], "closure type must be position, pose or position_axis");
      }
      if (closure.body_a == closure.body_b)
        fail(source, c, "closure '" + closure.name + "' joins a body to itself");
      if (!closure_names.insert(closure.name).second)
        fail(source, c, "duplicate closure name '" + closure.name + "'");
      m.closures.push_back(closure);
    }
  }
  if (const YAML::Node rods = root["rods"]) {
    if (!rods.IsSequence()) fail(source, rods, "rods must be a list");
    for (const auto& r : rods) {
      check_keys(source, r, "rod", {"name", "a", "b", "length", "sigma", "free"});
      Closure closure;
      closure.line = line_of(r);
      closure.type = ClosureType::kDistance;
      if (!r["name"]) fail(source, r, "rod without 'name'");
      closure.name = text(source, r["name"], "name");
      if (!r["a"] || !r["b"]) fail(source, r, "rod '" + closure.name + "' needs 'a' and 'b'");
      closure.body_a = body_ref(source, m, r["a"], "rod '" + closure.name + "': a");
      closure.body_b = body_ref(source, m, r["b"], "rod '" + closure.name + "': b");
      if (!r["length"]) fail(source, r, "rod '" + closure.name + "' needs 'length'");
      if (!closure_names.insert(closure.name).second || m.body_index(closure.name) >= 0)
        fail(source, r, "rod name '" + closure.name + "' is already used");
      Parameter prm;
      prm.name = closure.name + ".length";
      prm.value = number(source, r["length"], prm.name);
      if (prm.value <= 0) fail(source, r["length"], "rod length must be > 0");
      prm.unit = ParamUnit::kLength;
      prm.group = ParamGroup::kRodLength;
      prm.closure = static_cast<int>(m.closures.size());
      prm.line = line_of(r["length"]);
      prm.sigma = r["sigma"] ? number(source, r["sigma"], "sigma") : sigma_defaults.at("length");
      prm.free = r["free"] ? r["free"].as<bool>(true) : true;
      closure.length_param = static_cast<int>(m.parameters.size());
      m.parameters.push_back(prm);
      m.closures.push_back(closure);
    }
  }
  for (const Body& b : m.bodies) {
    if (b.role != JointRole::kCut) continue;
    const bool used = std::any_of(m.closures.begin(), m.closures.end(), [&](const Closure& c) {
      return m.bodies[c.body_a].name == b.name || m.bodies[c.body_b].name == b.name;
    });
    if (!used)
      throw RobotFileError(source + ":" + std::to_string(b.line) + ": spherical body '" + b.name +
                           "' is not an end of any closure (a cut joint must close a loop)");
  }
}

void parse_tool_and_task(const YAML::Node& root, const std::string& source, Mechanism& m) {
  if (root["tool"]) {
    m.tool = body_ref(source, m, root["tool"], "tool");
  } else {
    m.tool = m.body_index("tool");
    if (m.tool < 0) m.tool = static_cast<int>(m.bodies.size()) - 1;
  }
  m.task.frame = m.tool;
  m.task.type = TaskType::kPose;
  if (const YAML::Node t = root["task"]) {
    check_keys(source, t, "task", {"type", "frame", "joint"});
    const std::string type = t["type"] ? text(source, t["type"], "task.type") : "pose";
    if (type == "position") {
      m.task.type = TaskType::kPosition;
    } else if (type == "pose") {
      m.task.type = TaskType::kPose;
    } else if (type == "joint") {
      m.task.type = TaskType::kJoint;
      m.task.joint = body_ref(source, m, t["joint"], "task.joint");
      if (m.bodies[m.task.joint].joint == JointType::kFixed)
        fail(source, t["joint"], "task.joint must be a moving joint");
    } else {
      fail(source, t["type"], "task.type must be position, pose or joint");
    }
    if (t["frame"]) m.task.frame = body_ref(source, m, t["frame"], "task.frame");
  }
}

void parse_controller(const YAML::Node& root, const std::string& source, Mechanism& m) {
  if (const YAML::Node c = root["controller"]) {
    check_keys(source, c, "controller", {"gcode_axes"});
    m.controller.line = c.Mark().line + 1;
    if (c["gcode_axes"]) {
      const std::string axes = text(source, c["gcode_axes"], "controller.gcode_axes");
      if (axes == "tool") {
        m.controller.gcode_axes = GcodeAxes::kTool;
      } else if (axes == "actuators") {
        m.controller.gcode_axes = GcodeAxes::kActuators;
      } else {
        fail(source, c["gcode_axes"],
             "controller.gcode_axes must be tool (the firmware computes this robot's kinematics: "
             "X Y Z = the tool position) or actuators (one G-code axis per actuator)");
      }
    }
  }
}

void parse_closed_form(const YAML::Node& root, const std::string& source, Mechanism& m) {
  if (const YAML::Node cf = root["closed_form"]) {
    check_keys(source, cf, "closed_form",
               {"type", "base_radius", "upper_arm", "rod", "plate_radius", "arm_angles",
                "rail_origins", "rail_directions", "platform_offsets", "link_lengths", "branch"});
    const std::string type = text(source, cf["type"], "closed_form.type");
    ClosedFormSpec& s = m.closed_form;
    auto need = [&](const char* key) {
      if (!cf[key]) fail(source, cf, std::string("closed_form needs '") + key + "'");
      return cf[key];
    };
    auto vec3_list = [&](const char* key) {
      std::vector<Eigen::Vector3d> out;
      const YAML::Node n = need(key);
      if (!n.IsSequence() || n.size() != 3) fail(source, n, std::string(key) + ": three [x,y,z]");
      for (const auto& v : n) out.push_back(vec3(source, v, key));
      return out;
    };
    if (m.actuated.size() != 3) fail(source, cf, "closed forms are for three actuators");
    if (type == "rotary_delta") {
      s.kind = ClosedFormKind::kRotaryDelta;
      s.base_radius = number(source, need("base_radius"), "base_radius");
      s.upper_arm = number(source, need("upper_arm"), "upper_arm");
      s.rod = number(source, need("rod"), "rod");
      s.plate_radius = number(source, need("plate_radius"), "plate_radius");
      const YAML::Node a = need("arm_angles");
      if (!a.IsSequence() || a.size() != 3) fail(source, a, "arm_angles: three angles");
      for (const auto& v : a) s.arm_angles.push_back(number(source, v, "arm_angles"));
    } else if (type == "rails") {
      s.kind = ClosedFormKind::kLinearDelta;
      s.rail_origin = vec3_list("rail_origins");
      s.rail_direction = vec3_list("rail_directions");
      s.platform_offset = vec3_list("platform_offsets");
      const YAML::Node l = need("link_lengths");
      if (!l.IsSequence() || l.size() != 3) fail(source, l, "link_lengths: three lengths");
      for (const auto& v : l) s.link_length.push_back(number(source, v, "link_lengths"));
      if (cf["branch"]) {
        const YAML::Node br = cf["branch"];
        check_keys(source, br, "branch", {"direction", "sign"});
        s.branch_direction = vec3(source, br["direction"], "branch.direction").normalized();
        s.branch_sign = number(source, br["sign"], "branch.sign") < 0 ? -1.0 : 1.0;
      }
    } else {
      fail(source, cf["type"], "closed_form.type must be rotary_delta or rails");
    }
  }
}

void parse_workspace(const YAML::Node& root, const std::string& source, Mechanism& m) {
  if (const YAML::Node w = root["workspace"]) {
    if (!w.IsMap()) fail(source, w, "workspace must be a map {min_task_conditioning: X}");
    check_keys(source, w, "workspace", {"min_task_conditioning"});
    m.workspace.line = w.Mark().line + 1;
    if (!w["min_task_conditioning"]) fail(source, w, "workspace needs 'min_task_conditioning'");
    const double c = number(source, w["min_task_conditioning"], "workspace.min_task_conditioning");
    if (!(c > 0.0 && c < 1.0))
      fail(source, w["min_task_conditioning"],
           "workspace.min_task_conditioning must be in (0, 1) (sigma_min/sigma_max), got " +
               std::to_string(c));
    m.workspace.min_task_conditioning = c;
  }
}

void parse_assembly_mode(const YAML::Node& node, const std::string& source, Mechanism& m) {
  if (!node) return;
  check_keys(source, node, "assembly_mode", {"ambiguity", "min_conditioning", "invariants"});
  AssemblyModeSpec& spec = m.assembly_mode;
  spec.line = line_of(node);
  if (node["ambiguity"]) {
    spec.ambiguity = number(source, node["ambiguity"], "assembly_mode.ambiguity");
    if (!(spec.ambiguity >= 0.0 && spec.ambiguity < 1.0))
      fail(source, node["ambiguity"], "assembly_mode.ambiguity must be in [0, 1)");
  }
  if (node["min_conditioning"]) {
    spec.min_conditioning =
        number(source, node["min_conditioning"], "assembly_mode.min_conditioning");
    if (!(spec.min_conditioning >= 0.0 && spec.min_conditioning < 1.0))
      fail(source, node["min_conditioning"], "assembly_mode.min_conditioning must be in [0, 1)");
  }
  const YAML::Node list = node["invariants"];
  if (!list || !list.IsSequence() || list.size() == 0)
    fail(source, list.IsDefined() ? list : node,
         "assembly_mode needs a non-empty list 'invariants' (testdata/robots/README.md)");
  std::set<std::string> names;
  for (const auto& n : list) {
    spec.invariants.push_back(parse_invariant(n, source, m));
    if (!names.insert(spec.invariants.back().name).second)
      fail(source, n, "duplicate assembly_mode invariant '" + spec.invariants.back().name + "'");
  }
  // The home configuration is, by the file's own words, on the intended mode: every invariant
  // must have its declared sign there, clear of the ambiguity band.
  const JointState home = home_joint_state(m);
  std::vector<Eigen::Isometry3d> poses;
  body_poses(m, m.nominal_parameters(), home, poses);
  for (const ModeInvariant& inv : spec.invariants) {
    const double v = invariant_value(inv, poses, home, m);
    if (!(inv.sign * v >= spec.ambiguity)) {
      std::ostringstream msg;
      msg.precision(3);
      msg << source << ":" << inv.line << ": assembly_mode invariant '" << inv.name << "' is " << v
          << " at the file's home configuration, but the file declares it "
          << (inv.sign > 0 ? "positive" : "negative")
          << (std::abs(v) < spec.ambiguity ? " (home sits on a mode boundary)" : "")
          << ": the declared mode contradicts the home values (fix the sign or the bodies' "
             "home:)";
      throw RobotFileError(msg.str());
    }
  }
}

// `labels:` maps a parameter name to its label, or a body or rod name to the words its
// parameters start with ("carriage_a: tower A carriage" gives "tower A carriage encoder zero").
// An exact parameter label wins over one made from its body's. A key that names nothing of this
// robot is an error at its line (a typo would otherwise leave a parameter unlabelled silently).
void parse_labels(const YAML::Node& node, const std::string& source, Mechanism& m) {
  if (!node) return;
  if (!node.IsMap()) fail(source, node, "labels must be a mapping NAME: words");
  std::map<std::string, std::string> owner_words;  // body or rod name -> words
  std::map<std::string, std::string> exact;        // parameter name -> label
  for (const auto& kv : node) {
    const std::string key = kv.first.Scalar();
    const std::string words = text(source, kv.second, "label of '" + key + "'");
    if (words.find_first_not_of(" \t") == std::string::npos)
      fail(source, kv.second, "label of '" + key + "' is empty");
    const bool is_parameter = m.parameter_index(key) >= 0;
    const bool is_owner = m.body_index(key) >= 0 ||
                          std::any_of(m.closures.begin(), m.closures.end(), [&](const Closure& c) {
                            return c.name == key && c.length_param >= 0;
                          });
    if (!is_parameter && !is_owner) {
      std::string hint;
      const std::string prefix = key.substr(0, key.find('.'));
      int shown = 0;
      for (const Parameter& p : m.parameters)
        if (p.name.rfind(prefix + ".", 0) == 0 && shown++ < 8) hint += " " + p.name;
      std::string what = "label for unknown parameter '";
      what += key;
      what += "' (not a parameter, body or rod of robot '";
      what += m.name;
      what += "'";
      if (!hint.empty()) {
        what += "; parameters of '";
        what += prefix;
        what += "':";
        what += hint;
      }
      what += ")";
      fail(source, kv.first, what);
    }
    (is_parameter ? exact : owner_words)[key] = words;
  }
  for (Parameter& p : m.parameters) {
    if (const auto it = exact.find(p.name); it != exact.end()) {
      p.label = it->second;
      continue;
    }
    const auto dot = p.name.find('.');
    const auto owner = owner_words.find(p.name.substr(0, dot));
    if (owner == owner_words.end()) continue;
    const std::string convention =
        p.body >= 0 ? m.bodies[static_cast<std::size_t>(p.body)].convention : std::string();
    p.label = owner->second + " " + key_words(convention, p.name.substr(dot + 1));
  }
}

}  // namespace robocal::calib::robot_yaml
