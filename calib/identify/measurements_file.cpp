#include "robocal/calib/measurements_file.hpp"

#include "robocal/core/files.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
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

// Orientation from `rotation_vector` or `quaternion` [w, x, y, z] (one of them required).
Eigen::Matrix3d rotation(const std::string& source, const YAML::Node& map, const std::string& what,
                         double angle_unit) {
  if (map["rotation_vector"] && map["quaternion"])
    fail(source, map, what + ": give either rotation_vector or quaternion, not both");
  if (map["rotation_vector"]) {
    const Eigen::Vector3d w =
        vector(source, map["rotation_vector"], what + " rotation_vector", 3) * angle_unit;
    return w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix()
                        : Eigen::Matrix3d::Identity();
  }
  if (map["quaternion"]) {
    const Eigen::VectorXd q =
        vector(source, map["quaternion"], what + " quaternion [w, x, y, z]", 4);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      fail(source, map["quaternion"],
           fmt::format("{}: quaternion must have unit norm (has {:.9g})", what, q.norm()));
    return Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
  }
  fail(source, map, what + " needs rotation_vector or quaternion");
}

// `cameras:` list → ObservingCamera (intrinsics in pixels, pose in the file's units).
std::vector<ObservingCamera> parse_cameras(const std::string& source, const YAML::Node& list,
                                           double length_unit, double angle_unit) {
  if (!list.IsSequence() || list.size() == 0)
    fail(source, list, "cameras must be a non-empty list");
  std::vector<ObservingCamera> cameras;
  std::set<std::string> names;
  for (const YAML::Node& c : list) {
    check_keys(source, c, "camera",
               {"name", "model", "size", "params", "position", "rotation_vector", "quaternion"});
    ObservingCamera cam;
    if (!c["name"] || c["name"].Scalar().empty()) fail(source, c, "camera without 'name'");
    cam.name = c["name"].Scalar();
    if (!names.insert(cam.name).second)
      fail(source, c["name"], fmt::format("camera '{}' appears more than once", cam.name));
    const std::string what = fmt::format("camera '{}'", cam.name);
    if (!c["model"]) fail(source, c, what + " needs 'model'");
    const auto kind = vision::kind_from_name(c["model"].Scalar());
    if (!kind)
      fail(source, c["model"],
           fmt::format("{}: unknown model '{}' (pinhole_radtan, pinhole_rational, fisheye_kb4)",
                       what, c["model"].Scalar()));
    cam.model.kind = *kind;
    if (!c["size"]) fail(source, c, what + " needs 'size: [width, height]'");
    const Eigen::VectorXd size = vector(source, c["size"], what + " size", 2);
    cam.model.width = static_cast<int>(size(0));
    cam.model.height = static_cast<int>(size(1));
    if (!c["params"]) fail(source, c, what + " needs 'params'");
    const Eigen::VectorXd prm =
        vector(source, c["params"], what + " params", vision::num_params(*kind));
    cam.model.params.assign(prm.data(), prm.data() + prm.size());
    const std::string problem = vision::validate_camera(cam.model);
    if (!problem.empty()) fail(source, c, fmt::format("{}: {}", what, problem));
    if (!c["position"]) fail(source, c, what + " needs 'position' (its centre in the world)");
    cam.world_T_camera.translation() =
        vector(source, c["position"], what + " position", 3) * length_unit;
    cam.world_T_camera.linear() = rotation(source, c, what, angle_unit);
    cameras.push_back(std::move(cam));
  }
  return cameras;
}

// Factors to metres and radians (the file's `units`).
struct Units {
  double length = 1.0;
  double angle = 1.0;
};

