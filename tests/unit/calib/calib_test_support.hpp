#pragma once
// Shared by the calib unit tests: the robot library and a reachable reading range per robot.
#include "robocal/calib/mechanism.hpp"
#include "robocal/calib/robot_file.hpp"

#include <Eigen/Core>

#include <initializer_list>
#include <random>
#include <string>
#include <vector>

namespace robocal::calib::testing {

struct LibraryRobot {
  std::string file;
  std::vector<double> lower, upper;  // actuator reading ranges used by the tests
};

inline const std::vector<LibraryRobot>& library() {
  static const std::vector<LibraryRobot> robots = {
      {"four_bar.yaml", {-1.0}, {1.0}},
      {"rotary_delta.yaml", {-0.2, -0.2, -0.2}, {0.8, 0.8, 0.8}},
      {"linear_delta.yaml", {0.25, 0.25, 0.25}, {0.31, 0.31, 0.31}},
      {"gantry_tau.yaml", {0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}},
      {"wire_robot_branch.yaml", {-20000, -20000, -150, -20}, {20000, 20000, 150, 20}},
      {"modular_arm.yaml", {-1.5, -1.5, -0.2}, {1.5, 1.5, 0.2}},
      {"ur5.yaml", {-3, -3, -3, -3, -3, -3}, {3, 3, 3, 3, 3, 3}},
  };
  return robots;
}

inline std::string robot_path(const std::string& file) {
  return std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + file;
}

inline Mechanism load(const std::string& file) {
  return load_robot_file(robot_path(file));
}

inline Eigen::VectorXd random_readings(const LibraryRobot& r, std::mt19937& rng) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(r.lower.size()));
  for (std::size_t i = 0; i < r.lower.size(); ++i)
    v[static_cast<Eigen::Index>(i)] =
        std::uniform_real_distribution<double>(r.lower[i], r.upper[i])(rng);
  return v;
}

// The nominal parameters with every parameter of `groups` moved by a normal draw of `sigma`
// (metres or radians), in parameter order from a generator seeded with `seed`.
inline Eigen::VectorXd perturbed_parameters(const Mechanism& m, double sigma, unsigned seed,
                                            std::initializer_list<ParamGroup> groups = {
                                                ParamGroup::kJointGeometry}) {
  Eigen::VectorXd p = m.nominal_parameters();
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  for (std::size_t k = 0; k < m.parameters.size(); ++k)
    for (const ParamGroup g : groups)
      if (m.parameters[k].group == g) {
        p[static_cast<Eigen::Index>(k)] += sigma * n(rng);
        break;
      }
  return p;
}

}  // namespace robocal::calib::testing
