#include "session/session_robot.hpp"

#include "cli/cli_common.hpp"

#include "robocal/calib/robot_file.hpp"
#include "robocal/vision/target_io.hpp"

#include <fmt/core.h>
#include <fmt/ranges.h>

#include <algorithm>

namespace robocal::app {

namespace fs = std::filesystem;

std::vector<std::string> library_robot_names() {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(ROBOCAL_ROBOT_LIBRARY_DIR, ec))
    if (e.path().extension() == ".yaml") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string resolve_robot(const std::string& robot) {
  if (fs::exists(robot)) return robot;
  const auto library = fs::path(ROBOCAL_ROBOT_LIBRARY_DIR) / (robot + ".yaml");
  if (fs::exists(library)) return library.string();
  throw InputError(fmt::format("robot '{}' is neither a file nor a library robot (library: {})",
                               robot, fmt::join(library_robot_names(), ", ")));
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
