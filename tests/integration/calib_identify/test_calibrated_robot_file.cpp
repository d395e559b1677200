#include "robocal/calib/calibrated_robot_file.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

namespace {

using namespace robocal::calib;

std::string read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Every parameter of every library robot (written in the file or defaulted, in flow or block
// style, encoder offsets, rod lengths) can be written and reads back exactly.
TEST(CalibratedRobotFile, EveryParameterOfEveryLibraryRobotRoundTrips) {
  for (const std::string name : {"rotary_delta", "linear_delta", "gantry_tau", "ur5", "modular_arm",
                                 "four_bar", "wire_robot_branch"}) {
    const std::string path = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + name + ".yaml";
    const Mechanism model = load_robot_file(path);
    Eigen::VectorXd values = model.nominal_parameters();
    std::vector<std::size_t> all;
    std::mt19937 rng(1);
    std::normal_distribution<double> n(0.0, 1e-4);
    for (std::size_t i = 0; i < model.parameters.size(); ++i) {
      all.push_back(i);
      values(static_cast<Eigen::Index>(i)) += n(rng);
    }
    const std::string text =
        calibrated_robot_yaml(read(path), model, values, all, {"calibrated by a test", "line 2"});
    const Mechanism back = parse_robot_yaml(text, name);
    ASSERT_EQ(back.parameters.size(), model.parameters.size()) << name;
    for (std::size_t i = 0; i < back.parameters.size(); ++i)
      EXPECT_EQ(back.parameters[i].value, values(static_cast<Eigen::Index>(i)))
          << name << " " << back.parameters[i].name;
    EXPECT_EQ(text.rfind("# calibrated by a test\n", 0), 0u);
  }
}

}  // namespace
