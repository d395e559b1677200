// The bodies of a robot file: their tree, and per body the joint, the convention's elementary
// operations and their parameters, the encoder, the limits and the collision shapes.
#include "robot_file_parse.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <functional>

namespace robocal::calib::robot_yaml {
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

// The bodies as the file lists them, before sorting.
struct BodyTree {
  std::vector<RawBody> raw;
  std::map<std::string, int> raw_index;  // name -> index in raw
  std::vector<int> new_index;            // raw index -> index in m.bodies
};

// Names and predecessors of `bodies:`, sorted pre-order from the world (a body follows its
// predecessor); a body never reached sits on a cycle, which is an error.
BodyTree body_tree(const YAML::Node& root, const std::string& source) {
  const YAML::Node bodies = root["bodies"];
  if (!bodies || !bodies.IsSequence() || bodies.size() == 0)
    fail(source, bodies ? bodies : root, "'bodies' must be a non-empty list");
  BodyTree tree;
  std::vector<RawBody>& raw = tree.raw;
  std::map<std::string, int>& raw_index = tree.raw_index;
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
  tree.new_index.resize(raw.size());
  for (int k = 0; k < static_cast<int>(order.size()); ++k) tree.new_index[order[k]] = k;
  return tree;
}

// The body's joint type and role (a spherical joint is a fixed one that cuts a loop).
void parse_joint(const std::string& source, const YAML::Node& b, Body& body) {
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
}

// The body's convention expanded into elementary operations (its rotation order and, for
// xyz_rpy, its joint axis), and the sign of that axis.
struct BodyConvention {
  ConventionSpec spec;
  double sign = 1.0;
};

BodyConvention body_convention(const std::string& source, const YAML::Node& b, Body& body,
                               const std::string& default_order) {
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
  return {convention_spec(body.convention, body.joint, order_text, axis), sign};
}

// What the body says of its parameters: values and their lines, which are fixed, exact or
// freed, and their σ.
struct ParameterChoices {
  std::map<std::string, double> values;
  std::map<std::string, int> lines;
  std::set<std::string> fixed;
  std::set<std::string> exact;
  std::set<std::string> freed;
  std::map<std::string, double> sigmas;
};

ParameterChoices parameter_choices(const std::string& source, const YAML::Node& b, const Body& body,
                                   const ConventionSpec& spec, const std::set<std::string>& keys) {
  ParameterChoices c;
  std::map<std::string, double>& values = c.values;
  std::map<std::string, int>& lines = c.lines;
  if (const YAML::Node p = b["params"]) {
    check_keys(source, p, "params of body '" + body.name + "' (" + body.convention + ")", keys);
    for (const auto& kv : p) {
      values[kv.first.Scalar()] = number(source, kv.second, body.name + "." + kv.first.Scalar());
      lines[kv.first.Scalar()] = line_of(kv.second);
    }
  }
  std::set<std::string>& fixed = c.fixed;
  fixed.insert(spec.default_fixed.begin(), spec.default_fixed.end());
  for (const std::string& k : string_list(source, b["fixed"], "fixed")) {
    if (!keys.count(k) && k != "encoder_offset" && k != "encoder_scale")
      fail(source, b["fixed"],
           "body '" + body.name + "': 'fixed' names unknown parameter '" + k + "'");
    fixed.insert(k);
  }
  std::set<std::string>& exact = c.exact;
  for (const std::string& k : string_list(source, b["exact"], "exact")) {
    if (!keys.count(k))
      fail(source, b["exact"],
           "body '" + body.name + "': 'exact' names unknown parameter '" + k + "'");
    exact.insert(k);
    fixed.insert(k);
  }
  std::set<std::string>& freed = c.freed;
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
  std::map<std::string, double>& sigmas = c.sigmas;
  if (const YAML::Node s = b["sigma"]) {
    if (!s.IsMap()) fail(source, s, "sigma must be a mapping NAME: value");
    for (const auto& kv : s) {
      const std::string k = kv.first.Scalar();
      if (!keys.count(k) && k != "encoder_offset" && k != "encoder_scale")
        fail(source, kv.first, "body '" + body.name + "': sigma for unknown parameter '" + k + "'");
      const double v = number(source, kv.second, "sigma");
      if (v <= 0) fail(source, kv.second, "sigma must be > 0");
      sigmas[k] = v;
    }
  }
  return c;
}

// Appends the body's parameters to m.parameters, named body.key, with the σ the body gives or
// the file's default for the unit.
struct ParameterAdder {
  Mechanism& m;
  const Body& body;
  int bi;
  ParameterChoices& choices;
  const std::map<std::string, double>& sigma_defaults;

