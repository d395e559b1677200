#pragma once
// The robot-file reader's parts (robot_file.cpp reads the file's top level and calls them): YAML
// values read with errors that name file, line and problem (robot_file_yaml.cpp), the bodies
// (robot_file_bodies.cpp) and the other sections (robot_file_sections.cpp). Internal to
// robocal_calib.
#include "robocal/calib/mechanism.hpp"

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>

#include <map>
#include <set>
#include <string>
#include <vector>

namespace robocal::calib::robot_yaml {

// ---- values (robot_file_yaml.cpp) ----------------------------------------------------------

// Throws RobotFileError "source:line: what" (the node's line when it has one).
[[noreturn]] void fail(const std::string& source, const YAML::Node& node, const std::string& what);

// The node's 1-based line, 0 when it has none.
int line_of(const YAML::Node& node);

// A number or an arithmetic expression (expression.hpp).
double number(const std::string& source, const YAML::Node& node, const std::string& what);

std::string text(const std::string& source, const YAML::Node& node, const std::string& what);

Eigen::Vector3d vec3(const std::string& source, const YAML::Node& node, const std::string& what);

// The rotation of an xyz_rpy body's `orientation:` (quaternion, rotation vector or matrix).
Eigen::Matrix3d orientation_of(const std::string& source, const YAML::Node& node,
                               const std::string& body);

// `map` is a mapping whose keys are all in `allowed`; an unknown key is an error at its line
// that lists the allowed ones.
void check_keys(const std::string& source, const YAML::Node& map, const std::string& what,
                const std::set<std::string>& allowed);

// A list of text values; empty when the node is absent.
std::vector<std::string> string_list(const std::string& source, const YAML::Node& node,
                                     const std::string& what);

// ---- bodies (robot_file_bodies.cpp) --------------------------------------------------------

// `bodies:` into m.bodies (sorted so that a body follows its predecessor) and their parameters
// (created in file order), then the subtree intervals and the actuated and passive joint lists.
void parse_bodies(const YAML::Node& root, const std::string& source,
                  const std::string& default_order,
                  const std::map<std::string, double>& sigma_defaults, Mechanism& m);

// ---- the other sections (robot_file_sections.cpp) ------------------------------------------

// `closures:` and `rods:` (a rod's length is a parameter); every spherical body must close one.
void parse_closures(const YAML::Node& root, const std::string& source,
                    const std::map<std::string, double>& sigma_defaults, Mechanism& m);

// `tool:` (default: the body named tool, else the last) and `task:`.
void parse_tool_and_task(const YAML::Node& root, const std::string& source, Mechanism& m);

// `controller:`: what the controller's G-code axes are.
void parse_controller(const YAML::Node& root, const std::string& source, Mechanism& m);

// `closed_form:`: the seeds' closed form (rotary delta or rails).
void parse_closed_form(const YAML::Node& root, const std::string& source, Mechanism& m);

// `workspace:`: the working volume's conditioning limit.
void parse_workspace(const YAML::Node& root, const std::string& source, Mechanism& m);

// `assembly_mode:` -> Mechanism::assembly_mode, checked against the file's own home
// configuration.
void parse_assembly_mode(const YAML::Node& node, const std::string& source, Mechanism& m);

// `labels:`: parameters in a technician's words.
void parse_labels(const YAML::Node& node, const std::string& source, Mechanism& m);

}  // namespace robocal::calib::robot_yaml
