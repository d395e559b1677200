#pragma once
// The robot and the boards of a session, loaded and checked against what session.yaml recorded.
#include "session/session.hpp"

#include "robocal/calib/mechanism.hpp"
#include "robocal/vision/target.hpp"

#include <Eigen/Core>

#include <filesystem>
#include <string>
#include <vector>

namespace robocal::app {

// The folder of the library robots shipped with robocal: $ROBOCAL_ROBOT_LIBRARY when set (an
// InputError when it is not a folder); else, for an installed program, share/robocal/robots of
// its installation prefix (found from the program's own path); else the source tree's
// testdata/robots (a program run from its build tree).
std::filesystem::path robot_library_dir();
// The names of the library robots (robot_library_dir()), sorted.
std::vector<std::string> library_robot_names();
// Library robot name (<robot_library_dir()>/NAME.yaml) or a robot file path -> path. InputError
// naming the library folder when neither exists.
std::string resolve_robot(const std::string& robot);

// A robot file; its RobotFileError is an InputError.
calib::Mechanism load_robot(const std::string& path);
// A target file; its error is an InputError.
vision::TargetBoard load_board(const std::filesystem::path& path);

// The robot of a session: its own robot file, or `override_file` checked against the session.
struct SessionRobot {
  calib::Mechanism model;
  std::string file;
  int frame = -1;           // measured body
  Eigen::VectorXd nominal;  // the file's values with the session's target mount
};
SessionRobot session_robot(const Session& session, const std::string& override_file);

}  // namespace robocal::app
