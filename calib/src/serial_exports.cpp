// URDF out and in, DH tables (serial_exports.hpp).
#include "robocal/calib/serial_exports.hpp"

#include "robocal/calib/kinematics.hpp"
#include "robocal/core/input_error.hpp"

#include <fmt/core.h>
#include <urdf_parser/urdf_parser.h>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace robocal::calib {
namespace {

bool is_rotation(OpKind k) {
  return static_cast<int>(k) < 3;
}
Eigen::Vector3d unit_axis(OpKind k) {
  return Eigen::Vector3d::Unit(static_cast<int>(k) % 3);
}

Eigen::Isometry3d elementary(OpKind kind, double value) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (is_rotation(kind))
    T.linear() = Eigen::AngleAxisd(value, unit_axis(kind)).toRotationMatrix();
  else
    T.translation() = value * unit_axis(kind);
  return T;
}

double param_value(const Eigen::VectorXd& params, int index) {
  return index >= 0 ? params[index] : 0.0;
}

// A body's transform split at its joint: parent -> A -> joint motion (about/along `axis`) -> B.
struct JointSplit {
  Eigen::Isometry3d before = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d after = Eigen::Isometry3d::Identity();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // in the joint frame, with the joint's sign
  bool rotation = true;
  double scale = 1.0;  // encoder scale (1 for joints without an encoder model)
};

JointSplit split(const Body& b, const Eigen::VectorXd& params) {
  JointSplit s;
  bool after = false;
  for (std::size_t k = 0; k < b.ops.size(); ++k) {
    const ElementaryOp& op = b.ops[k];
    Eigen::Isometry3d& side = after ? s.after : s.before;
    side = side * elementary(op.kind, param_value(params, op.param));
    if (static_cast<int>(k) == b.joint_op) {
      // q = scale · reading + offset: the offset is a constant motion, folded in before.
      s.before =
          s.before * elementary(op.kind, op.sign * param_value(params, b.encoder_offset_param));
      if (b.encoder_scale_param >= 0) s.scale = params[b.encoder_scale_param];
      s.axis = op.sign * unit_axis(op.kind);
      s.rotation = is_rotation(op.kind);
      after = true;
    }
  }
  return s;
}

// URDF rpy (fixed axes x, y, z: R = Rz(yaw) Ry(pitch) Rx(roll)).
Eigen::Vector3d rpy_of(const Eigen::Matrix3d& R) {
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(2, 1), R(2, 2)));
  if (std::abs(std::cos(pitch)) < 1e-9) {  // gimbal lock: put the whole turn in yaw
    const double yaw = std::atan2(-R(0, 1), R(1, 1));
    return {0.0, pitch, yaw};
  }
  return {std::atan2(R(2, 1), R(2, 2)), pitch, std::atan2(R(1, 0), R(0, 0))};
}

std::string origin_xml(const Eigen::Isometry3d& T) {
  const Eigen::Vector3d p = T.translation(), r = rpy_of(T.linear());
  return fmt::format(R"(<origin xyz="{:.17g} {:.17g} {:.17g}" rpy="{:.17g} {:.17g} {:.17g}"/>)",
                     p.x(), p.y(), p.z(), r.x(), r.y(), r.z());
}

bool is_identity(const Eigen::Isometry3d& T) {
  return T.matrix().isApprox(Eigen::Matrix4d::Identity(), 1e-15);
}

double deg(double rad) {
  return rad * 180.0 / std::numbers::pi;
}

}  // namespace

std::string urdf_mismatch(const Mechanism& model) {
  if (!model.closures.empty())
    return fmt::format(
        "'{}' has closed loops ({} closures: a parallel robot); URDF describes a "
        "tree of links without loops (a serial arm)",
        model.name, model.closures.size());
  for (const Body& b : model.bodies)
    if (b.role == JointRole::kCut || (b.joint != JointType::kFixed && b.actuator < 0))
      return fmt::format(
          "'{}': body '{}' has a joint no controller drives (passive or ball "
          "joint); URDF's joints here are the controller's axes",
          model.name, b.name);
  return "";
}

