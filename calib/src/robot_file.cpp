// YAML robot description -> Mechanism. The loader is the only place that knows the file format;
// every error names file, line and problem.
#include "robocal/calib/robot_file.hpp"

#include "robot_units.hpp"

#include "robocal/calib/assembly_mode.hpp"
#include "robocal/calib/kinematics.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>

namespace robocal::calib {
namespace {

struct OpSpec {
  OpKind kind;
  const char* key;  // parameter key, nullptr = constant 0
  bool joint;
};

struct ConventionSpec {
  std::vector<OpSpec> ops;
  std::vector<std::string> default_fixed;  // keys fixed by default (redundant in this convention)
};

[[noreturn]] void fail(const std::string& source, const YAML::Node& node, const std::string& what) {
  std::ostringstream msg;
  msg << source;
  if (node.IsDefined() && node.Mark().line >= 0) msg << ":" << node.Mark().line + 1;
  msg << ": " << what;
  throw RobotFileError(msg.str());
}

int line_of(const YAML::Node& node) {
  return node.IsDefined() && node.Mark().line >= 0 ? node.Mark().line + 1 : 0;
}

// The expansion of every convention into elementary ops (see README.md).
ConventionSpec convention_spec(const std::string& convention, JointType joint,
                               const std::string& rotation_order, const std::string& axis) {
  using K = OpKind;
  const bool rev = joint == JointType::kRevolute;
  const bool pri = joint == JointType::kPrismatic;
  if (convention == "mcpc") {
    if (pri)
      return {{{K::kRotX, "a1", false},
               {K::kRotY, "a2", false},
               {K::kTransX, "d1", false},
               {K::kTransY, "d2", false},
               {K::kRotZ, "a3", false},
               {K::kTransZ, "d3", true}},
              {"a3", "d1", "d2"}};
    return {{{K::kRotX, "a1", false},
             {K::kRotY, "a2", false},
             {K::kTransX, "d1", false},
             {K::kTransY, "d2", false},
             {K::kTransZ, "d3", false},
             {K::kRotZ, "a3", rev}},
            rev ? std::vector<std::string>{"d3"} : std::vector<std::string>{}};
  }
  if (convention == "dh") {
    return {{{K::kRotZ, "theta", rev},
             {K::kTransZ, "d", pri},
             {K::kTransX, "a", false},
             {K::kRotX, "alpha", false}},
            {}};
  }
  if (convention == "mdh") {
    return {{{K::kRotX, "alpha", false},
             {K::kTransX, "a", false},
             {K::kRotZ, "theta", rev},
             {K::kTransZ, "d", pri}},
            {}};
  }
  if (convention == "hayati") {
    return {{{K::kRotZ, "theta", rev},
             {K::kTransX, "a", false},
             {K::kRotX, "alpha", false},
             {K::kRotY, "beta", false}},
            {}};
  }
  // xyz_rpy
  ConventionSpec spec;
  spec.ops = {{K::kTransX, "x", false}, {K::kTransY, "y", false}, {K::kTransZ, "z", false}};
  if (rotation_order == "xyz") {
    spec.ops.push_back({K::kRotX, "roll", false});
    spec.ops.push_back({K::kRotY, "pitch", false});
    spec.ops.push_back({K::kRotZ, "yaw", false});
  } else {
    spec.ops.push_back({K::kRotZ, "yaw", false});
    spec.ops.push_back({K::kRotY, "pitch", false});
    spec.ops.push_back({K::kRotX, "roll", false});
  }
  if (rev || pri) {
    const char a = axis.back();
    K kind = K::kRotZ;
    if (rev) kind = a == 'x' ? K::kRotX : (a == 'y' ? K::kRotY : K::kRotZ);
    if (pri) kind = a == 'x' ? K::kTransX : (a == 'y' ? K::kTransY : K::kTransZ);
    spec.ops.push_back({kind, nullptr, true});
  }
  return spec;
}

const std::set<std::string> kConventions = {"mcpc", "dh", "mdh", "hayati", "xyz_rpy"};

double number(const std::string& source, const YAML::Node& node, const std::string& what) {
  if (!node.IsScalar()) fail(source, node, what + " must be a number or an expression");
  try {
    return evaluate_expression(node.Scalar());
  } catch (const std::invalid_argument& e) {
    fail(source, node, what + ": " + e.what());
  }
}

std::string text(const std::string& source, const YAML::Node& node, const std::string& what) {
  if (!node.IsScalar()) fail(source, node, what + " must be a text value");
  return node.Scalar();
}

Eigen::Vector3d vec3(const std::string& source, const YAML::Node& node, const std::string& what) {
  if (!node.IsSequence() || node.size() != 3) fail(source, node, what + " must be [x, y, z]");
  return {number(source, node[0], what), number(source, node[1], what),
          number(source, node[2], what)};
}

// ---- Frames given as users have them (issue 22) -------------------------------------------
// `orientation:` of an xyz_rpy body: {quaternion: [w, x, y, z]}, {quaternion_xyzw: [x, y, z, w]},
// {rotation_vector: [rx, ry, rz]} (rad) or {matrix: [9 numbers, row-major]}. The rotation R0 is
// applied after the translation and BEFORE roll/pitch/yaw, which then default to 0 and act as
// local increments: a frame is never parameterised at a gimbal lock, whatever R0 is.
Eigen::Matrix3d orientation_of(const std::string& source, const YAML::Node& node,
                               const std::string& body) {
  const std::string what = "body '" + body + "': orientation";
  if (!node.IsMap() || node.size() != 1)
    fail(source, node,
         what +
             " must be one of {quaternion: [w, x, y, z]}, {quaternion_xyzw: [x, y, z, w]}, "
             "{rotation_vector: [rx, ry, rz]}, {matrix: [9 numbers, row-major]}");
  const std::string form = node.begin()->first.Scalar();
  const YAML::Node v = node.begin()->second;
  auto numbers = [&](std::size_t n) {
    if (!v.IsSequence() || v.size() != n)
      fail(source, v, what + "." + form + " must have " + std::to_string(n) + " numbers");
    std::vector<double> x;
    for (std::size_t i = 0; i < n; ++i) x.push_back(number(source, v[i], what));
    return x;
  };
  if (form == "quaternion" || form == "quaternion_xyzw") {
    const auto x = numbers(4);
    const Eigen::Quaterniond q = form == "quaternion" ? Eigen::Quaterniond(x[0], x[1], x[2], x[3])
                                                      : Eigen::Quaterniond(x[3], x[0], x[1], x[2]);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      fail(source, v,
           what + ": quaternion must have unit norm (has " + std::to_string(q.norm()) +
               "; w first for 'quaternion', w last for 'quaternion_xyzw')");
    return q.normalized().toRotationMatrix();
  }
  if (form == "rotation_vector") {
    const auto x = numbers(3);
    const Eigen::Vector3d w(x[0], x[1], x[2]);
    return w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                        : Eigen::Matrix3d::Identity();
  }
  if (form == "matrix") {
    const auto x = numbers(9);
    Eigen::Matrix3d R;
    R << x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8];
    if (!(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || R.determinant() < 0)
      fail(source, v, what + ".matrix is not a rotation (orthonormal, determinant +1)");
    return R;
  }
  fail(source, node.begin()->first,
       what + ": unknown form '" + form +
           "' (quaternion, quaternion_xyzw, rotation_vector, matrix)");
}
// ---- end of frames given as users have them --------------------------------------------------

void check_keys(const std::string& source, const YAML::Node& map, const std::string& what,
                const std::set<std::string>& allowed) {
  if (!map.IsMap()) fail(source, map, what + " must be a mapping");
  for (const auto& kv : map) {
    const std::string key = kv.first.Scalar();
    if (!allowed.count(key)) {
      std::string list;
      for (const auto& a : allowed) {
        if (!list.empty()) list += ", ";
        list += a;
      }
      std::ostringstream message;
      message << "unknown key '" << key << "' in " << what << " (allowed: " << list << ")";
      fail(source, kv.first, message.str());
    }
  }
}

std::vector<std::string> string_list(const std::string& source, const YAML::Node& node,
                                     const std::string& what) {
  std::vector<std::string> out;
  if (!node.IsDefined()) return out;
  if (!node.IsSequence()) fail(source, node, what + " must be a list");
  for (const auto& item : node) out.push_back(text(source, item, what));
  return out;
}

struct RawBody {
  YAML::Node node;
  std::string name, parent;
};

double default_sigma(const std::map<std::string, double>& sigma, ParamUnit unit) {
  switch (unit) {
    case ParamUnit::kLength:
      return sigma.at("length");
    case ParamUnit::kAngle:
      return sigma.at("angle");
    case ParamUnit::kScale:
      return sigma.at("scale");
  }
  return 1.0;
}

// ---------------------------------------------------------------------------------------------
// Assembly mode (issue 15): `assembly_mode:` -> Mechanism::assembly_mode, checked against the
// file's own home configuration. Kept apart from the rest of the loader on purpose.

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

// ---- Labels: parameters in a technician's words (issue 20) ---------------------------------
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
// ---- end of labels -----------------------------------------------------------------------------

Mechanism parse(const YAML::Node& root, const std::string& source) {
  if (!root.IsMap()) fail(source, root, "a robot file must be a YAML mapping");
  check_keys(source, root, "robot file",
             {"robot", "description", "source", "rotation_order", "sigma_defaults", "tool", "task",
              "closed_form", "workspace", "bodies", "closures", "rods", "assembly_mode", "labels",
              "unmodelled_error", "controller"});
  Mechanism m;
  m.source = source;
  if (!root["robot"]) fail(source, root, "missing 'robot' (the robot's name)");
  m.name = text(source, root["robot"], "robot");
  if (root["description"]) m.description = text(source, root["description"], "description");

  std::string default_order = "xyz";
  if (root["rotation_order"]) {
    default_order = text(source, root["rotation_order"], "rotation_order");
    if (default_order != "xyz" && default_order != "zyx")
      fail(source, root["rotation_order"], "rotation_order must be xyz or zyx");
  }
  std::map<std::string, double> sigma_defaults = {
      {"length", 1e-3}, {"angle", 1e-2}, {"scale", 1e-3}};
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

  // --- bodies: names, predecessors, topological (pre-order) sort, cycle detection
  const YAML::Node bodies = root["bodies"];
  if (!bodies || !bodies.IsSequence() || bodies.size() == 0)
    fail(source, bodies ? bodies : root, "'bodies' must be a non-empty list");
  std::vector<RawBody> raw;
  std::map<std::string, int> raw_index;
  for (const auto& b : bodies) {
    check_keys(
        source, b, "body",
        {"name",      "parent",         "convention", "joint",       "role",     "params", "free",
         "fixed",     "exact",          "sigma",      "encoder",     "limits",   "cone",   "home",
         "collision", "rotation_order", "axis",       "orientation", "velocity", "effort"});
    if (!b["name"]) fail(source, b, "body without 'name'");
    RawBody r{b, text(source, b["name"], "name"), "world"};
    if (r.name == "world") fail(source, b["name"], "'world' is the root frame, not a body name");
    if (raw_index.count(r.name)) fail(source, b["name"], "duplicate body name '" + r.name + "'");
    if (b["parent"]) r.parent = text(source, b["parent"], "parent");
    raw_index[r.name] = static_cast<int>(raw.size());
    raw.push_back(r);
  }
  for (const RawBody& r : raw)
    if (r.parent != "world" && !raw_index.count(r.parent))
      fail(source, r.node["parent"],
           "body '" + r.name + "': unknown predecessor '" + r.parent + "'");
  // Pre-order DFS from the world; bodies never reached sit on a cycle.
  std::vector<std::vector<int>> children(raw.size());
  std::vector<int> roots;
  for (int i = 0; i < static_cast<int>(raw.size()); ++i) {
    if (raw[i].parent == "world")
      roots.push_back(i);
    else
      children[raw_index[raw[i].parent]].push_back(i);
  }
  std::vector<int> order;  // order[new] = raw index
  std::function<void(int)> visit = [&](int i) {
    order.push_back(i);
    for (int c : children[i]) visit(c);
  };
  for (int r : roots) visit(r);
  if (order.size() != raw.size()) {
    std::vector<bool> seen(raw.size(), false);
    for (int i : order) seen[i] = true;
    for (std::size_t i = 0; i < raw.size(); ++i)
      if (!seen[i])
        fail(source, raw[i].node["parent"],
             "body '" + raw[i].name + "' is on a cycle of predecessors (never reaches 'world')");
  }
  std::vector<int> new_index(raw.size());
  for (int k = 0; k < static_cast<int>(order.size()); ++k) new_index[order[k]] = k;
  m.bodies.resize(raw.size());

  // --- per body: joint, convention, parameters (created in file order)
  for (int ri = 0; ri < static_cast<int>(raw.size()); ++ri) {
    const YAML::Node& b = raw[ri].node;
    const int bi = new_index[ri];
    Body& body = m.bodies[bi];
    body.name = raw[ri].name;
    body.line = line_of(b);
    body.parent = raw[ri].parent == "world" ? -1 : new_index[raw_index[raw[ri].parent]];
    const std::string joint = b["joint"] ? text(source, b["joint"], "joint") : "fixed";
    bool cut = false;
    if (joint == "revolute") {
      body.joint = JointType::kRevolute;
    } else if (joint == "prismatic") {
      body.joint = JointType::kPrismatic;
    } else if (joint == "fixed") {
      body.joint = JointType::kFixed;
    } else if (joint == "spherical") {
      body.joint = JointType::kFixed;
      cut = true;
    } else {
      fail(source, b["joint"],
           "body '" + body.name + "': joint must be revolute, prismatic, fixed or spherical");
    }
    const bool moving = body.joint != JointType::kFixed;
    body.role = cut ? JointRole::kCut : (moving ? JointRole::kPassive : JointRole::kAuxiliary);
    if (b["role"]) {
      const std::string role = text(source, b["role"], "role");
      if (!moving)
        fail(source, b["role"],
             "body '" + body.name + "': a " + joint + " joint has no role (only moving joints do)");
      if (role == "actuated") {
        body.role = JointRole::kActuated;
      } else if (role != "passive") {
        fail(source, b["role"], "role must be actuated or passive");
      }
    }
    if (!b["convention"]) fail(source, b, "body '" + body.name + "': missing 'convention'");
    body.convention = text(source, b["convention"], "convention");
    if (!kConventions.count(body.convention))
      fail(source, b["convention"],
           "body '" + body.name + "': unknown convention '" + body.convention +
               "' (mcpc, dh, mdh (Craig's modified DH), hayati, xyz_rpy)");
    if (body.convention == "hayati" && body.joint == JointType::kPrismatic)
      fail(source, b["joint"], "body '" + body.name + "': hayati is for revolute joints");
    std::string order_text = default_order;
    if (b["rotation_order"]) {
      order_text = text(source, b["rotation_order"], "rotation_order");
      if (order_text != "xyz" && order_text != "zyx")
        fail(source, b["rotation_order"], "rotation_order must be xyz or zyx");
    }
    std::string axis = "z";
    double sign = 1.0;
    if (b["axis"]) {
      if (body.convention != "xyz_rpy")
        fail(source, b["axis"], "'axis' is only for xyz_rpy bodies (others move about z)");
      axis = text(source, b["axis"], "axis");
      static const std::set<std::string> axes = {"x", "y", "z", "-x", "-y", "-z"};
      if (!axes.count(axis)) fail(source, b["axis"], "axis must be x, y, z, -x, -y or -z");
      if (axis[0] == '-') sign = -1.0;
    }
    const ConventionSpec spec = convention_spec(body.convention, body.joint, order_text, axis);
    std::set<std::string> keys;
    for (const OpSpec& op : spec.ops)
      if (op.key) keys.insert(op.key);

    std::map<std::string, double> values;
    std::map<std::string, int> lines;
    if (const YAML::Node p = b["params"]) {
      check_keys(source, p, "params of body '" + body.name + "' (" + body.convention + ")", keys);
      for (const auto& kv : p) {
        values[kv.first.Scalar()] = number(source, kv.second, body.name + "." + kv.first.Scalar());
        lines[kv.first.Scalar()] = line_of(kv.second);
      }
    }
    std::set<std::string> fixed(spec.default_fixed.begin(), spec.default_fixed.end());
    for (const std::string& k : string_list(source, b["fixed"], "fixed")) {
      if (!keys.count(k) && k != "encoder_offset" && k != "encoder_scale")
        fail(source, b["fixed"],
             "body '" + body.name + "': 'fixed' names unknown parameter '" + k + "'");
      fixed.insert(k);
    }
    std::set<std::string> exact;
    for (const std::string& k : string_list(source, b["exact"], "exact")) {
      if (!keys.count(k))
        fail(source, b["exact"],
             "body '" + body.name + "': 'exact' names unknown parameter '" + k + "'");
      exact.insert(k);
      fixed.insert(k);
    }
    std::set<std::string> freed;
    for (const std::string& k : string_list(source, b["free"], "free")) {
      if (!keys.count(k) && k != "encoder_offset" && k != "encoder_scale")
        fail(source, b["free"],
             "body '" + body.name + "': 'free' names unknown parameter '" + k + "'");
      if (exact.count(k))
        fail(source, b["free"],
             "body '" + body.name + "': '" + k +
                 "' is both 'exact' (cannot differ from the drawing) and 'free' (identified)");
      freed.insert(k);
      fixed.erase(k);
    }
    std::map<std::string, double> sigmas;
    if (const YAML::Node s = b["sigma"]) {
      if (!s.IsMap()) fail(source, s, "sigma must be a mapping NAME: value");
      for (const auto& kv : s) {
        const std::string k = kv.first.Scalar();
        if (!keys.count(k) && k != "encoder_offset" && k != "encoder_scale")
          fail(source, kv.first,
               "body '" + body.name + "': sigma for unknown parameter '" + k + "'");
        const double v = number(source, kv.second, "sigma");
        if (v <= 0) fail(source, kv.second, "sigma must be > 0");
        sigmas[k] = v;
      }
    }
    auto add_param = [&](const std::string& key, ParamUnit unit, ParamGroup group, double value,
                         bool is_free, int line) {
      Parameter prm;
      prm.name = body.name + "." + key;
      prm.value = value;
      prm.free = is_free;
      prm.unit = unit;
      prm.group = group;
      prm.body = bi;
      prm.line = line;
      prm.sigma = sigmas.count(key) ? sigmas[key] : default_sigma(sigma_defaults, unit);
      m.parameters.push_back(prm);
      return static_cast<int>(m.parameters.size()) - 1;
    };
    const ParamGroup geom_group = moving ? ParamGroup::kJointGeometry : ParamGroup::kFrame;
    for (const OpSpec& op : spec.ops) {
      ElementaryOp e;
      e.kind = op.kind;
      e.joint = op.joint;
      e.sign = op.joint ? sign : 1.0;
      if (op.key) {
        const bool angle =
            op.kind == OpKind::kRotX || op.kind == OpKind::kRotY || op.kind == OpKind::kRotZ;
        const double v = values.count(op.key) ? values[op.key] : 0.0;
        e.param = add_param(op.key, angle ? ParamUnit::kAngle : ParamUnit::kLength, geom_group, v,
                            !fixed.count(op.key), lines.count(op.key) ? lines[op.key] : body.line);
        m.parameters[static_cast<std::size_t>(e.param)].exact = exact.count(op.key) > 0;
      }
      if (op.joint) body.joint_op = static_cast<int>(body.ops.size());
      body.ops.push_back(e);
      if (op.kind == OpKind::kTransZ && b["orientation"]) {
        // Issue 22: the fixed orientation R0 = Rx Ry Rz (held parameters), then roll/pitch/yaw.
        const Eigen::Vector3d a =
            orientation_of(source, b["orientation"], body.name).eulerAngles(0, 1, 2);
        const OpKind kinds[3] = {OpKind::kRotX, OpKind::kRotY, OpKind::kRotZ};
        for (int k = 0; k < 3; ++k) {
          ElementaryOp r;
          r.kind = kinds[k];
          r.param = add_param("orientation_" + std::string(1, "xyz"[k]), ParamUnit::kAngle,
                              geom_group, a(k), false, line_of(b["orientation"]));
          body.ops.push_back(r);
        }
      }
    }
    if (b["orientation"] && body.convention != "xyz_rpy")
      fail(source, b["orientation"], "'orientation' is only for xyz_rpy bodies");
    if (body.role == JointRole::kActuated) {
      double scale = 1.0, offset = 0.0;
      if (const YAML::Node enc = b["encoder"]) {
        check_keys(source, enc, "encoder", {"scale", "offset"});
        if (enc["scale"]) scale = number(source, enc["scale"], "encoder.scale");
        if (enc["offset"]) offset = number(source, enc["offset"], "encoder.offset");
        if (scale == 0.0) fail(source, enc["scale"], "encoder scale must not be 0");
      }
      const ParamUnit joint_unit =
          body.joint == JointType::kRevolute ? ParamUnit::kAngle : ParamUnit::kLength;
      body.encoder_offset_param =
          add_param("encoder_offset", joint_unit, ParamGroup::kEncoderOffset, offset,
                    freed.count("encoder_offset") > 0, body.line);
      body.encoder_scale_param =
          add_param("encoder_scale", ParamUnit::kScale, ParamGroup::kEncoderScale, scale,
                    freed.count("encoder_scale") > 0, body.line);
    } else if (b["encoder"]) {
      fail(source, b["encoder"], "body '" + body.name + "': only actuated joints have an encoder");
    }
    if (const YAML::Node lim = b["limits"]) {
      if (!lim.IsSequence() || lim.size() != 2) fail(source, lim, "limits must be [lower, upper]");
      body.limits.lower = number(source, lim[0], "limits");
      body.limits.upper = number(source, lim[1], "limits");
      if (body.limits.lower > body.limits.upper) fail(source, lim, "limits: lower > upper");
    }
    if (b["cone"]) body.limits.cone = number(source, b["cone"], "cone");
    // The drive's rated speed and force (exports such as URDF carry them; robocal plans nothing
    // with them).
    for (const auto& [key, value] :
         {std::pair<const char*, double*>{"velocity", &body.limits.velocity},
          std::pair<const char*, double*>{"effort", &body.limits.effort}}) {
      if (!b[key]) continue;
      if (!moving) fail(source, b[key], std::string(key) + " is only for moving joints");
      *value = number(source, b[key], key);
      if (!(*value > 0.0))
        fail(source, b[key],
             std::string(key) + " must be > 0 (rad/s or m/s for velocity, N m or N for effort)");
    }
    if (b["home"]) {
      if (!moving) fail(source, b["home"], "home is only for moving joints");
      body.home = number(source, b["home"], "home");
    }
    if (const YAML::Node col = b["collision"]) {
      if (!col.IsSequence()) fail(source, col, "collision must be a list of shapes");
      for (const auto& s : col) {
        CollisionShape shape;
        if (s["capsule"]) {
          const YAML::Node c = s["capsule"];
          check_keys(source, c, "capsule", {"a", "b", "radius"});
          shape.kind = ShapeKind::kCapsule;
          shape.a = vec3(source, c["a"], "capsule.a");
          shape.b = vec3(source, c["b"], "capsule.b");
          shape.radius = number(source, c["radius"], "capsule.radius");
          if (shape.radius <= 0) fail(source, c["radius"], "capsule radius must be > 0");
        } else if (s["box"]) {
          const YAML::Node c = s["box"];
          check_keys(source, c, "box", {"center", "size", "rpy"});
          shape.kind = ShapeKind::kBox;
          shape.a = vec3(source, c["center"], "box.center");
          shape.half_size = 0.5 * vec3(source, c["size"], "box.size");
          if ((shape.half_size.array() <= 0).any())
            fail(source, c["size"], "box sizes must be > 0");
          if (c["rpy"]) {
            const Eigen::Vector3d rpy = vec3(source, c["rpy"], "box.rpy");
            shape.rotation = (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
                              Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
                                 .toRotationMatrix();
          }
        } else {
          fail(source, s, "collision shape must be {capsule: ...} or {box: ...}");
        }
        body.collision.push_back(shape);
      }
    }
  }
  // Subtree intervals and joint lists (in sorted order; actuated in file order below).
  for (int i = static_cast<int>(m.bodies.size()) - 1; i >= 0; --i) {
    Body& b = m.bodies[i];
    if (b.subtree_end < i + 1) b.subtree_end = i + 1;
    if (b.parent >= 0)
      m.bodies[b.parent].subtree_end = std::max(m.bodies[b.parent].subtree_end, b.subtree_end);
  }
  for (int ri = 0; ri < static_cast<int>(raw.size()); ++ri) {
    const int bi = new_index[ri];
    Body& b = m.bodies[bi];
    if (b.role == JointRole::kActuated) {
      b.actuator = static_cast<int>(m.actuated.size());
      m.actuated.push_back(bi);
    }
  }
  for (int bi = 0; bi < static_cast<int>(m.bodies.size()); ++bi) {
    Body& b = m.bodies[bi];
    if (b.role == JointRole::kPassive) {
      b.passive = static_cast<int>(m.passive.size());
      m.passive.push_back(bi);
    }
  }

  // --- closures and rods
  auto body_ref = [&](const YAML::Node& n, const std::string& what) {
    if (!n) fail(source, n, what + " missing");
    const std::string name = text(source, n, what);
    const int i = m.body_index(name);
    if (i < 0) fail(source, n, what + " names a missing body '" + name + "'");
    return i;
  };
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
      closure.body_a = body_ref(c["a"], "closure '" + closure.name + "': a");
      closure.body_b = body_ref(c["b"], "closure '" + closure.name + "': b");
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
      closure.body_a = body_ref(r["a"], "rod '" + closure.name + "': a");
      closure.body_b = body_ref(r["b"], "rod '" + closure.name + "': b");
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
      prm.sigma = r["sigma"] ? number(source, r["sigma"], "sigma") : sigma_defaults["length"];
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

  // --- tool frame and task
  if (root["tool"]) {
    m.tool = body_ref(root["tool"], "tool");
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
      m.task.joint = body_ref(t["joint"], "task.joint");
      if (m.bodies[m.task.joint].joint == JointType::kFixed)
        fail(source, t["joint"], "task.joint must be a moving joint");
    } else {
      fail(source, t["type"], "task.type must be position, pose or joint");
    }
    if (t["frame"]) m.task.frame = body_ref(t["frame"], "task.frame");
  }

  // --- what the controller's G-code axes are
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

  // --- closed form (seeds)
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
  // --- working volume
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

std::string describe_convention(const std::string& convention, JointType joint) {
  const ConventionSpec spec = convention_spec(convention, joint, "xyz", "z");
  std::string out;
  for (const OpSpec& op : spec.ops) {
    static const char* names[] = {"Rx", "Ry", "Rz", "Tx", "Ty", "Tz"};
    if (!out.empty()) out += ' ';
    out += names[static_cast<int>(op.kind)];
    out += '(';
    if (op.key) out += op.key;
    if (op.joint) out += op.key ? " + q" : "q";
    out += ")";
  }
  return out;
}

}  // namespace robocal::calib
