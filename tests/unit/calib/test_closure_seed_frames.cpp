// The closed-form seed must not depend on where the base frame is or how long the tool is:
// identification estimates both (the base typically metres and half a turn away from the robot
// file's values, seen from a camera), and a seed that ignored them put the Delta on another
// assembly mode.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace {

using robocal::calib::JointType;
using robocal::calib::Mechanism;
using robocal::calib::ParamUnit;

std::string robot_path(const std::string& name) {
  return std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + name + ".yaml";
}

// Moves every base-frame parameter (fixed bodies hanging from the world) and tool-frame
// parameter by a large amount.
Eigen::VectorXd move_base_and_tool(const Mechanism& m, const Eigen::VectorXd& nominal) {
  Eigen::VectorXd p = nominal;
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    const int b = m.parameters[i].body;
    if (b < 0) continue;
    const auto& body = m.bodies[static_cast<std::size_t>(b)];
    const bool base = body.parent < 0 && body.joint == JointType::kFixed;
    const bool tool = b == m.tool && body.joint == JointType::kFixed;
    if (!base && !tool) continue;
    const bool angle = m.parameters[i].unit == ParamUnit::kAngle;
    // 3 rad: a camera looking up at a robot sees its base nearly upside down.
    p[static_cast<Eigen::Index>(i)] += base ? (angle ? 3.0 : 1.7) : (angle ? 0.3 : 0.08);
  }
  return p;
}

class ClosedFormSeedFrames : public testing::TestWithParam<std::string> {};

TEST_P(ClosedFormSeedFrames, PassiveSolutionIgnoresBaseAndToolFrames) {
  const Mechanism m = robocal::calib::load_robot_file(robot_path(GetParam()));
  const Eigen::VectorXd nominal = m.nominal_parameters();
  std::vector<Eigen::VectorXd> variants = {move_base_and_tool(m, nominal)};
  ASSERT_GT((variants[0] - nominal).norm(), 1.0)
      << "the model has no base frame parameters to move";
  // Each base rotation alone, too (a single 3 rad base roll put the Delta on another branch).
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    const int b = m.parameters[i].body;
    if (b < 0 || m.parameters[i].unit != ParamUnit::kAngle) continue;
    const auto& body = m.bodies[static_cast<std::size_t>(b)];
    if (body.parent >= 0 || body.joint != JointType::kFixed) continue;
    Eigen::VectorXd p = nominal;
    p[static_cast<Eigen::Index>(i)] += 3.0;
    variants.push_back(p);
  }

  Eigen::VectorXd q_home(static_cast<Eigen::Index>(m.actuated.size()));
  for (std::size_t i = 0; i < m.actuated.size(); ++i)
    q_home[static_cast<Eigen::Index>(i)] = m.bodies[static_cast<std::size_t>(m.actuated[i])].home;
  // Home and configurations around it (0.1 rad or 2 cm per actuator, different per actuator).
  for (int k = 0; k < 4; ++k) {
    Eigen::VectorXd q = q_home;
    for (Eigen::Index i = 0; i < q.size(); ++i) {
      const auto& body =
          m.bodies[static_cast<std::size_t>(m.actuated[static_cast<std::size_t>(i)])];
      const double step = body.joint == JointType::kPrismatic ? 0.02 : 0.1;
      q[i] += step * k * static_cast<double>(i + 1) / 2.0;
    }
    const Eigen::VectorXd readings = robocal::calib::readings_from_joint_values(m, nominal, q);
    const auto reference = robocal::calib::solve_closure(m, nominal, readings);
    ASSERT_TRUE(reference.ok()) << "configuration " << k;
    for (std::size_t v = 0; v < variants.size(); ++v) {
      const auto shifted = robocal::calib::solve_closure(m, variants[v], readings);
      ASSERT_TRUE(shifted.ok()) << "configuration " << k << ", variant " << v << ": "
                                << robocal::calib::to_string(shifted.status);
      EXPECT_LE((shifted.passive - reference.passive).cwiseAbs().maxCoeff(), 1e-9)
          << "configuration " << k << ", variant " << v
          << ": moving the base/tool frame changed the assembly mode";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(LibraryRobotsWithClosedForms, ClosedFormSeedFrames,
                         testing::Values("rotary_delta", "linear_delta", "gantry_tau"));

}  // namespace