std::string urdf_text(const Mechanism& model, const Eigen::VectorXd& params,
                      const std::vector<ExtraFrame>& extra) {
  if (const std::string why = urdf_mismatch(model); !why.empty()) throw std::invalid_argument(why);
  std::string links = "  <link name=\"world\"/>\n", joints;
  std::string notes;
  std::vector<std::string> link_names = {"world"};
  std::vector<std::string> defaulted;  // joints given the default velocity/effort
  for (std::size_t i = 0; i < model.bodies.size(); ++i) {
    const Body& b = model.bodies[i];
    const std::string parent =
        b.parent < 0 ? "world" : model.bodies[static_cast<std::size_t>(b.parent)].name;
    links += fmt::format("  <link name=\"{}\"/>\n", b.name);
    link_names.push_back(b.name);
    if (b.joint == JointType::kFixed) {
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      for (const ElementaryOp& op : b.ops)
        T = T * elementary(op.kind, param_value(params, op.param));
      joints += fmt::format(
          "  <joint name=\"{0}\" type=\"fixed\">\n    <parent link=\"{1}\"/>\n    <child "
          "link=\"{0}\"/>\n    {2}\n  </joint>\n",
          b.name, parent, origin_xml(T));
      continue;
    }
    const JointSplit s = split(b, params);
    if (std::abs(s.scale - 1.0) > 1e-12)
      notes += fmt::format(
          "  <!-- joint {}: encoder scale {:.12g} cannot be written in URDF: its "
          "joint value is the joint's own angle/position, reading x scale -->\n",
          b.name, s.scale);
    const bool offset = !is_identity(s.after);
    const std::string moving = offset ? b.name + "_moving" : b.name;
    if (offset) {
      links += fmt::format("  <link name=\"{}\"/>\n", moving);
      link_names.push_back(moving);
    }
    // Speed and force: the robot file's (joint units per second, and the force conjugate to the
    // joint value), in reading units; else the documented defaults (0 would read "cannot move").
    const double abs_scale = std::abs(s.scale) > 0.0 ? std::abs(s.scale) : 1.0;
    double velocity = b.limits.velocity, effort = b.limits.effort;
    if (!(velocity > 0.0) || !(effort > 0.0)) defaulted.push_back(b.name);
    if (!(velocity > 0.0))
      velocity = s.rotation ? kDefaultRevoluteVelocity : kDefaultPrismaticVelocity;
    if (!(effort > 0.0)) effort = s.rotation ? kDefaultRevoluteEffort : kDefaultPrismaticEffort;
    velocity /= abs_scale;
    effort *= abs_scale;
    std::string limit;
    const bool bounded = b.limits.lower > -1e299 && b.limits.upper < 1e299;
    if (bounded) {
      // robocal's limits bound q; URDF's the joint value = the reading (q - offset) / scale.
      const double offset_q = param_value(params, b.encoder_offset_param);
      double lower = (b.limits.lower - offset_q) / s.scale;
      double upper = (b.limits.upper - offset_q) / s.scale;
      if (lower > upper) std::swap(lower, upper);
      limit = fmt::format(
          "\n    <limit lower=\"{:.17g}\" upper=\"{:.17g}\" effort=\"{:.17g}\" "
          "velocity=\"{:.17g}\"/>",
          lower, upper, effort, velocity);
    } else if (s.rotation) {
      // A continuous joint has no position limits; its speed and force still bound it.
      limit =
          fmt::format("\n    <limit effort=\"{:.17g}\" velocity=\"{:.17g}\"/>", effort, velocity);
    } else {
      // URDF requires position limits on a prismatic joint; the file gives none.
      limit = fmt::format(
          "\n    <limit lower=\"-1e9\" upper=\"1e9\" effort=\"{:.17g}\" velocity=\"{:.17g}\"/>",
          effort, velocity);
    }
    joints += fmt::format(
        "  <joint name=\"{0}\" type=\"{1}\">\n    <parent link=\"{2}\"/>\n    <child "
        "link=\"{3}\"/>\n    {4}\n    <axis xyz=\"{5:g} {6:g} {7:g}\"/>{8}\n  </joint>\n",
        b.name, s.rotation ? (bounded ? "revolute" : "continuous") : "prismatic", parent, moving,
        origin_xml(s.before), s.axis.x(), s.axis.y(), s.axis.z(), limit);
    if (offset)
      joints += fmt::format(
          "  <joint name=\"{0}_offset\" type=\"fixed\">\n    <parent link=\"{1}\"/>\n    <child "
          "link=\"{0}\"/>\n    {2}\n  </joint>\n",
          b.name, moving, origin_xml(s.after));
  }
  if (!defaulted.empty()) {
    std::string names;
    for (const auto& n : defaulted) names += (names.empty() ? "" : ", ") + n;
    notes += fmt::format(
        "  <!-- joints {}: the robot file gives no velocity/effort; written: {:g} rad/s and {:g} "
        "N m (revolute), {:g} m/s and {:g} N (prismatic): set your drives' ratings -->\n",
        names, kDefaultRevoluteVelocity, kDefaultRevoluteEffort, kDefaultPrismaticVelocity,
        kDefaultPrismaticEffort);
  }
  for (const ExtraFrame& f : extra) {
    if (std::find(link_names.begin(), link_names.end(), f.name) != link_names.end())
      throw std::invalid_argument(
          fmt::format("'{}': the frame '{}' cannot be added: a link has that name already",
                      model.name, f.name));
    if (f.parent >= static_cast<int>(model.bodies.size()))
      throw std::invalid_argument("urdf_text: an extra frame's parent is not a body");
    link_names.push_back(f.name);
    links += fmt::format("  <link name=\"{}\"/>\n", f.name);
    if (!f.what.empty()) notes += fmt::format("  <!-- link {}: {} -->\n", f.name, f.what);
    joints += fmt::format(
        "  <joint name=\"{0}_mount\" type=\"fixed\">\n    <parent link=\"{1}\"/>\n    <child "
        "link=\"{0}\"/>\n    {2}\n  </joint>\n",
        f.name,
        f.parent < 0 ? std::string("world") : model.bodies[static_cast<std::size_t>(f.parent)].name,
        origin_xml(f.parent_T_frame));
  }
  return fmt::format(
      "<?xml version=\"1.0\"?>\n<!-- robocal: '{0}' (links = robocal's bodies, same frames; "
      "world = the robot file's world frame; tool = link '{1}'; joint values = the controller's "
      "readings) -->\n{2}<robot name=\"{0}\">\n{3}{4}</robot>\n",
      model.name, model.bodies.at(static_cast<std::size_t>(model.tool)).name, notes, links, joints);
}