  int operator()(const std::string& key, ParamUnit unit, ParamGroup group, double value,
                 bool is_free, int line) const {
    std::map<std::string, double>& sigmas = choices.sigmas;
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
  }
};

// The body's elementary operations with a parameter each (in the convention's order), the fixed
// orientation of an xyz_rpy body after its translation.
void add_operations(const std::string& source, const YAML::Node& b, Body& body,
                    const BodyConvention& convention, const ParameterAdder& add_param,
                    Mechanism& m) {
  const ConventionSpec& spec = convention.spec;
  const double sign = convention.sign;
  std::map<std::string, double>& values = add_param.choices.values;
  std::map<std::string, int>& lines = add_param.choices.lines;
  const std::set<std::string>& fixed = add_param.choices.fixed;
  const std::set<std::string>& exact = add_param.choices.exact;
  const bool moving = body.joint != JointType::kFixed;
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
}

// An actuated joint's encoder offset and scale (parameters); only actuated joints have one.
void parse_encoder(const std::string& source, const YAML::Node& b, Body& body,
                   const ParameterAdder& add_param) {
  const std::set<std::string>& freed = add_param.choices.freed;
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
    body.encoder_offset_param = add_param("encoder_offset", joint_unit, ParamGroup::kEncoderOffset,
                                          offset, freed.count("encoder_offset") > 0, body.line);
    body.encoder_scale_param =
        add_param("encoder_scale", ParamUnit::kScale, ParamGroup::kEncoderScale, scale,
                  freed.count("encoder_scale") > 0, body.line);
  } else if (b["encoder"]) {
    fail(source, b["encoder"], "body '" + body.name + "': only actuated joints have an encoder");
  }
}

// Joint limits, cone, rated speed and force, home.
void parse_limits(const std::string& source, const YAML::Node& b, Body& body) {
  const bool moving = body.joint != JointType::kFixed;
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
}

// Collision shapes: capsules and boxes in the body's frame.
void parse_collision(const std::string& source, const YAML::Node& b, Body& body) {
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
        if ((shape.half_size.array() <= 0).any()) fail(source, c["size"], "box sizes must be > 0");
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

}  // namespace

void parse_bodies(const YAML::Node& root, const std::string& source,
                  const std::string& default_order,
                  const std::map<std::string, double>& sigma_defaults, Mechanism& m) {
  BodyTree tree = body_tree(root, source);
  const std::vector<RawBody>& raw = tree.raw;
  m.bodies.resize(raw.size());

  // Per body: joint, convention, parameters (created in file order).
  for (int ri = 0; ri < static_cast<int>(raw.size()); ++ri) {
    const YAML::Node& b = raw[ri].node;
    const int bi = tree.new_index[ri];
    Body& body = m.bodies[bi];
    body.name = raw[ri].name;
    body.line = line_of(b);
    body.parent = raw[ri].parent == "world" ? -1 : tree.new_index[tree.raw_index[raw[ri].parent]];
    parse_joint(source, b, body);
    const BodyConvention convention = body_convention(source, b, body, default_order);
    std::set<std::string> keys;
    for (const OpSpec& op : convention.spec.ops)
      if (op.key) keys.insert(op.key);
    ParameterChoices choices = parameter_choices(source, b, body, convention.spec, keys);
    const ParameterAdder add_param{m, body, bi, choices, sigma_defaults};
    add_operations(source, b, body, convention, add_param, m);
    parse_encoder(source, b, body, add_param);
    parse_limits(source, b, body);
    parse_collision(source, b, body);
  }
  // Subtree intervals and joint lists (in sorted order; actuated in file order below).
  for (int i = static_cast<int>(m.bodies.size()) - 1; i >= 0; --i) {
    Body& b = m.bodies[i];
    if (b.subtree_end < i + 1) b.subtree_end = i + 1;
    if (b.parent >= 0)
      m.bodies[b.parent].subtree_end = std::max(m.bodies[b.parent].subtree_end, b.subtree_end);
  }
  for (int ri = 0; ri < static_cast<int>(raw.size()); ++ri) {
    const int bi = tree.new_index[ri];
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
}

}  // namespace robocal::calib::robot_yaml
