// Cell files (YAML) -> Cell. Every error names the file and the line of the offending node.
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/errors.hpp"
#include "robocal/vision/target_io.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>

namespace robocal::planner {
namespace {

namespace fs = std::filesystem;

// Why an angle of `value` "radians" is likely degrees, and what to write instead.
std::string degrees_for_radians(const std::string& what, double value) {
  std::ostringstream msg;
  msg << what << " value " << value
      << " is beyond ±2π rad: likely degrees written where the cell file takes radians (write deg("
      << value << "))";
  return msg.str();
}

// Reading context: the file name for messages, the folder relative names resolve against, and
// the length unit of the file.
struct Reader {
  std::string source;
  std::string base_dir;
  double length_unit = 1.0;  // metres per file length unit

  [[noreturn]] void fail(const YAML::Node& node, const std::string& what) const {
    throw CellFileError(core::yaml_where(source, node) + ": " + what);
  }
  static int line(const YAML::Node& node) {
    return node.IsDefined() && node.Mark().line >= 0 ? node.Mark().line + 1 : 0;
  }
  // A number or an expression (same syntax as robot files: deg(30), 0.2*sqrt(3), ...).
  double number(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) fail(node, what + " must be a number or an expression");
    double v = 0.0;
    try {
      v = calib::evaluate_expression(node.Scalar());
    } catch (const std::invalid_argument& e) {
      fail(node, what + ": " + e.what());
    }
    if (!std::isfinite(v)) fail(node, what + " must be finite");
    return v;
  }
  double length(const YAML::Node& node, const std::string& what) const {
    return number(node, what) * length_unit;
  }
  Eigen::Vector3d vec3(const YAML::Node& node, const std::string& what, double unit) const {
    if (!node.IsSequence() || node.size() != 3) fail(node, what + " must be a list of 3 numbers");
    return {number(node[0], what) * unit, number(node[1], what) * unit,
            number(node[2], what) * unit};
  }
  // Roll, pitch, yaw in radians. A value beyond ±2π is degrees taken for radians: the file
  // loads, but every camera or obstacle so turned points elsewhere than drawn.
  Eigen::Vector3d rpy(const YAML::Node& node, const std::string& what) const {
    Eigen::Vector3d v = vec3(node, what, 1.0);
    constexpr double kMaxAngle = 2.0 * std::numbers::pi + 0.01;
    for (int i = 0; i < 3; ++i)
      if (std::abs(v[i]) > kMaxAngle) fail(node[i], degrees_for_radians(what, v[i]));
    return v;
  }
  Eigen::Vector3d point(const YAML::Node& node, const std::string& what) const {
    return vec3(node, what, length_unit);
  }
  YAML::Node require(const YAML::Node& map, const std::string& key,
                     const std::string& where) const {
    if (!map.IsMap()) fail(map, where + " must be a map");
    const YAML::Node n = map[key];
    if (!n) fail(map, where + ": missing required key '" + key + "'");
    return n;
  }
  void known_keys(const YAML::Node& map, const std::vector<std::string>& known,
                  const std::string& where) const {
    if (!map.IsMap()) fail(map, where + " must be a map");
    for (const auto& kv : map) {
      const std::string key = kv.first.Scalar();
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
        std::string msg = where;
        msg.append(": unknown key '").append(key).append("' (known: ").append(list).append(")");
        fail(kv.first, msg);
      }
    }
  }
  std::string text(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar()) fail(node, what + " must be a string");
    return node.Scalar();
  }
  std::string resolve(const std::string& name) const {
    const fs::path p(name);
    if (p.is_absolute() || base_dir.empty()) return p.string();
    return (fs::path(base_dir) / p).lexically_normal().string();
  }
};

