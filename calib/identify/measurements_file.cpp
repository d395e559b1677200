#include "robocal/calib/measurements_file.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace robocal::calib {
namespace {

[[noreturn]] void fail(const std::string& source, const YAML::Node& node, const std::string& what) {
  std::string where = source;
  if (node.IsDefined() && node.Mark().line >= 0) where += fmt::format(":{}", node.Mark().line + 1);
  throw MeasurementsFileError(where + ": " + what);
}

void check_keys(const std::string& source, const YAML::Node& map, const std::string& what,
                const std::set<std::string>& allowed) {
  if (!map.IsMap()) fail(source, map, what + " must be a mapping");
  for (const auto& kv : map) {
    if (!allowed.count(kv.first.Scalar())) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      fail(source, kv.first,
           fmt::format("unknown key '{}' in {} (allowed: {})", kv.first.Scalar(), what, list));
    }
  }
}

// Numbers may be written as "nan"/".nan" by a broken exporter: they are parsed (and rejected
// later with the pose named) rather than silently turned into 0.
double number(const std::string& source, const YAML::Node& node, const std::string& what) {
  if (!node.IsDefined() || !node.IsScalar()) fail(source, node, what + " must be a number");
  const std::string& s = node.Scalar();
  if (s == "nan" || s == ".nan" || s == "NaN" || s == ".NaN") return std::nan("");
  try {
    std::size_t used = 0;
    const double v = std::stod(s, &used);
    if (used != s.size()) throw std::invalid_argument(s);
    return v;
  } catch (const std::exception&) {
    fail(source, node, fmt::format("{} must be a number (got '{}')", what, s));
  }
}

Eigen::VectorXd vector(const std::string& source, const YAML::Node& node, const std::string& what,
                       int size = -1) {
  if (!node.IsDefined() || !node.IsSequence())
    fail(source, node, what + " must be a list of numbers");
  if (size >= 0 && static_cast<int>(node.size()) != size)
    fail(source, node, fmt::format("{} must have {} numbers (has {})", what, size, node.size()));
  Eigen::VectorXd v(static_cast<Eigen::Index>(node.size()));
  for (std::size_t i = 0; i < node.size(); ++i)
    v(static_cast<Eigen::Index>(i)) = number(source, node[i], what);
  return v;
}

double positive(const std::string& source, const YAML::Node& node, const std::string& what) {
  const double v = number(source, node, what);
  if (!(v > 0.0)) fail(source, node, what + " must be > 0");
  return v;
}

}  // namespace

