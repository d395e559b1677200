#include "session/session.hpp"

#include "cli/cli_common.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/yaml.hpp"
#include "robocal/robotio/png_encode.hpp"
#include "robocal/vision/hand_eye_io.hpp"

#include <fmt/core.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>

namespace robocal::app {

namespace fs = std::filesystem;

std::vector<std::string> Session::camera_names() const {
  std::vector<std::string> names;
  for (const auto& c : cameras) names.push_back(c.name);
  return names;
}

bool is_session(const fs::path& dir) {
  std::error_code ec;
  return fs::is_directory(dir, ec) && fs::is_regular_file(dir / "session.yaml", ec);
}

Session parse_session_yaml(const std::string& text, const std::string& source) {
  const YAML::Node root = core::load_yaml_text(text, source);
  const core::YamlContext ctx{source};
  if (!root.IsMap())
    throw InputError(fmt::format("{}: a session file is a YAML mapping (see app/SESSION.md)",
                                 core::yaml_where(source, root)));
  ctx.reject_unknown_keys(root, {"format", "software", "created", "source", "seed", "robot",
                                 "cameras", "targets", "folders"});
  Session s;
  s.format = ctx.required<std::string>(root, "format");
  if (s.format != kSessionFormat)
    throw InputError(fmt::format("{}: format '{}' is not '{}'",
                                 core::yaml_where(source, root["format"]), s.format,
                                 kSessionFormat));
  s.software = ctx.optional<std::string>(root, "software", "");
  s.created = ctx.optional<std::string>(root, "created", "");
  s.source = ctx.optional<std::string>(root, "source", "recorded");
  s.seed = ctx.optional<unsigned>(root, "seed", 1U);

  const YAML::Node robot = ctx.require_map(root, "robot");
  ctx.reject_unknown_keys(robot, {"file", "name", "measured_frame", "actuators", "target_mount"});
  s.robot_file = ctx.required<std::string>(robot, "file");
  s.robot_name = ctx.required<std::string>(robot, "name");
  s.measured_frame = ctx.optional<std::string>(robot, "measured_frame", "");
  s.actuators = ctx.required<int>(robot, "actuators");
  if (s.actuators <= 0)
    throw InputError(
        fmt::format("{}: 'actuators' must be positive", core::yaml_where(source, robot)));
  if (const YAML::Node mount = robot["target_mount"]) {
    if (!mount.IsMap())
      throw InputError(fmt::format("{}: 'target_mount' must map parameter names to values",
                                   core::yaml_where(source, mount)));
    for (const auto& kv : mount) {
      const auto name = kv.first.as<std::string>();
      try {
        s.target_mount.emplace_back(name, kv.second.as<double>());
      } catch (const YAML::Exception&) {
        throw InputError(fmt::format("{}: target_mount.{} is not a number",
                                     core::yaml_where(source, kv.second), name));
      }
    }
  }

  const YAML::Node cameras = root["cameras"];
  if (!cameras || !cameras.IsSequence() || cameras.size() == 0)
    throw InputError(fmt::format("{}: 'cameras' must be a non-empty list",
                                 core::yaml_where(source, cameras ? cameras : root)));
  for (const auto& c : cameras) {
    if (!c.IsMap())
      throw InputError(fmt::format("{}: a camera is a mapping {{name, width, height}}",
                                   core::yaml_where(source, c)));
    ctx.reject_unknown_keys(c, {"name", "width", "height"});
    SessionCamera cam{ctx.required<std::string>(c, "name"), ctx.required<int>(c, "width"),
                      ctx.required<int>(c, "height")};
    if (cam.width <= 0 || cam.height <= 0)
      throw InputError(fmt::format("{}: camera '{}' needs a positive image size",
                                   core::yaml_where(source, c), cam.name));
    for (const auto& other : s.cameras)
      if (other.name == cam.name)
        throw InputError(
            fmt::format("{}: camera name '{}' used twice", core::yaml_where(source, c), cam.name));
    s.cameras.push_back(cam);
  }
  const YAML::Node targets = ctx.require_map(root, "targets");
  ctx.reject_unknown_keys(targets, {"end_effector", "calibration"});
  s.ee_target = ctx.required<std::string>(targets, "end_effector");
  s.calibration_target = ctx.required<std::string>(targets, "calibration");
  const YAML::Node folders = ctx.require_map(root, "folders");
  ctx.reject_unknown_keys(folders, {"intrinsics", "rig", "poses"});
  s.intrinsics_views = ctx.required<std::string>(folders, "intrinsics");
  s.rig_views = ctx.required<std::string>(folders, "rig");
  s.poses = ctx.required<std::string>(folders, "poses");
  return s;
}

Session load_session(const fs::path& dir) {
  const fs::path file = dir / "session.yaml";
  if (!is_session(dir))
    throw InputError(fmt::format("{}: not a session folder (no session.yaml; see app/SESSION.md)",
                                 dir.string()));
  Session s = parse_session_yaml(core::read_text_file(file), file.string());
  s.dir = dir;
  return s;
}

std::string session_to_yaml(const Session& s) {
  YAML::Emitter e;
  e << YAML::BeginMap;
  e << YAML::Key << "format" << YAML::Value << s.format;
  e << YAML::Key << "software" << YAML::Value << s.software;
  e << YAML::Key << "created" << YAML::Value << s.created;
  e << YAML::Key << "source" << YAML::Value << s.source;
  e << YAML::Key << "seed" << YAML::Value << s.seed;
  e << YAML::Key << "robot" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "file" << YAML::Value << s.robot_file;
  e << YAML::Key << "name" << YAML::Value << s.robot_name;
  e << YAML::Key << "measured_frame" << YAML::Value << s.measured_frame;
  e << YAML::Key << "actuators" << YAML::Value << s.actuators;
  if (!s.target_mount.empty()) {
    e << YAML::Key << "target_mount" << YAML::Value << YAML::BeginMap;
    for (const auto& [name, value] : s.target_mount)
      e << YAML::Key << name << YAML::Value << fmt::format("{:.17g}", value);
    e << YAML::EndMap;
  }
  e << YAML::EndMap;
  e << YAML::Key << "cameras" << YAML::Value << YAML::BeginSeq;
  for (const auto& c : s.cameras)
    e << YAML::Flow << YAML::BeginMap << YAML::Key << "name" << YAML::Value << c.name << YAML::Key
      << "width" << YAML::Value << c.width << YAML::Key << "height" << YAML::Value << c.height
      << YAML::EndMap;
  e << YAML::EndSeq;
  e << YAML::Key << "targets" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "end_effector" << YAML::Value << s.ee_target;
  e << YAML::Key << "calibration" << YAML::Value << s.calibration_target;
  e << YAML::EndMap;
  e << YAML::Key << "folders" << YAML::Value << YAML::BeginMap;
  e << YAML::Key << "intrinsics" << YAML::Value << s.intrinsics_views;
  e << YAML::Key << "rig" << YAML::Value << s.rig_views;
  e << YAML::Key << "poses" << YAML::Value << s.poses;
  e << YAML::EndMap;
  e << YAML::EndMap;
  return std::string("# robocal session (format: app/SESSION.md)\n") + e.c_str() + "\n";
}

std::string pose_record_yaml(const PoseRecord& pose) {
  std::string text =
      fmt::format("# robot pose {} (format: app/SESSION.md)\nactuators: [", pose.name);
  for (Eigen::Index i = 0; i < pose.actuators.size(); ++i)
    text += fmt::format("{}{:.17g}", i ? ", " : "", pose.actuators[i]);
  text += fmt::format("]\ntimestamp: {:.3f}\n", pose.timestamp);
  if (pose.base_T_flange) {
    const Eigen::Vector3d p = pose.base_T_flange->translation();
    const Eigen::Quaterniond q(pose.base_T_flange->linear());
    text += fmt::format(
        "flange_pose: {{x: {:.17g}, y: {:.17g}, z: {:.17g}, qx: {:.17g}, qy: {:.17g}, qz: "
        "{:.17g}, qw: {:.17g}}}\n",
        p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
  }
  return text;
}

std::vector<PoseRecord> load_pose_records(const Session& session) {
  const fs::path folder = session.path(session.poses);
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw InputError(folder.string() + ": the session's pose folder is missing");
  std::vector<fs::path> subs;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_directory()) subs.push_back(e.path());
  // A pose folder the system will not list (no read permission, a link loop) is said so, not
  // taken for a session without poses.
  if (ec) throw InputError(filesystem_problem(folder, ec));
  std::sort(subs.begin(), subs.end());
  std::vector<PoseRecord> out;
  for (const auto& sub : subs) {
    PoseRecord r;
    r.name = sub.filename().string();
    r.dir = sub;
    const fs::path file = sub / "pose.yaml";
    try {
      // is_regular_file reports a folder it may not enter (no permission, a link loop) in `ec`:
      // that cause, not "missing", which would send the operator looking for a lost file.
      if (!fs::is_regular_file(file, ec))
        throw InputError(ec && ec != std::errc::no_such_file_or_directory
                             ? filesystem_problem(file, ec)
                             : file.string() + ": missing");
      const std::string source = file.string();
      const YAML::Node root = core::load_yaml_text(core::read_text_file(file), source);
      const core::YamlContext ctx{source};
      if (!root.IsMap()) throw InputError(core::yaml_where(source, root) + ": expected a mapping");
      const YAML::Node q = root["actuators"];
      if (!q || !q.IsSequence())
        throw InputError(core::yaml_where(source, q ? q : root) +
                         ": 'actuators' must be a list of numbers");
      r.actuators.resize(static_cast<Eigen::Index>(q.size()));
      for (std::size_t i = 0; i < q.size(); ++i) {
        try {
          r.actuators[static_cast<Eigen::Index>(i)] = q[i].as<double>();
        } catch (const YAML::Exception&) {
          throw InputError(
              fmt::format("{}: actuators[{}] is not a number", core::yaml_where(source, q[i]), i));
        }
      }
      r.timestamp = ctx.optional<double>(root, "timestamp", 0.0);
      if (const YAML::Node flange = root["flange_pose"]) {
        try {
          r.base_T_flange = vision::read_flange_pose(ctx, flange);
        } catch (const InputError& e) {
          r.flange_problem = e.what();
        }
      }
      if (r.actuators.size() != session.actuators)
        throw InputError(fmt::format("{}: {} actuator readings, the session's robot has {}",
                                     core::yaml_where(source, q), r.actuators.size(),
                                     session.actuators));
      for (Eigen::Index i = 0; i < r.actuators.size(); ++i)
        if (!std::isfinite(r.actuators[i]))
          throw InputError(fmt::format("{}: actuators[{}] is {} (no valid reading)",
                                       core::yaml_where(source, q), i, r.actuators[i]));
    } catch (const InputError& e) {
      r.problem = e.what();
    }
    // A copied folder (pose_003_dup) is not a new measurement: the same readings at the same
    // recorded time as an earlier pose. Without a timestamp, equal readings may be a deliberate
    // repeat and are kept.
    if (r.problem.empty() && r.timestamp != 0.0)
      for (const PoseRecord& earlier : out)
        if (earlier.problem.empty() && earlier.timestamp == r.timestamp &&
            earlier.actuators == r.actuators) {
          r.problem = fmt::format(
              "{}: a copy of {} (same actuator readings, same time {:.3f} s); a copied folder is "
              "not a new measurement, remove it",
              (sub / "pose.yaml").string(), earlier.name, r.timestamp);
          break;
        }
    out.push_back(r);
  }
  return out;
}

void write_image_atomic(const fs::path& path, const cv::Mat& image) {
  // The capture's encoding (zlib level 1, Huffman coding only, no row filter): lossless like
  // any PNG, in half cv::imencode's time for a camera frame (robotio/png_encode.hpp).
  std::string png;
  try {
    png = robotio::encode_png(image, 1, path.string());
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
  core::write_file_atomic(path, png, core::Overwrite::kRefuse);
}

std::string utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

}  // namespace robocal::app