Units parse_units(const std::string& source, const YAML::Node& root) {
  Units units;
  if (const YAML::Node u = root["units"]) {
    check_keys(source, u, "units", {"length", "angle"});
    if (u["length"]) {
      const std::string l = u["length"].Scalar();
      if (l == "m")
        units.length = 1.0;
      else if (l == "mm")
        units.length = 1e-3;
      else if (l == "um")
        units.length = 1e-6;
      else
        fail(source, u["length"], "units.length must be m, mm or um");
    }
    if (u["angle"]) {
      const std::string a = u["angle"].Scalar();
      if (a == "rad")
        units.angle = 1.0;
      else if (a == "deg")
        units.angle = M_PI / 180.0;
      else
        fail(source, u["angle"], "units.angle must be rad or deg");
    }
  }
  return units;
}

// The file's `noise`: sigmas for observations that state none (0: none given).
struct NoiseDefaults {
  double position = 0.0;
  double rotation = 0.0;
  double pixel = 0.0;
};

NoiseDefaults parse_noise(const std::string& source, const YAML::Node& root, const Units& units,
                          MeasurementsFile& file) {
  NoiseDefaults noise;
  if (const YAML::Node n = root["noise"]) {
    check_keys(source, n, "noise",
               {"position_sigma", "rotation_sigma", "actuator_sigma", "pixel_sigma"});
    if (n["position_sigma"])
      noise.position = positive(source, n["position_sigma"], "noise.position_sigma") * units.length;
    if (n["rotation_sigma"])
      noise.rotation = positive(source, n["rotation_sigma"], "noise.rotation_sigma") * units.angle;
    if (n["actuator_sigma"])
      file.actuator_sigma = vector(source, n["actuator_sigma"], "noise.actuator_sigma");
    if (n["pixel_sigma"]) noise.pixel = positive(source, n["pixel_sigma"], "noise.pixel_sigma");
  }
  return noise;
}

// The file's `target`: corner id -> point in the measured frame.
std::map<int, Eigen::Vector3d> parse_target(const std::string& source, const YAML::Node& root,
                                            const Units& units) {
  std::map<int, Eigen::Vector3d> target;
  if (const YAML::Node t = root["target"]) {
    if (!t.IsSequence()) fail(source, t, "target must be a list of {id, point}");
    for (const YAML::Node& c : t) {
      check_keys(source, c, "target corner", {"id", "point"});
      if (!c["id"] || !c["point"]) fail(source, c, "a target corner needs 'id' and 'point'");
      const int id = static_cast<int>(number(source, c["id"], "target corner id"));
      if (!target.emplace(id, vector(source, c["point"], "target corner point", 3) * units.length)
               .second)
        fail(source, c["id"], fmt::format("target corner {} appears more than once", id));
    }
  }
  return target;
}