MeasurementsFile parse_measurements_yaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw MeasurementsFileError(
        fmt::format("{}:{}: not valid YAML: {}", source, e.mark.line + 1, e.msg));
  }
  if (!root.IsMap()) fail(source, root, "a measurements file must be a YAML mapping");
  check_keys(source, root, "measurements file",
             {"robot", "frame", "units", "noise", "poses", "distances", "description"});
  MeasurementsFile file;
  file.source = source;
  if (root["robot"]) file.robot = root["robot"].Scalar();
  if (root["frame"]) file.frame = root["frame"].Scalar();

  double length_unit = 1.0;  // factor to metres
  double angle_unit = 1.0;   // factor to radians
  if (const YAML::Node u = root["units"]) {
    check_keys(source, u, "units", {"length", "angle"});
    if (u["length"]) {
      const std::string l = u["length"].Scalar();
      if (l == "m")
        length_unit = 1.0;
      else if (l == "mm")
        length_unit = 1e-3;
      else if (l == "um")
        length_unit = 1e-6;
      else
        fail(source, u["length"], "units.length must be m, mm or um");
    }
    if (u["angle"]) {
      const std::string a = u["angle"].Scalar();
      if (a == "rad")
        angle_unit = 1.0;
      else if (a == "deg")
        angle_unit = M_PI / 180.0;
      else
        fail(source, u["angle"], "units.angle must be rad or deg");
    }
  }
  double default_pos_sigma = 0.0;
  double default_rot_sigma = 0.0;
  if (const YAML::Node n = root["noise"]) {
    check_keys(source, n, "noise", {"position_sigma", "rotation_sigma", "actuator_sigma"});
    if (n["position_sigma"])
      default_pos_sigma =
          positive(source, n["position_sigma"], "noise.position_sigma") * length_unit;
    if (n["rotation_sigma"])
      default_rot_sigma =
          positive(source, n["rotation_sigma"], "noise.rotation_sigma") * angle_unit;
    if (n["actuator_sigma"])
      file.actuator_sigma = vector(source, n["actuator_sigma"], "noise.actuator_sigma");
  }
  const YAML::Node poses = root["poses"];
  if (!poses || !poses.IsSequence()) fail(source, root, "missing 'poses' (a list)");
  Eigen::Index actuator_count = -1;
  for (const YAML::Node& p : poses) {
    check_keys(source, p, "pose",
               {"id", "actuators", "point", "point_sigma", "pose", "probe", "comment"});
    PoseMeasurement m;
    if (!p["id"]) fail(source, p, "pose without 'id'");
    m.id = p["id"].Scalar();
    if (!p["actuators"]) fail(source, p, fmt::format("pose '{}' has no 'actuators'", m.id));
    m.actuators = vector(source, p["actuators"], fmt::format("pose '{}' actuators", m.id));
    if (actuator_count >= 0 && m.actuators.size() != actuator_count)
      fail(source, p["actuators"],
           fmt::format("pose '{}' has {} actuator readings, earlier poses have {}", m.id,
                       m.actuators.size(), actuator_count));
    actuator_count = m.actuators.size();
    if (const YAML::Node pt = p["point"]) {
      const double sigma = p["point_sigma"]
                               ? positive(source, p["point_sigma"], "point_sigma") * length_unit
                               : default_pos_sigma;
      if (!(sigma > 0.0))
        fail(source, pt,
             fmt::format("pose '{}': point needs point_sigma or noise.position_sigma", m.id));
      const Eigen::Vector3d x = vector(source, pt, "point", 3) * length_unit;
      PointObservation o;
      o.measured = x;
      o.weight = Eigen::Matrix3d::Identity() / sigma;
      m.observations.push_back(o);
    }
    if (const YAML::Node ps = p["pose"]) {
      check_keys(source, ps, "pose observation",
                 {"position", "rotation_vector", "quaternion", "position_sigma", "rotation_sigma",
                  "covariance"});
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      if (!ps["position"]) fail(source, ps, fmt::format("pose '{}': pose needs 'position'", m.id));
      T.translation() = vector(source, ps["position"], "position", 3) * length_unit;
      if (ps["rotation_vector"] && ps["quaternion"])
        fail(source, ps, "give either rotation_vector or quaternion, not both");
      if (ps["rotation_vector"]) {
        const Eigen::Vector3d w =
            vector(source, ps["rotation_vector"], "rotation_vector", 3) * angle_unit;
        if (w.norm() > 0)
          T.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
      } else if (ps["quaternion"]) {
        const Eigen::VectorXd q = vector(source, ps["quaternion"], "quaternion [w, x, y, z]", 4);
        if (std::abs(q.norm() - 1.0) > 1e-6)
          fail(source, ps["quaternion"],
               fmt::format("quaternion must have unit norm (has {:.9g})", q.norm()));
        T.linear() = Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
      } else {
        fail(source, ps, fmt::format("pose '{}': pose needs rotation_vector or quaternion", m.id));
      }
      Matrix6d cov = Matrix6d::Zero();
      if (ps["covariance"]) {
        const Eigen::VectorXd c =
            vector(source, ps["covariance"], "covariance (36 numbers, row-major, m and rad)", 36);
        for (int i = 0; i < 36; ++i) cov(i / 6, i % 6) = c(i);
      } else {
        const double sp =
            ps["position_sigma"]
                ? positive(source, ps["position_sigma"], "position_sigma") * length_unit
                : default_pos_sigma;
        const double sr =
            ps["rotation_sigma"]
                ? positive(source, ps["rotation_sigma"], "rotation_sigma") * angle_unit
                : default_rot_sigma;
        if (!(sp > 0.0) || !(sr > 0.0))
          fail(source, ps,
               fmt::format("pose '{}': pose needs sigmas (or noise defaults) or covariance", m.id));
        cov.diagonal() << Eigen::Vector3d::Constant(sp * sp), Eigen::Vector3d::Constant(sr * sr);
      }
      try {
        if (!T.matrix().allFinite() || !cov.allFinite()) {
          // Keep it: identify() excludes the pose with a reason naming it.
          PoseObservation o;
          o.measured_position = T.translation();
          o.measured_rotation = T.linear();
          o.weight = Matrix6d::Constant(std::nan(""));
          m.observations.push_back(o);
        } else {
          m.observations.push_back(PoseObservation::with_covariance(T, cov));
        }
      } catch (const std::invalid_argument& e) {
        fail(source, ps, fmt::format("pose '{}': covariance {}", m.id, e.what()));
      }
    }
    if (const YAML::Node pr = p["probe"]) {
      check_keys(source, pr, "probe", {"height", "normal", "offset", "sigma"});
      ProbeHeightObservation o;
      if (!pr["height"]) fail(source, pr, "probe needs 'height'");
      o.measured_height = number(source, pr["height"], "probe height") * length_unit;
      if (pr["normal"]) {
        o.normal = vector(source, pr["normal"], "probe normal", 3);
        if (!(o.normal.norm() > 0)) fail(source, pr["normal"], "probe normal must not be zero");
        o.normal.normalize();
      }
      if (pr["offset"]) o.offset = number(source, pr["offset"], "probe offset") * length_unit;
      o.sigma = pr["sigma"] ? positive(source, pr["sigma"], "probe sigma") * length_unit
                            : default_pos_sigma;
      if (!(o.sigma > 0.0)) fail(source, pr, "probe needs 'sigma' (or noise.position_sigma)");
      m.observations.push_back(o);
    }
    if (m.observations.empty())
      fail(source, p, fmt::format("pose '{}' has no observation (point, pose or probe)", m.id));
    file.measurements.poses.push_back(std::move(m));
  }
  if (const YAML::Node ds = root["distances"]) {
    if (!ds.IsSequence()) fail(source, ds, "distances must be a list");
    for (const YAML::Node& d : ds) {
      check_keys(source, d, "distance", {"a", "b", "distance", "sigma"});
      if (!d["a"] || !d["b"] || !d["distance"])
        fail(source, d, "a distance needs 'a', 'b' (pose ids) and 'distance'");
      DistanceMeasurement dm;
      dm.first = d["a"].Scalar();
      dm.second = d["b"].Scalar();
      dm.observation.measured_distance = number(source, d["distance"], "distance") * length_unit;
      dm.observation.sigma = d["sigma"]
                                 ? positive(source, d["sigma"], "distance sigma") * length_unit
                                 : default_pos_sigma;
      if (!(dm.observation.sigma > 0.0))
        fail(source, d, "distance needs 'sigma' (or noise.position_sigma)");
      file.measurements.distances.push_back(dm);
    }
  }
  return file;
}

