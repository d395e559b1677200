#include "session/session_robot.hpp"

#include "cli/cli_common.hpp"

#include "robocal/calib/robot_file.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cstdlib>

namespace robocal::app {

namespace fs = std::filesystem;

fs::path robot_library_dir() {
  if (const char* env = std::getenv("ROBOCAL_ROBOT_LIBRARY"); env != nullptr && *env != '\0') {
    std::error_code ec;
    if (!fs::is_directory(env, ec))
      throw InputError(fmt::format(
          "ROBOCAL_ROBOT_LIBRARY={}: no such folder (unset it to use the installed robot library)",
          env));
    return env;
  }
  // An installed program: <prefix>/bin/robocal beside <prefix>/share/robocal/robots, wherever the
  // prefix is (/usr from the Debian package, /opt/..., a DESTDIR). The link names the real file
  // even when robocal was started through a symlink or from PATH.
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    fs::path installed = (exe.parent_path() / ROBOCAL_INSTALLED_ROBOT_LIBRARY).lexically_normal();
    if (fs::is_directory(installed, ec)) return installed;
  }
  // A program in its build tree: the robots of the source it was built from.
  return ROBOCAL_SOURCE_ROBOT_LIBRARY;
}

std::vector<std::string> library_robot_names() {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(robot_library_dir(), ec))
    if (e.path().extension() == ".yaml") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string resolve_robot(const std::string& robot) {
  if (fs::exists(robot)) return robot;
  const fs::path dir = robot_library_dir();
  const auto library = dir / (robot + ".yaml");
  if (fs::exists(library)) return library.string();
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw InputError(fmt::format(
        "robot '{}' is not a file, and the robot library {} does not exist (install robocal, or "
        "set ROBOCAL_ROBOT_LIBRARY to a folder of robot files)",
        robot, dir.string()));
  throw InputError(fmt::format("robot '{}' is neither a file nor a library robot in {} ({})", robot,
                               dir.string(), fmt::join(library_robot_names(), ", ")));
}

calib::Mechanism load_robot(const std::string& path) {
  return calib::load_robot_file(path);
}

vision::TargetBoard load_board(const fs::path& path) {
  return vision::load_target_file(path);
}

SessionRobot session_robot(const Session& s, const std::string& override_file) {
  SessionRobot r;
  r.file = override_file.empty() ? s.path(s.robot_file).string() : override_file;
  r.model = load_robot(r.file);
  const std::string recorded = fmt::format("{} ({} actuators)", s.robot_name, s.actuators);
  if (r.model.name != s.robot_name)
    throw InputError(fmt::format(
        "{}: robot '{}' does not match the session {}, which was recorded with robot {}", r.file,
        r.model.name, s.dir.string(), recorded));
  if (static_cast<int>(r.model.actuated.size()) != s.actuators)
    throw InputError(
        fmt::format("{}: robot '{}' has {} actuators; the session {} was recorded with robot {}",
                    r.file, r.model.name, r.model.actuated.size(), s.dir.string(), recorded));
  r.frame = s.measured_frame.empty() ? r.model.tool : r.model.body_index(s.measured_frame);
  if (r.frame < 0)
    throw InputError(fmt::format("{}: the session's measured frame '{}' is not a body of {}",
                                 r.file, s.measured_frame, r.model.name));
  r.nominal = r.model.nominal_parameters();
  for (const auto& [name, value] : s.target_mount) {
    const int i = r.model.parameter_index(name);
    if (i < 0)
      throw InputError(
          fmt::format("{}: robot.target_mount names '{}', which is not a parameter of {} ({})",
                      (s.dir / "session.yaml").string(), name, r.model.name, r.file));
    r.nominal[i] = value;
  }
  return r;
}

}  // namespace robocal::app