// A pose observation's orientation: exactly one of rpy, quaternion_xyzw, matrix (whose 4x4 form's
// translation must agree with `translation`), rotation_vector or quaternion.
Eigen::Matrix3d pose_rotation(const std::string& source, const YAML::Node& ps,
                              const std::string& id, const Eigen::Vector3d& translation,
                              const Units& units) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = translation;
  if ((ps["rotation_vector"] ? 1 : 0) + (ps["quaternion"] ? 1 : 0) +
          (ps["quaternion_xyzw"] ? 1 : 0) + (ps["matrix"] ? 1 : 0) + (ps["rpy"] ? 1 : 0) >
      1)
    fail(source, ps,
         "give one of rotation_vector, quaternion, quaternion_xyzw, matrix or rpy, not several");
  if (ps["rpy"]) {
    // Roll, pitch, yaw about the fixed x, y, z axes (URDF, ROS, most robot controllers):
    // R = Rz(yaw) Ry(pitch) Rx(roll), angles in units.angle (degrees allowed).
    const Eigen::Vector3d a = vector(source, ps["rpy"], "rpy [roll, pitch, yaw]", 3) * units.angle;
    T.linear() = (Eigen::AngleAxisd(a.z(), Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(a.y(), Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(a.x(), Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
  } else if (ps["quaternion_xyzw"]) {
    // w last (ROS, scipy, Eigen's coeffs()): [x, y, z, w].
    const Eigen::VectorXd q =
        vector(source, ps["quaternion_xyzw"], "quaternion_xyzw [x, y, z, w]", 4);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      fail(source, ps["quaternion_xyzw"],
           fmt::format("quaternion_xyzw must have unit norm (has {:.9g})", q.norm()));
    T.linear() = Eigen::Quaterniond(q(3), q(0), q(1), q(2)).normalized().toRotationMatrix();
  } else if (ps["matrix"]) {
    // 3×3 rotation (9 numbers) or 4×4 homogeneous transform (16; its translation must agree
    // with `position`), row-major.
    const YAML::Node mx = ps["matrix"];
    const Eigen::VectorXd v = vector(source, mx, "matrix (9 or 16 numbers, row-major)");
    if (v.size() != 9 && v.size() != 16)
      fail(source, mx, fmt::format("matrix must have 9 or 16 numbers (has {})", v.size()));
    const int stride = v.size() == 9 ? 3 : 4;
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) R(r, c) = v(r * stride + c);
    if (!(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6) || R.determinant() < 0.0)
      fail(source, mx, "matrix is not a rotation (orthonormal, determinant +1)");
    if (stride == 4 &&
        (Eigen::Vector3d(v(3), v(7), v(11)) * units.length - T.translation()).norm() > 1e-9)
      fail(source, mx, "the 4x4 matrix's translation differs from 'position'");
    T.linear() = R;
  } else if (ps["rotation_vector"]) {
    const Eigen::Vector3d w =
        vector(source, ps["rotation_vector"], "rotation_vector", 3) * units.angle;
    if (w.norm() > 0) T.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  } else if (ps["quaternion"]) {
    const Eigen::VectorXd q = vector(source, ps["quaternion"], "quaternion [w, x, y, z]", 4);
    if (std::abs(q.norm() - 1.0) > 1e-6)
      fail(source, ps["quaternion"],
           fmt::format("quaternion must have unit norm (has {:.9g})", q.norm()));
    T.linear() = Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
  } else {
    fail(source, ps,
         fmt::format("pose '{}': pose needs rotation_vector, quaternion, quaternion_xyzw, rpy or "
                     "matrix",
                     id));
  }
  return T.linear();
}

void add_point_observation(const std::string& source, const YAML::Node& p, const Units& units,
                           const NoiseDefaults& noise, PoseMeasurement& m) {
  if (const YAML::Node pt = p["point"]) {
    const double sigma = p["point_sigma"]
                             ? positive(source, p["point_sigma"], "point_sigma") * units.length
                             : noise.position;
    if (!(sigma > 0.0))
      fail(source, pt,
           fmt::format("pose '{}': point needs point_sigma or noise.position_sigma", m.id));
    const Eigen::Vector3d x = vector(source, pt, "point", 3) * units.length;
    PointObservation o;
    o.measured = x;
    o.weight = Eigen::Matrix3d::Identity() / sigma;
    m.observations.emplace_back(o);
  }
}

void add_pose_observation(const std::string& source, const YAML::Node& p, const Units& units,
                          const NoiseDefaults& noise, PoseMeasurement& m) {
  if (const YAML::Node ps = p["pose"]) {
    check_keys(source, ps, "pose observation",
               {"position", "rotation_vector", "quaternion", "quaternion_xyzw", "matrix", "rpy",
                "position_sigma", "rotation_sigma", "covariance"});
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    if (!ps["position"]) fail(source, ps, fmt::format("pose '{}': pose needs 'position'", m.id));
    T.translation() = vector(source, ps["position"], "position", 3) * units.length;
    T.linear() = pose_rotation(source, ps, m.id, T.translation(), units);
    Matrix6d cov = Matrix6d::Zero();
    if (ps["covariance"]) {
      const Eigen::VectorXd c =
          vector(source, ps["covariance"], "covariance (36 numbers, row-major, m and rad)", 36);
      for (int i = 0; i < 36; ++i) cov(i / 6, i % 6) = c(i);
    } else {
      const double sp =
          ps["position_sigma"]
              ? positive(source, ps["position_sigma"], "position_sigma") * units.length
              : noise.position;
      const double sr = ps["rotation_sigma"]
                            ? positive(source, ps["rotation_sigma"], "rotation_sigma") * units.angle
                            : noise.rotation;
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
        m.observations.emplace_back(o);
      } else {
        m.observations.emplace_back(PoseObservation::with_covariance(T, cov));
      }
    } catch (const std::invalid_argument& e) {
      fail(source, ps, fmt::format("pose '{}': covariance {}", m.id, e.what()));
    }
  }
}

void add_probe_observation(const std::string& source, const YAML::Node& p, const Units& units,
                           const NoiseDefaults& noise, PoseMeasurement& m) {
  if (const YAML::Node pr = p["probe"]) {
    check_keys(source, pr, "probe", {"height", "normal", "offset", "sigma"});
    ProbeHeightObservation o;
    if (!pr["height"]) fail(source, pr, "probe needs 'height'");
    o.measured_height = number(source, pr["height"], "probe height") * units.length;
    if (pr["normal"]) {
      o.normal = vector(source, pr["normal"], "probe normal", 3);
      if (!(o.normal.norm() > 0)) fail(source, pr["normal"], "probe normal must not be zero");
      o.normal.normalize();
    }
    if (pr["offset"]) o.offset = number(source, pr["offset"], "probe offset") * units.length;
    o.sigma =
        pr["sigma"] ? positive(source, pr["sigma"], "probe sigma") * units.length : noise.position;
    if (!(o.sigma > 0.0)) fail(source, pr, "probe needs 'sigma' (or noise.position_sigma)");
    m.observations.emplace_back(o);
  }
}

void add_pixel_observations(const std::string& source, const YAML::Node& p, const Units& units,
                            const NoiseDefaults& noise, const MeasurementsFile& file,
                            const std::map<int, Eigen::Vector3d>& target, PoseMeasurement& m) {
  if (const YAML::Node pxs = p["pixels"]) {
    if (!pxs.IsSequence()) fail(source, pxs, fmt::format("pose '{}': pixels must be a list", m.id));
    if (file.cameras.empty())
      fail(source, pxs, fmt::format("pose '{}' has pixels but the file lists no cameras", m.id));
    for (const YAML::Node& x : pxs) {
      check_keys(source, x, "pixel observation",
                 {"camera", "corner", "point", "pixel", "sigma", "covariance"});
      if (!x["camera"] || !x["pixel"])
        fail(source, x,
             fmt::format("pose '{}': a pixel observation needs 'camera' and 'pixel'", m.id));
      PixelObservation o;
      const std::string cam = x["camera"].Scalar();
      const auto it = std::find_if(file.cameras.begin(), file.cameras.end(),
                                   [&](const ObservingCamera& c) { return c.name == cam; });
      if (it == file.cameras.end())
        fail(source, x["camera"], fmt::format("pose '{}': unknown camera '{}'", m.id, cam));
      o.camera = static_cast<int>(it - file.cameras.begin());
      if (x["corner"]) o.corner = static_cast<int>(number(source, x["corner"], "corner id"));
      if (x["point"]) {
        o.point = vector(source, x["point"], "pixel observation point", 3) * units.length;
      } else if (o.corner >= 0 && target.count(o.corner)) {
        o.point = target.at(o.corner);
      } else {
        fail(source, x,
             fmt::format("pose '{}': corner {} has no 'point' and is not in 'target'", m.id,
                         o.corner));
      }
      o.measured = vector(source, x["pixel"], "pixel [u, v]", 2);
      Eigen::Matrix2d cov = Eigen::Matrix2d::Identity();
      if (x["covariance"]) {
        const Eigen::VectorXd c =
            vector(source, x["covariance"], "pixel covariance (4 numbers, px²)", 4);
        cov << c(0), c(1), c(2), c(3);
      } else {
        const double s = x["sigma"] ? positive(source, x["sigma"], "pixel sigma") : noise.pixel;
        if (!(s > 0.0))
          fail(source, x, fmt::format("pose '{}': pixel needs sigma (or noise.pixel_sigma)", m.id));
        cov *= s * s;
      }
      if (!cov.allFinite()) {
        o.weight = Eigen::Matrix2d::Constant(std::nan(""));  // identify() excludes the pose
      } else {
        try {
          o.weight = sqrt_information(cov);
        } catch (const std::invalid_argument& e) {
          fail(source, x, fmt::format("pose '{}': pixel {}", m.id, e.what()));
        }
      }
      m.observations.emplace_back(o);
    }
  }
}

// The file's `distances` (pose ids checked against `ids`; a pose they name counts as observed).
void parse_distances(const std::string& source, const YAML::Node& root, const Units& units,
                     const NoiseDefaults& noise, const std::map<std::string, YAML::Node>& ids,
                     std::map<std::string, YAML::Node>& unobserved, MeasurementsFile& file) {
  if (const YAML::Node ds = root["distances"]) {
    if (!ds.IsSequence()) fail(source, ds, "distances must be a list");
    for (const YAML::Node& d : ds) {
      check_keys(source, d, "distance", {"a", "b", "distance", "sigma"});
      if (!d["a"] || !d["b"] || !d["distance"])
        fail(source, d, "a distance needs 'a', 'b' (pose ids) and 'distance'");
      DistanceMeasurement dm;
      dm.first = d["a"].Scalar();
      dm.second = d["b"].Scalar();
      for (const auto& [key, id] : {std::pair{"a", dm.first}, {"b", dm.second}})
        if (!ids.count(id))
          fail(source, d[key],
               fmt::format("distance names pose '{}', which is not in 'poses'", id));
      if (dm.first == dm.second)
        fail(source, d, fmt::format("distance from pose '{}' to itself", dm.first));
      unobserved.erase(dm.first);
      unobserved.erase(dm.second);
      dm.observation.measured_distance = number(source, d["distance"], "distance") * units.length;
      dm.observation.sigma = d["sigma"]
                                 ? positive(source, d["sigma"], "distance sigma") * units.length
                                 : noise.position;
      if (!(dm.observation.sigma > 0.0))
        fail(source, d, "distance needs 'sigma' (or noise.position_sigma)");
      file.measurements.distances.push_back(dm);
    }
  }
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
             {"robot", "frame", "units", "noise", "poses", "distances", "description", "cameras",
              "target"});
  MeasurementsFile file;
  file.source = source;
  if (root["robot"]) file.robot = root["robot"].Scalar();
  if (root["frame"]) file.frame = root["frame"].Scalar();

  const Units units = parse_units(source, root);
  const NoiseDefaults noise = parse_noise(source, root, units, file);
  if (const YAML::Node c = root["cameras"])
    file.cameras = parse_cameras(source, c, units.length, units.angle);
  const std::map<int, Eigen::Vector3d> target = parse_target(source, root, units);
  const YAML::Node poses = root["poses"];
  if (!poses || !poses.IsSequence()) fail(source, root, "missing 'poses' (a list)");
  Eigen::Index actuator_count = -1;
  std::map<std::string, YAML::Node> ids;         // pose id -> its node (for line numbers)
  std::map<std::string, YAML::Node> unobserved;  // poses that only distances may observe
  for (const YAML::Node& p : poses) {
    check_keys(source, p, "pose",
               {"id", "actuators", "point", "point_sigma", "pose", "probe", "pixels", "comment"});
    PoseMeasurement m;
    m.line = p.Mark().line + 1;
    if (!p["id"]) fail(source, p, "pose without 'id'");
    m.id = p["id"].Scalar();
    if (!p["actuators"]) fail(source, p, fmt::format("pose '{}' has no 'actuators'", m.id));
    m.actuators = vector(source, p["actuators"], fmt::format("pose '{}' actuators", m.id));
    if (actuator_count >= 0 && m.actuators.size() != actuator_count)
      fail(source, p["actuators"],
           fmt::format("pose '{}' has {} actuator readings, earlier poses have {}", m.id,
                       m.actuators.size(), actuator_count));
    actuator_count = m.actuators.size();
    add_point_observation(source, p, units, noise, m);
    add_pose_observation(source, p, units, noise, m);
    add_probe_observation(source, p, units, noise, m);
    add_pixel_observations(source, p, units, noise, file, target, m);
    // A pose without an observation of its own is allowed when a distance names it (a caliper
    // between two printed positions, a ball-bar): checked once the distances are read.
    if (m.observations.empty()) unobserved.emplace(m.id, p);
    if (!ids.emplace(m.id, p).second)
      fail(source, p["id"], fmt::format("pose id '{}' appears more than once", m.id));
    file.measurements.poses.push_back(std::move(m));
  }
  parse_distances(source, root, units, noise, ids, unobserved, file);
  if (!unobserved.empty()) {
    const auto& [id, node] = *unobserved.begin();
    fail(source, node,
         fmt::format("pose '{}' has no observation (point, pose, probe or pixels) and no "
                     "distance names it",
                     id));
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
  for (const auto& cam : file.cameras) {
    YAML::Node c;
    c["name"] = cam.name;
    c["model"] = std::string(vision::kind_name(cam.model.kind));
    c["size"] = seq(Eigen::Vector2d(cam.model.width, cam.model.height));
    c["params"] = seq(Eigen::Map<const Eigen::VectorXd>(
        cam.model.params.data(), static_cast<Eigen::Index>(cam.model.params.size())));
    c["position"] = seq(cam.world_T_camera.translation());
    const Eigen::AngleAxisd aa(cam.world_T_camera.linear());
    c["rotation_vector"] = seq(aa.axis() * aa.angle());
    root["cameras"].push_back(c);
  }
  // Corner points go to `target` once when every observation of a corner id agrees.
  std::map<int, Eigen::Vector3d> target;
  std::set<int> inconsistent;
  for (const auto& m : file.measurements.poses)
    for (const auto& obs : m.observations)
      if (const auto* px = std::get_if<PixelObservation>(&obs); px && px->corner >= 0) {
        const auto [it, inserted] = target.emplace(px->corner, px->point);
        if (!inserted && it->second != px->point) inconsistent.insert(px->corner);
      }
  for (const auto& [id, point] : target)
    if (!inconsistent.count(id)) {
      YAML::Node t;
      t["id"] = id;
      t["point"] = seq(point);
      t.SetStyle(YAML::EmitterStyle::Flow);
      root["target"].push_back(t);
    }
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
      } else if (const auto* px = std::get_if<PixelObservation>(&obs)) {
        YAML::Node x;
        x["camera"] = file.cameras.at(static_cast<std::size_t>(px->camera)).name;
        if (px->corner >= 0) x["corner"] = px->corner;
        if (px->corner < 0 || inconsistent.count(px->corner)) x["point"] = seq(px->point);
        x["pixel"] = seq(px->measured);
        const Eigen::Matrix2d cov = (px->weight.transpose() * px->weight).inverse();
        if (px->weight(0, 1) == 0.0 && px->weight(1, 0) == 0.0 &&
            std::abs(px->weight(0, 0) - px->weight(1, 1)) <= 1e-12 * px->weight(0, 0))
          x["sigma"] = fmt::format("{:.17g}", 1.0 / px->weight(0, 0));
        else
          x["covariance"] = seq(Eigen::Map<const Eigen::Vector4d>(cov.data()));
        x.SetStyle(YAML::EmitterStyle::Flow);
        p["pixels"].push_back(x);
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
  core::write_file_atomic(path, measurements_to_yaml(file));
}

}  // namespace robocal::calib
