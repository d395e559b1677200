// YAML values of a robot file, read with errors that name file, line and problem.
#include "robot_file_parse.hpp"

#include "robocal/calib/robot_file.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace robocal::calib::robot_yaml {

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

}  // namespace robocal::calib::robot_yaml