MeasurementsFile load_measurements_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw MeasurementsFileError(fmt::format("{}: cannot open the measurements file", path));
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_measurements_yaml(ss.str(), path);
}

namespace {
YAML::Node seq(const Eigen::VectorXd& v) {
  YAML::Node n(YAML::NodeType::Sequence);
  for (Eigen::Index i = 0; i < v.size(); ++i) n.push_back(fmt::format("{:.17g}", v(i)));
  n.SetStyle(YAML::EmitterStyle::Flow);
  return n;
}
}  // namespace

std::string measurements_to_yaml(const MeasurementsFile& file) {
  YAML::Node root;
  if (!file.robot.empty()) root["robot"] = file.robot;
  if (!file.frame.empty()) root["frame"] = file.frame;
  root["units"]["length"] = "m";
  root["units"]["angle"] = "rad";
  if (file.actuator_sigma.size() > 0) root["noise"]["actuator_sigma"] = seq(file.actuator_sigma);
  for (const auto& m : file.measurements.poses) {
    YAML::Node p;
    p["id"] = m.id;
    p["actuators"] = seq(m.actuators);
    for (const auto& obs : m.observations) {
      if (const auto* pt = std::get_if<PointObservation>(&obs)) {
        p["point"] = seq(pt->measured);
        p["point_sigma"] = fmt::format("{:.17g}", 1.0 / pt->weight(0, 0));
      } else if (const auto* po = std::get_if<PoseObservation>(&obs)) {
        p["pose"]["position"] = seq(po->measured_position);
        const Eigen::AngleAxisd aa(po->measured_rotation);
        p["pose"]["rotation_vector"] = seq(aa.axis() * aa.angle());
        const Matrix6d info = po->weight.transpose() * po->weight;
        const Matrix6d cov = info.inverse();
        Eigen::VectorXd flat(36);
        for (int i = 0; i < 36; ++i) flat(i) = cov(i / 6, i % 6);
        p["pose"]["covariance"] = seq(flat);
      } else if (const auto* pr = std::get_if<ProbeHeightObservation>(&obs)) {
        p["probe"]["height"] = fmt::format("{:.17g}", pr->measured_height);
        p["probe"]["normal"] = seq(pr->normal);
        p["probe"]["offset"] = fmt::format("{:.17g}", pr->offset);
        p["probe"]["sigma"] = fmt::format("{:.17g}", pr->sigma);
      }
    }
    root["poses"].push_back(p);
  }
  for (const auto& d : file.measurements.distances) {
    YAML::Node n;
    n["a"] = d.first;
    n["b"] = d.second;
    n["distance"] = fmt::format("{:.17g}", d.observation.measured_distance);
    n["sigma"] = fmt::format("{:.17g}", d.observation.sigma);
    root["distances"].push_back(n);
  }
  YAML::Emitter out;
  out << root;
  return std::string("# robocal measurements (format: testdata/measurements/README.md)\n") +
         out.c_str() + "\n";
}

void save_measurements_file(const MeasurementsFile& file, const std::string& path) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw MeasurementsFileError(fmt::format("{}: cannot write", path));
    out << measurements_to_yaml(file);
  }
  std::filesystem::rename(tmp, path);
}

}  // namespace robocal::calib
