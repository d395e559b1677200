#pragma once
// Shared by the robotio link tests and the link bench: starts `robocal sim-controller` as its own
// process (the built binary, ROBOCAL_BINARY), sets up the linear delta's guard and link, and
// reads the simulator's JSONL log, the independent record of what the controller received and
// executed.
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/safety_guard.hpp"
#include "robocal/robotio/sim_process.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace robocal::test {

inline calib::Mechanism linear_delta() {
  return calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
}

// The declared cell for these tests: the effector stays in this box (robot world, m).
inline robotio::SafetyLimits delta_limits() {
  robotio::SafetyLimits l;
  l.workspace_min = Eigen::Vector3d(-0.08, -0.08, 0.02);
  l.workspace_max = Eigen::Vector3d(0.08, 0.08, 0.16);
  l.max_speed = 0.25;        // m/s of carriage travel
  l.max_acceleration = 5.0;  // m/s^2
  l.path_step = 2e-3;
  return l;
}

inline std::vector<std::string> sim_args(const std::string& log, std::vector<std::string> extra) {
  // --max-seconds: a simulator orphaned by a crashed test exits on its own.
  std::vector<std::string> a = {
      "--robot",       "linear_delta", "--log",           log, "--pty-link", log + ".pty",
      "--max-seconds", "600",          "--busy-interval", "1"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

// Every JSON line of the simulator's log.
inline std::vector<nlohmann::json> read_sim_log(const std::string& path) {
  std::vector<nlohmann::json> out;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line))
    if (!line.empty()) out.push_back(nlohmann::json::parse(line, nullptr, false));
  return out;
}

inline std::vector<nlohmann::json> events(const std::vector<nlohmann::json>& log,
                                          const std::string& ev) {
  std::vector<nlohmann::json> out;
  for (const auto& j : log)
    if (j.is_object() && j.value("ev", "") == ev) out.push_back(j);
  return out;
}

// Lines the controller received whose command (after the line number) starts with `code`.
inline int received(const std::vector<nlohmann::json>& log, const std::string& code) {
  int n = 0;
  for (const auto& j : events(log, "rx")) {
    std::string line = j.value("line", "");
    if (!line.empty() && line[0] == 'N') line = line.substr(line.find(' ') + 1);
    if (line.rfind(code, 0) == 0) ++n;
  }
  return n;
}

// Targets inside the declared box, solved by IK on the nominal model (readings).
inline std::vector<Eigen::VectorXd> delta_targets(const calib::Mechanism& model, int count,
                                                  unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> xy(-0.05, 0.05), z(0.05, 0.12);
  std::vector<Eigen::VectorXd> out;
  const Eigen::VectorXd params = model.nominal_parameters();
  while (static_cast<int>(out.size()) < count) {
    calib::TaskTarget t;
    // One draw a statement, z first (robocal/core/random_draws.hpp says why).
    const double height = z(rng);
    const double y = xy(rng);
    const double x = xy(rng);
    t.pose.translation() = Eigen::Vector3d(x, y, height);
    const calib::IkResult ik = calib::solve_ik(model, params, t);
    if (ik.ok()) out.push_back(ik.actuator_readings);
  }
  return out;
}

// The box for a delta printer driven in its firmware's own kinematics: up to the homed position
// (all carriages at the endstops put the effector at z = 0.45 - sqrt(0.27^2 - 0.14^2) = 0.219
// m), where every motion starts.
inline robotio::SafetyLimits delta_native_limits() {
  robotio::SafetyLimits l = delta_limits();
  l.workspace_max.z() = 0.225;
  return l;
}

// X Y Z of a G1 line as sent ("G1 X.. Y.. Z.. F..", or numbered "N.. G1 ...*cs"); NaN where a
// word is missing.
inline Eigen::Vector3d g1_xyz(std::string line) {
  line = line.substr(0, line.find('*'));
  std::stringstream ss(line);
  std::string tok;
  Eigen::Vector3d p = Eigen::Vector3d::Constant(std::nan(""));
  while (ss >> tok)
    if (tok.size() > 1 && (tok[0] == 'X' || tok[0] == 'Y' || tok[0] == 'Z'))
      p[tok[0] - 'X'] = std::stod(tok.substr(1));
  return p;
}

inline robotio::GcodeLinkOptions link_options(const calib::Mechanism& model,
                                              const std::string& address) {
  robotio::GcodeLinkOptions o;
  o.address = address;
  o.axes = robotio::axes_for_robot(model, 80.0, 100.0);
  o.reply_timeout = std::chrono::milliseconds(500);
  return o;
}

}  // namespace robocal::test