std::string robot_yaml_from_urdf(const std::string& urdf, const std::string& source) {
  const urdf::ModelInterfaceSharedPtr m = urdf::parseURDF(urdf);
  if (!m) throw core::InputError(source + ": not a valid URDF (urdfdom could not parse it)");
  std::string out = fmt::format(
      "# Imported from {} by robocal (URDF joint origins as xyz_rpy; rpy = URDF's fixed-axis "
      "roll, pitch, yaw)\nrobot: {}\nrotation_order: zyx\nbodies:\n",
      source, m->getName());
  // Depth-first from the root link so parents come before children. The root link is the world
  // frame: the joints hanging from it make robocal's root bodies.
  std::vector<urdf::LinkConstSharedPtr> stack = {m->getRoot()};
  std::string tool;
  while (!stack.empty()) {
    const urdf::LinkConstSharedPtr link = stack.back();
    stack.pop_back();
    for (auto it = link->child_joints.rbegin(); it != link->child_joints.rend(); ++it) {
      const urdf::JointSharedPtr& j = *it;
      std::string type;
      switch (j->type) {
        case urdf::Joint::REVOLUTE:
        case urdf::Joint::CONTINUOUS:
          type = "revolute";
          break;
        case urdf::Joint::PRISMATIC:
          type = "prismatic";
          break;
        case urdf::Joint::FIXED:
          type = "fixed";
          break;
        default:
          throw core::InputError(fmt::format(
              "{}: joint '{}' is planar or floating: robocal's robot model takes revolute, "
              "continuous, prismatic and fixed joints",
              source, j->name));
      }
      const urdf::Pose& o = j->parent_to_joint_origin_transform;
      double roll = 0, pitch = 0, yaw = 0;
      o.rotation.getRPY(roll, pitch, yaw);
      std::string axis;
      if (type != "fixed") {
        const Eigen::Vector3d a(j->axis.x, j->axis.y, j->axis.z);
        for (int k = 0; k < 3 && axis.empty(); ++k)
          for (const double sign : {1.0, -1.0})
            if ((a - sign * Eigen::Vector3d::Unit(k)).norm() < 1e-12)
              axis = std::string(sign < 0 ? "-" : "") + "xyz"[k];
        if (axis.empty())
          throw core::InputError(fmt::format(
              "{}: joint '{}' turns about ({:g}, {:g}, {:g}); robocal's joints move about or "
              "along an axis of their frame (x, y or z): rotate the joint's origin so its axis "
              "is one of them",
              source, j->name, a.x(), a.y(), a.z()));
      }
      // The URDF joint's child link is the robocal body (named after the link).
      out += fmt::format(
          "  - {{name: {}{}, convention: xyz_rpy, joint: {}{}{}, params: {{x: {:.17g}, "
          "y: {:.17g}, z: {:.17g}, roll: {:.17g}, pitch: {:.17g}, yaw: {:.17g}}}{}}}\n",
          j->child_link_name, link == m->getRoot() ? "" : ", parent: " + link->name, type,
          axis.empty() ? "" : ", role: actuated, axis: ", axis, o.position.x, o.position.y,
          o.position.z, roll, pitch, yaw,
          j->limits && j->type != urdf::Joint::CONTINUOUS
              ? fmt::format(", limits: [{:.17g}, {:.17g}]", j->limits->lower, j->limits->upper)
              : std::string());
      tool = j->child_link_name;
    }
    for (auto it = link->child_links.rbegin(); it != link->child_links.rend(); ++it)
      stack.push_back(*it);
  }
  if (!tool.empty()) out += fmt::format("tool: {}\n", tool);
  return out;
}

