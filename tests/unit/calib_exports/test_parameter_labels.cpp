// Parameter labels: every library robot says each parameter in words, exact labels win
// over a body's words, and a label for something the robot does not have is an error at its line.
#include "../calib/calib_test_support.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <set>
#include <string>

namespace robocal::calib {
namespace {

const std::string kArm = R"(robot: arm
bodies:
  - {name: base, convention: xyz_rpy, joint: fixed}
  - {name: shoulder, parent: base, convention: dh, joint: revolute, role: actuated, params: {a: 0.3}}
  - {name: tool, parent: shoulder, convention: xyz_rpy, joint: fixed}
)";

TEST(ParameterLabels, EveryLibraryRobotLabelsEveryParameterOnce) {
  for (const auto& robot : testing::library()) {
    const Mechanism m = testing::load(robot.file);
    std::set<std::string> labels;
    for (std::size_t i = 0; i < m.parameters.size(); ++i) {
      const Parameter& p = m.parameters[i];
      EXPECT_FALSE(p.label.empty()) << robot.file << ": " << p.name << " has no label";
      // Words, not the raw name: a technician does not read "body26.d1".
      EXPECT_EQ(p.label.find('.'), std::string::npos) << robot.file << ": " << p.label;
      EXPECT_TRUE(labels.insert(p.label).second)
          << robot.file << ": label '" << p.label << "' names two parameters";
      EXPECT_EQ(m.parameter_display_name(i), p.label);
    }
  }
}

TEST(ParameterLabels, TheIssuesExamplesReadAsWritten) {
  const Mechanism delta = testing::load("rotary_delta.yaml");
  EXPECT_EQ(delta.parameters[static_cast<std::size_t>(delta.parameter_index("body26.d1"))].label,
            "rod 26 length");
  EXPECT_EQ(
      delta.parameters[static_cast<std::size_t>(delta.parameter_index("body2.encoder_offset"))]
          .label,
      "shoulder 1 encoder zero");
  const Mechanism printer = testing::load("linear_delta.yaml");
  EXPECT_EQ(
      printer.parameters[static_cast<std::size_t>(printer.parameter_index("rod_a.length"))].label,
      "tower A arm length");
}

TEST(ParameterLabels, BodyWordsExactLabelsAndRawNameFallback) {
  const Mechanism m = parse_robot_yaml(kArm +
                                           "labels:\n  shoulder: joint 1\n  shoulder.a: upper "
                                           "arm length\n",
                                       "arm.yaml");
  const auto label = [&](const std::string& name) {
    return m.parameter_display_name(static_cast<std::size_t>(m.parameter_index(name)));
  };
  EXPECT_EQ(label("shoulder.a"), "upper arm length");  // exact wins over the body's words
  EXPECT_EQ(label("shoulder.alpha"), "joint 1 link twist");
  EXPECT_EQ(label("shoulder.encoder_offset"), "joint 1 encoder zero");
  EXPECT_EQ(label("base.x"), "base.x");  // no label: the raw name
  const Mechanism unlabelled = parse_robot_yaml(kArm, "arm.yaml");
  for (std::size_t i = 0; i < unlabelled.parameters.size(); ++i)
    EXPECT_EQ(unlabelled.parameter_display_name(i), unlabelled.parameters[i].name);
}

std::string error_of(const std::string& text) {
  try {
    parse_robot_yaml(text, "arm.yaml");
  } catch (const RobotFileError& e) {
    return e.what();
  }
  return "no error";
}

TEST(ParameterLabels, BadLabelsNameFileLineAndProblem) {
  // kArm has 5 lines; `labels:` is line 6, its first entry line 7.
  const std::string unknown = error_of(kArm + "labels:\n  shoulder.b: oops\n");
  EXPECT_NE(unknown.find("arm.yaml:7:"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("unknown parameter 'shoulder.b'"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("shoulder.alpha"), std::string::npos) << unknown;  // close matches
  const std::string nobody = error_of(kArm + "labels:\n  tool: tip\n  elbow: joint 2\n");
  EXPECT_NE(nobody.find("arm.yaml:8:"), std::string::npos) << nobody;
  const std::string empty = error_of(kArm + "labels:\n  shoulder: ' '\n");
  EXPECT_NE(empty.find("arm.yaml:7:"), std::string::npos) << empty;
  EXPECT_NE(empty.find("empty"), std::string::npos) << empty;
  const std::string not_map = error_of(kArm + "labels: [a, b]\n");
  EXPECT_NE(not_map.find("arm.yaml:6:"), std::string::npos) << not_map;
}

}  // namespace
}  // namespace robocal::calib