// R = Rz(yaw) Ry(pitch) Rx(roll), as the robot files' collision boxes.
Eigen::Matrix3d rpy_rotation(const Eigen::Vector3d& rpy) {
  return (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// world_T_camera looking from `eye` at `at`, image "up" (-y) as close as possible to `up`.
Eigen::Isometry3d look_at_pose(const Reader& r, const YAML::Node& node, const Eigen::Vector3d& eye,
                               const Eigen::Vector3d& at, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = at - eye;
  if (z.norm() < 1e-9) r.fail(node, "camera pose: look_at equals position");
  const Eigen::Vector3d zn = z.normalized();
  // Camera y points down in the image, so -y should follow `up`: x = y × z = (-up) × z.
  Eigen::Vector3d x = (-up).cross(zn);
  if (x.norm() < 1e-6) r.fail(node, "camera pose: 'up' is parallel to the viewing direction");
  x.normalize();
  const Eigen::Vector3d y = zn.cross(x);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = zn;
  T.translation() = eye;
  return T;
}

Eigen::Isometry3d read_pose(const Reader& r, const YAML::Node& node, const std::string& where,
                            bool allow_look_at) {
  std::vector<std::string> keys = {"position", "rpy"};
  if (allow_look_at) keys.insert(keys.end(), {"look_at", "up", "uncertainty"});
  r.known_keys(node, keys, where);
  const Eigen::Vector3d p = r.point(r.require(node, "position", where), where + ".position");
  if (allow_look_at && node["look_at"]) {
    if (node["rpy"]) r.fail(node, where + ": give either 'look_at' or 'rpy', not both");
    const Eigen::Vector3d at = r.point(node["look_at"], where + ".look_at");
    // Default image "up": world z, or world y for a camera looking (nearly) straight up/down.
    Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
    if (node["up"])
      up = r.vec3(node["up"], where + ".up", 1.0);
    else if (std::abs((at - p).normalized().z()) > 0.99)
      up = Eigen::Vector3d::UnitY();
    return look_at_pose(r, node, p, at, up);
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = p;
  if (node["rpy"]) T.linear() = rpy_rotation(r.rpy(node["rpy"], where + ".rpy"));
  return T;
}

CellCamera read_camera(const Reader& r, const YAML::Node& node, std::size_t index) {
  const std::string where = "cameras[" + std::to_string(index) + "]";
  r.known_keys(node, {"name", "file", "pose", "roughly"}, where);
  CellCamera cam;
  cam.line = Reader::line(node);
  cam.name =
      node["name"] ? r.text(node["name"], where + ".name") : "camera" + std::to_string(index);
  const YAML::Node file = r.require(node, "file", where);
  cam.file = r.resolve(r.text(file, where + ".file"));
  if (!fs::exists(cam.file))
    r.fail(file, "camera '" + cam.name + "': camera file '" + cam.file +
                     "' does not exist (calibrate the camera first: robocal intrinsics, or give "
                     "the path of its camera file)");
  try {
    cam.model = vision::load_camera_file(cam.file);
  } catch (const std::exception& e) {
    r.fail(file, "camera '" + cam.name + "': " + e.what());
  }
  const YAML::Node pose = r.require(node, "pose", where);
  if (pose.IsScalar() && pose.Scalar() == "unknown") {
    cam.pose_known = false;
    const YAML::Node rough = node["roughly"];
    if (!rough)
      r.fail(pose, "camera '" + cam.name +
                       "': pose 'unknown' needs 'roughly: {position: [...], look_at: [...], "
                       "uncertainty: m}' (where it is, give or take)");
    cam.world_T_camera = read_pose(r, rough, where + ".roughly", true);
    cam.pose_uncertainty =
        rough["uncertainty"] ? r.length(rough["uncertainty"], where + ".roughly.uncertainty") : 0.1;
    if (cam.pose_uncertainty < 0)
      r.fail(rough["uncertainty"], where + ".roughly.uncertainty must be >= 0");
  } else {
    if (node["roughly"]) r.fail(node["roughly"], where + ": 'roughly' goes with 'pose: unknown'");
    if (pose.IsMap() && pose["uncertainty"])
      r.fail(pose["uncertainty"], where + ".pose: 'uncertainty' goes with 'pose: unknown'");
    if (!pose.IsMap())
      r.fail(pose, where + ".pose must be a map {position, look_at | rpy} or 'unknown'");
    cam.world_T_camera = read_pose(r, pose, where + ".pose", true);
  }
  return cam;
}

Obstacle read_obstacle(const Reader& r, const YAML::Node& node, std::size_t index) {
  const std::string where = "obstacles[" + std::to_string(index) + "]";
  r.known_keys(node, {"name", "box", "cylinder", "sphere", "mesh"}, where);
  Obstacle ob;
  ob.line = Reader::line(node);
  ob.name =
      node["name"] ? r.text(node["name"], where + ".name") : "obstacle" + std::to_string(index);
  int shapes = 0;
  for (const char* k : {"box", "cylinder", "sphere", "mesh"}) shapes += node[k] ? 1 : 0;
  if (shapes != 1)
    r.fail(node, where + " ('" + ob.name + "') needs exactly one of box, cylinder, sphere, mesh");
  auto placement = [&](const YAML::Node& s, const std::string& key) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = r.point(r.require(s, key, where), where + "." + key);
    if (s["rpy"]) T.linear() = rpy_rotation(r.rpy(s["rpy"], where + ".rpy"));
    return T;
  };
  auto positive = [&](const YAML::Node& n, const std::string& what) {
    const double v = r.length(n, what);
    if (v <= 0) r.fail(n, what + " must be > 0");
    return v;
  };
  if (node["box"]) {
    const YAML::Node s = node["box"];
    r.known_keys(s, {"center", "size", "rpy"}, where + ".box");
    ob.kind = ObstacleKind::kBox;
    ob.world_T_obstacle = placement(s, "center");
    const YAML::Node size = r.require(s, "size", where + ".box");
    ob.size = r.point(size, where + ".box.size");
    if ((ob.size.array() <= 0).any()) r.fail(size, where + ".box.size: every edge must be > 0");
  } else if (node["cylinder"]) {
    const YAML::Node s = node["cylinder"];
    r.known_keys(s, {"center", "radius", "length", "rpy"}, where + ".cylinder");
    ob.kind = ObstacleKind::kCylinder;
    ob.world_T_obstacle = placement(s, "center");
    ob.radius = positive(r.require(s, "radius", where), where + ".cylinder.radius");
    ob.length = positive(r.require(s, "length", where), where + ".cylinder.length");
  } else if (node["sphere"]) {
    const YAML::Node s = node["sphere"];
    r.known_keys(s, {"center", "radius"}, where + ".sphere");
    ob.kind = ObstacleKind::kSphere;
    ob.world_T_obstacle = placement(s, "center");
    ob.radius = positive(r.require(s, "radius", where), where + ".sphere.radius");
  } else if (node["mesh"]) {
    const YAML::Node s = node["mesh"];
    r.known_keys(s, {"file", "scale", "position", "rpy"}, where + ".mesh");
    ob.kind = ObstacleKind::kMesh;
    const YAML::Node f = r.require(s, "file", where + ".mesh");
    ob.mesh_file = r.resolve(r.text(f, where + ".mesh.file"));
    // STL files carry no unit: `scale` converts the file's numbers to the cell's length unit.
    const double scale = s["scale"] ? r.number(s["scale"], where + ".mesh.scale") : 1.0;
    if (scale <= 0) r.fail(s["scale"], where + ".mesh.scale must be > 0");
    if (!fs::exists(ob.mesh_file)) r.fail(f, "mesh file '" + ob.mesh_file + "' does not exist");
    try {
      read_stl(ob.mesh_file, scale * r.length_unit, ob.vertices, ob.triangles);
    } catch (const CellFileError& e) {
      r.fail(f, e.what());
    }
    ob.world_T_obstacle = Eigen::Isometry3d::Identity();
    if (s["position"])
      ob.world_T_obstacle.translation() = r.point(s["position"], where + ".mesh.position");
    if (s["rpy"]) ob.world_T_obstacle.linear() = rpy_rotation(r.rpy(s["rpy"], where + ".rpy"));
  }
  return ob;
}

void read_margins(const Reader& r, const YAML::Node& node, Margins& m) {
  r.known_keys(node,
               {"clearance", "self_clearance", "joint_limit", "joint_limit_length", "image_border"},
               "margins");
  auto nonneg = [&](const char* key, double unit, double& out) {
    if (!node[key]) return;
    out = r.number(node[key], std::string("margins.") + key) * unit;
    if (out < 0) r.fail(node[key], std::string("margins.") + key + " must be >= 0");
  };
  nonneg("clearance", r.length_unit, m.clearance);
  nonneg("self_clearance", r.length_unit, m.self_clearance);
  nonneg("joint_limit", 1.0, m.joint_limit_angle);
  nonneg("joint_limit_length", r.length_unit, m.joint_limit_length);
  nonneg("image_border", 1.0, m.image_border);
  if (m.joint_limit_angle > 0.5)
    r.fail(node["joint_limit"], "margins.joint_limit is in radians (use deg(2) for 2 degrees); " +
                                    std::to_string(m.joint_limit_angle) +
                                    " rad is more than the margin of any joint");
}

void read_target(const Reader& r, const YAML::Node& node, TargetMount& t) {
  r.known_keys(node, {"file", "frame", "position", "rpy"}, "target");
  t.line = Reader::line(node);
  const YAML::Node f = r.require(node, "file", "target");
  t.file = r.resolve(r.text(f, "target.file"));
  if (!fs::exists(t.file)) r.fail(f, "target file '" + t.file + "' does not exist");
  try {
    t.board = vision::load_target_file(t.file);
  } catch (const std::exception& e) {
    r.fail(f, std::string("target: ") + e.what());
  }
  if (node["frame"]) t.frame = r.text(node["frame"], "target.frame");
  t.frame_T_board = Eigen::Isometry3d::Identity();
  if (node["position"])
    t.frame_T_board.translation() = r.point(node["position"], "target.position");
  if (node["rpy"]) t.frame_T_board.linear() = rpy_rotation(r.rpy(node["rpy"], "target.rpy"));
}

void read_visibility(const Reader& r, const YAML::Node& node, VisibilityRequirements& v) {
  r.known_keys(node, {"cameras", "min_cameras", "max_incidence", "min_image_size", "corners"},
               "visibility");
  if (const YAML::Node c = node["cameras"]) {
    if (!c.IsSequence()) r.fail(c, "visibility.cameras must be a list of camera names");
    for (const YAML::Node& n : c) v.cameras.push_back(r.text(n, "visibility.cameras"));
  }
  if (node["min_cameras"]) {
    const double n = r.number(node["min_cameras"], "visibility.min_cameras");
    if (n < 1 || n != std::floor(n))
      r.fail(node["min_cameras"], "visibility.min_cameras must be a whole number >= 1");
    v.min_cameras = static_cast<int>(n);
  }
  if (node["max_incidence"]) {
    v.max_incidence = r.number(node["max_incidence"], "visibility.max_incidence");
    if (v.max_incidence <= 0 || v.max_incidence > M_PI / 2)
      r.fail(node["max_incidence"],
             "visibility.max_incidence must be in (0, pi/2] radians (e.g. deg(60))");
  }
  if (node["min_image_size"]) {
    v.min_image_size = r.number(node["min_image_size"], "visibility.min_image_size");
    if (v.min_image_size < 0)
      r.fail(node["min_image_size"], "visibility.min_image_size must be >= 0 px");
  }
  if (node["corners"]) {
    const std::string c = r.text(node["corners"], "visibility.corners");
    if (c == "all")
      v.corners = RequiredCorners::kAll;
    else if (c == "outline")
      v.corners = RequiredCorners::kOutline;
    else
      r.fail(node["corners"], "visibility.corners must be 'all' or 'outline'");
  }
}

}  // namespace

int Cell::camera_index(const std::string& camera_name) const {
  for (std::size_t i = 0; i < cameras.size(); ++i)
    if (cameras[i].name == camera_name) return static_cast<int>(i);
  return -1;
}

int Cell::cameras_needed() const {
  const int required = static_cast<int>(required_cameras().size());
  return visibility.min_cameras > 0 ? std::min(visibility.min_cameras, required) : required;
}

std::vector<int> Cell::required_cameras() const {
  std::vector<int> out;
  if (visibility.cameras.empty()) {
    for (std::size_t i = 0; i < cameras.size(); ++i) out.push_back(static_cast<int>(i));
  } else {
    for (const std::string& n : visibility.cameras) out.push_back(camera_index(n));
  }
  return out;
}

Cell parse_cell_yaml(const std::string& text, const std::string& source,
                     const std::string& base_dir) {
  Reader r{source, base_dir, 1.0};
  const YAML::Node root = core::load_yaml_text(text, source);
  if (!root.IsMap())
    throw CellFileError(source + ": a cell file is a YAML map (see planner/README.md)");
  r.known_keys(root,
               {"cell", "units", "robot", "cameras", "obstacles", "workspace", "margins", "target",
                "visibility"},
               "cell file");
  Cell cell;
  cell.source = source;
  cell.name = root["cell"] ? r.text(root["cell"], "cell") : fs::path(source).stem().string();
  if (const YAML::Node u = root["units"]) {
    const std::string unit = r.text(u, "units");
    if (unit == "m")
      r.length_unit = 1.0;
    else if (unit == "mm")
      r.length_unit = 1e-3;
    else
      r.fail(u, "units must be 'm' or 'mm' (angles are always radians; write deg(30))");
  }
  if (root["robot"]) cell.robot_file = r.resolve(r.text(root["robot"], "robot"));

  const YAML::Node cams = r.require(root, "cameras", "cell file");
  if (!cams.IsSequence() || cams.size() == 0)
    r.fail(cams, "cameras must be a non-empty list (each: name, file, pose)");
  for (std::size_t i = 0; i < cams.size(); ++i) {
    CellCamera cam = read_camera(r, cams[i], i);
    if (cell.camera_index(cam.name) >= 0)
      r.fail(cams[i], "duplicate camera name '" + cam.name + "'");
    cell.cameras.push_back(std::move(cam));
  }
  if (const YAML::Node obs = root["obstacles"]) {
    if (!obs.IsSequence()) r.fail(obs, "obstacles must be a list");
    for (std::size_t i = 0; i < obs.size(); ++i)
      cell.obstacles.push_back(read_obstacle(r, obs[i], i));
  }
  if (const YAML::Node ws = root["workspace"]) {
    r.known_keys(ws, {"min", "max"}, "workspace");
    cell.workspace.declared = true;
    cell.workspace.line = Reader::line(ws);
    cell.workspace.min = r.point(r.require(ws, "min", "workspace"), "workspace.min");
    cell.workspace.max = r.point(r.require(ws, "max", "workspace"), "workspace.max");
    if ((cell.workspace.max.array() <= cell.workspace.min.array()).any())
      r.fail(ws, "workspace: every max coordinate must exceed min");
  }
  if (const YAML::Node m = root["margins"]) read_margins(r, m, cell.margins);
  read_target(r, r.require(root, "target", "cell file"), cell.target);
  if (const YAML::Node v = root["visibility"]) {
    read_visibility(r, v, cell.visibility);
    for (const std::string& cam_name : cell.visibility.cameras)
      if (cell.camera_index(cam_name) < 0)
        r.fail(v["cameras"],
               "visibility.cameras names '" + cam_name + "', which is not a camera of this cell");
    const auto required = static_cast<int>(cell.required_cameras().size());
    if (cell.visibility.min_cameras > required)
      r.fail(v["min_cameras"], "visibility.min_cameras is " +
                                   std::to_string(cell.visibility.min_cameras) + " but only " +
                                   std::to_string(required) +
                                   " camera(s) may see the target (visibility.cameras, or every "
                                   "camera of the cell)");
  }
  return cell;
}

Cell load_cell_file(const std::string& path) {
  return parse_cell_yaml(core::read_text_file(path), path, fs::path(path).parent_path().string());
}

void read_stl(const std::string& path, double scale, std::vector<Eigen::Vector3d>& vertices,
              std::vector<Eigen::Vector3i>& triangles) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CellFileError(path + ": cannot open the mesh file");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  const std::string data = buffer.str();
  vertices.clear();
  triangles.clear();
  // Binary STL: 80-byte header, uint32 count, 50 bytes per facet. ASCII files start with "solid"
  // but so do some binary ones; the size test decides.
  if (data.size() >= 84) {
    std::uint32_t n = 0;
    std::memcpy(&n, data.data() + 80, 4);
    if (data.size() == 84 + static_cast<std::size_t>(n) * 50) {
      for (std::uint32_t f = 0; f < n; ++f) {
        const char* rec = data.data() + 84 + static_cast<std::size_t>(f) * 50 + 12;
        const int base = static_cast<int>(vertices.size());
        for (int k = 0; k < 3; ++k) {
          std::array<float, 3> xyz{};
          std::memcpy(xyz.data(), rec + static_cast<std::ptrdiff_t>(k) * 12, 12);
          vertices.emplace_back(scale * xyz[0], scale * xyz[1], scale * xyz[2]);
        }
        triangles.emplace_back(base, base + 1, base + 2);
      }
      if (triangles.empty()) throw CellFileError(path + ": the mesh has no triangles");
      return;
    }
  }
  std::istringstream text(data);
  std::string word;
  int in_facet = 0;
  while (text >> word) {
    if (word == "vertex") {
      double x = 0, y = 0, z = 0;
      if (!(text >> x >> y >> z))
        throw CellFileError(path + ": malformed 'vertex' line in ASCII STL");
      vertices.emplace_back(scale * x, scale * y, scale * z);
      if (++in_facet == 3) {
        const int base = static_cast<int>(vertices.size()) - 3;
        triangles.emplace_back(base, base + 1, base + 2);
        in_facet = 0;
      }
    }
  }
  if (triangles.empty())
    throw CellFileError(path + ": not an STL mesh (no triangles found, ASCII or binary)");
}

std::vector<Eigen::Vector3d> board_outline(const vision::TargetBoard& board) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = Eigen::Vector2d::Constant(-1e300);
  for (const vision::TargetCorner& c : board.corners) {
    lo = lo.cwiseMin(c.point.head<2>());
    hi = hi.cwiseMax(c.point.head<2>());
  }
  return {{lo.x(), lo.y(), 0}, {hi.x(), lo.y(), 0}, {hi.x(), hi.y(), 0}, {lo.x(), hi.y(), 0}};
}

std::vector<Eigen::Vector3d> required_corner_points(const vision::TargetBoard& board,
                                                    RequiredCorners which) {
  if (which == RequiredCorners::kOutline) return board_outline(board);
  std::vector<Eigen::Vector3d> out;
  out.reserve(board.corners.size());
  for (const vision::TargetCorner& c : board.corners) out.push_back(c.point);
  return out;
}

}  // namespace robocal::planner