namespace {

std::string frame_text(const Eigen::Isometry3d& T) {
  // Rounding noise printed as 0 (not -0.000000, which reads like a correction).
  const auto clean = [](Eigen::Vector3d v) {
    for (double& c : v) c = std::abs(c) < 5e-10 ? 0.0 : c;
    return v;
  };
  const Eigen::Vector3d p = clean(T.translation() * 1e3), r = clean(rpy_of(T.linear()));
  return fmt::format("xyz [{:.4f}, {:.4f}, {:.4f}] mm, rpy [{:.6f}, {:.6f}, {:.6f}] deg", p.x(),
                     p.y(), p.z(), deg(r.x()), deg(r.y()), deg(r.z()));
}

std::string dh_row(const std::string& name, bool revolute, double theta, double d, double a,
                   double alpha) {
  const auto clean = [](double v) { return std::abs(v) < 5e-13 ? 0.0 : v; };
  return fmt::format("  {:<16} {:>9} {:>14.6f} {:>12.4f} {:>12.4f} {:>12.6f}\n", name,
                     revolute ? "revolute" : "prismatic", clean(deg(theta)), clean(d * 1e3),
                     clean(a * 1e3), clean(deg(alpha)));
}

// Classic DH frames from the joint axes at readings 0 (common normals between consecutive axes;
// parallel axes: the normal through the previous origin). The joint values are the readings.
std::string derived_dh_table(const Mechanism& model, const Eigen::VectorXd& params,
                             const std::vector<int>& joints) {
  const JointState state = make_joint_state(
      model, params, Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.actuated.size())),
      Eigen::VectorXd());
  std::vector<Eigen::Vector3d> point, axis;
  for (const int j : joints) {
    const Body& b = model.bodies[static_cast<std::size_t>(j)];
    const JointSplit s = split(b, params);
    if (std::abs(s.scale - 1.0) > 1e-12)
      throw std::invalid_argument(fmt::format(
          "'{}': joint '{}' has encoder scale {:.9g}; a DH row's joint value is the reading",
          model.name, b.name, s.scale));
    const Eigen::Isometry3d W = (b.parent >= 0 ? frame_pose(model, params, state, b.parent)
                                               : Eigen::Isometry3d::Identity()) *
                                s.before;
    point.emplace_back(W.translation());
    axis.emplace_back((W.linear() * s.axis).normalized());
  }
  const std::size_t n = joints.size();
  std::vector<Eigen::Vector3d> origin(n), x(n), z(n);
  z[0] = axis[0];
  origin[0] = point[0] + z[0] * z[0].dot(-point[0]);  // the world origin's foot on axis 1
  x[0] = Eigen::Vector3d::UnitX() - z[0] * z[0].x();
  if (x[0].norm() < 1e-6) x[0] = Eigen::Vector3d::UnitY() - z[0] * z[0].y();
  x[0].normalize();
  std::string rows;
  for (std::size_t k = 1; k < n; ++k) {
    const Eigen::Vector3d u = z[k - 1], v = axis[k], w = u.cross(v);
    Eigen::Vector3d foot_prev, foot_next;  // on axis k (line of z[k-1]) and on axis k+1
    if (w.norm() < 1e-9) {
      foot_prev = origin[k - 1];
      foot_next = point[k] + v * v.dot(origin[k - 1] - point[k]);
    } else {
      // Closest points of the lines origin[k-1] + t u and point[k] + s v.
      const Eigen::Vector3d r = origin[k - 1] - point[k];
      const double b = u.dot(v), dn = 1.0 - b * b;
      const double t = (b * v.dot(r) - u.dot(r)) / dn, s2 = (v.dot(r) - b * u.dot(r)) / dn;
      if (std::abs(t) > 10.0 || std::abs(s2) > 10.0)
        throw std::invalid_argument(fmt::format(
            "'{}': the axes of joints '{}' and '{}' are nearly parallel ({:.3g} deg apart): their "
            "common normal lies {:.3g} m away, so a DH table would be ill-conditioned (use the "
            "URDF, or a Hayati/MCPC model)",
            model.name, model.bodies[static_cast<std::size_t>(joints[k - 1])].name,
            model.bodies[static_cast<std::size_t>(joints[k])].name, deg(std::asin(w.norm())),
            std::max(std::abs(t), std::abs(s2))));
      foot_prev = origin[k - 1] + t * u;
      foot_next = point[k] + s2 * v;
    }
    const Eigen::Vector3d normal = foot_next - foot_prev;
    x[k] =
        normal.norm() > 1e-12 ? normal.normalized() : (w.norm() > 1e-9 ? w.normalized() : x[k - 1]);
    z[k] = v;
    origin[k] = foot_next;
    const Eigen::Vector3d step = origin[k] - origin[k - 1];
    const Body& b = model.bodies[static_cast<std::size_t>(joints[k - 1])];
    rows += dh_row(b.name, b.joint == JointType::kRevolute,
                   std::atan2(x[k - 1].cross(x[k]).dot(u), x[k - 1].dot(x[k])), step.dot(u),
                   step.dot(x[k]), std::atan2(u.cross(z[k]).dot(x[k]), u.dot(z[k])));
  }
  // The last joint's frame: its own axis, no offset (the tool frame carries the rest).
  const Body& last = model.bodies[static_cast<std::size_t>(joints.back())];
  rows += dh_row(last.name, last.joint == JointType::kRevolute, 0, 0, 0, 0);
  const auto frame_of = [&](std::size_t k) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear().col(0) = x[k];
    T.linear().col(1) = z[k].cross(x[k]);
    T.linear().col(2) = z[k];
    T.translation() = origin[k];
    return T;
  };
  const Eigen::Isometry3d tool =
      frame_of(n - 1).inverse() * frame_pose(model, params, state, model.tool);
  std::string t = fmt::format(
      "Denavit-Hartenberg table of '{}' derived from its joint axes (its robot file gives them as "
      "{}; A_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i), q_i = the reading)\n",
      model.name, model.bodies[static_cast<std::size_t>(joints.front())].convention);
  t += fmt::format("  {:<16} {:>9} {:>14} {:>12} {:>12} {:>12}\n", "joint", "type", "theta [deg]",
                   "d [mm]", "a [mm]", "alpha [deg]");
  t += rows;
  t += "  base (world -> joint 1's frame): " + frame_text(frame_of(0)) + "\n";
  t += "  tool (last joint's frame -> tool): " + frame_text(tool) + "\n";
  return t;
}

}  // namespace

std::string dh_table_text(const Mechanism& model, const Eigen::VectorXd& params,
                          const std::vector<ExtraFrame>& extra) {
  if (const std::string why = urdf_mismatch(model); !why.empty()) throw std::invalid_argument(why);
  std::string extra_lines;
  for (const ExtraFrame& f : extra)
    extra_lines +=
        fmt::format("  {} ({} -> {}): {}{}\n", f.name,
                    f.parent < 0 ? std::string("world")
                                 : model.bodies.at(static_cast<std::size_t>(f.parent)).name,
                    f.name, frame_text(f.parent_T_frame), f.what.empty() ? "" : "; " + f.what);
  std::string convention;
  std::vector<int> joints;
  for (std::size_t i = 0; i < model.bodies.size(); ++i) {
    const Body& b = model.bodies[i];
    if (b.joint == JointType::kFixed) continue;
    // One DH convention throughout: the table reads the file's numbers; else it is derived.
    convention = convention.empty() || convention == b.convention ? b.convention : "mixed";
    if (!joints.empty() && b.parent != joints.back())
      throw std::invalid_argument(fmt::format(
          "'{}': joint '{}' does not follow joint '{}' directly (fixed frames between joints or "
          "a branch): a DH table is one chain of joints",
          model.name, b.name, model.bodies[static_cast<std::size_t>(joints.back())].name));
    joints.push_back(static_cast<int>(i));
  }
  if (joints.empty()) throw std::invalid_argument("'" + model.name + "' has no moving joints");
  // Joints not given in DH: the table is derived from the joint axes' geometry.
  if (convention != "dh" && convention != "mdh")
    return derived_dh_table(model, params, joints) + extra_lines;
  const auto value = [&](const Body& b, const char* key) {
    const int k = model.parameter_index(b.name + "." + key);
    return k >= 0 ? params[k] : 0.0;
  };
  std::string t =
      fmt::format("{} table of '{}' ({}); theta includes the encoder zero\n",
                  convention == "dh" ? "Denavit-Hartenberg" : "Modified DH (Craig)", model.name,
                  convention == "dh" ? "A_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i)"
                                     : "A_i = Rx(alpha_i) Tx(a_i) Rz(theta_i + q_i) Tz(d_i)");
  t += fmt::format("  {:<16} {:>9} {:>14} {:>12} {:>12} {:>12}\n", "joint", "type", "theta [deg]",
                   "d [mm]", "a [mm]", "alpha [deg]");
  for (const int j : joints) {
    const Body& b = model.bodies[static_cast<std::size_t>(j)];
    const double offset = param_value(params, b.encoder_offset_param);
    const bool revolute = b.joint == JointType::kRevolute;
    t += fmt::format(
        "  {:<16} {:>9} {:>14.6f} {:>12.4f} {:>12.4f} {:>12.6f}{}\n", b.name,
        revolute ? "revolute" : "prismatic", deg(value(b, "theta") + (revolute ? offset : 0.0)),
        (value(b, "d") + (revolute ? 0.0 : offset)) * 1e3, value(b, "a") * 1e3,
        deg(value(b, "alpha")),
        b.encoder_scale_param >= 0 && std::abs(params[b.encoder_scale_param] - 1) > 1e-12
            ? fmt::format("  (encoder scale {:.9g})", params[b.encoder_scale_param])
            : std::string());
  }
  // Base: world -> the first joint's parent frame; tool: last joint frame -> tool.
  JointState zero{Eigen::VectorXd::Zero(static_cast<Eigen::Index>(model.bodies.size()))};
  const Body& first = model.bodies[static_cast<std::size_t>(joints.front())];
  const Eigen::Isometry3d base = first.parent >= 0 ? frame_pose(model, params, zero, first.parent)
                                                   : Eigen::Isometry3d::Identity();
  const Eigen::Isometry3d tool = frame_pose(model, params, zero, joints.back()).inverse() *
                                 frame_pose(model, params, zero, model.tool);
  t += "  base (world -> joint 1's frame): " + frame_text(base) + "\n";
  t += "  tool (last joint's frame -> tool): " + frame_text(tool) + "\n";
  return t + extra_lines;
}

}  // namespace robocal::calib
