// G-code parsing and the rewrite's bookkeeping: what each line means, and malformed
// lines refused naming the file and line.
#include "robocal/calib/gcode_program.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/input_error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace robocal::calib {
namespace {

std::string error_of(const std::string& text) {
  try {
    (void)gcode_path(parse_gcode(text, "prog.gcode"), 1e-3);
  } catch (const core::InputError& e) {
    return e.what();
  }
  return "";
}

TEST(GcodeProgram, ParsesWordsCommentsAndCommands) {
  const GcodeProgram p = parse_gcode(
      "G01 X1.5 y-2 Z+3 F1200 ; move\r\n(setup) M83\nM117 Hello (world)\n%\n", "p.gcode");
  ASSERT_EQ(p.lines.size(), 4U);
  EXPECT_EQ(p.lines[0].command, "G1");
  ASSERT_NE(p.lines[0].word('Y'), nullptr);
  EXPECT_DOUBLE_EQ(p.lines[0].word('Y')->value, -2.0);
  EXPECT_DOUBLE_EQ(p.lines[0].word('Z')->value, 3.0);
  EXPECT_EQ(p.lines[0].comment, "; move");
  EXPECT_EQ(p.lines[0].text, "G01 X1.5 y-2 Z+3 F1200 ; move");
  EXPECT_EQ(p.lines[1].command, "M83");
  EXPECT_EQ(p.lines[1].comment, "(setup)");
  EXPECT_EQ(p.lines[2].command, "M117");  // free text is not parsed as words
  EXPECT_TRUE(p.lines[2].words.empty());
  EXPECT_TRUE(p.lines[3].command.empty());
}

TEST(GcodeProgram, MeantPathFollowsModesOffsetsAndArcs) {
  // Absolute, relative, G92 offset, then a clockwise half circle by R.
  const auto path = gcode_path(parse_gcode("G90\nG1 X10 Y0 Z5\nG91\nG1 X5 Y5\nG90\nG92 X0 Y0\n"
                                           "G1 X1 Y0\nG2 X-19 Y0 R10\n",
                                           "p.gcode"),
                               0.5e-3);
  ASSERT_FALSE(path.empty());
  EXPECT_EQ(path.front().line, 2);
  EXPECT_LT((path.front().position - Eigen::Vector3d(10e-3, 0, 5e-3)).norm(), 1e-12);
  // After the relative move the machine is at (15, 5); G92 makes that (0, 0); X1 Y0 -> (16, 5).
  // The half circle from (16, 5) to (-4, 5) about (6, 5), clockwise: through (6, -5).
  double best = 1.0;
  for (const auto& p : path) {
    if (p.line != 8) continue;
    EXPECT_NEAR((p.position - Eigen::Vector3d(6e-3, 5e-3, 5e-3)).norm(), 10e-3, 1e-12);
    best = std::min(best, (p.position - Eigen::Vector3d(6e-3, -5e-3, 5e-3)).norm());
  }
  EXPECT_LT(best, 0.3e-3);
  EXPECT_LT((path.back().position - Eigen::Vector3d(-4e-3, 5e-3, 5e-3)).norm(), 1e-12);

  // An arc with only a centre is a full circle back to its start.
  const auto circle = gcode_path(parse_gcode("G90\nG1 X10 Y0 Z5\nG3 I-10 J0\n", "c.gcode"), 0.5e-3);
  double far = 0.0;
  for (const auto& p : circle) {
    EXPECT_NEAR(p.position.head<2>().norm(), 10e-3, 1e-12);
    far = std::max(far, (p.position - Eigen::Vector3d(10e-3, 0, 5e-3)).norm());
  }
  EXPECT_NEAR(far, 20e-3, 1e-5);  // it goes round to the opposite side
  EXPECT_GT(circle.size(), 100U);
}

TEST(GcodeProgram, MalformedLinesAreNamed) {
  EXPECT_NE(error_of("G90\nG1 X\n").find("prog.gcode:2: 'X' at column 4 has no number"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X1.2.3 Y0 Z0\n").find("prog.gcode:1: 'X1.2.3'"), std::string::npos);
  EXPECT_NE(error_of("G1 X1 X2\n").find("prog.gcode:1: 'X' is given twice"), std::string::npos);
  EXPECT_NE(error_of("G1 X0 (open\n").find("prog.gcode:1: comment '('"), std::string::npos);
  EXPECT_NE(error_of("G1 X0 Y0 Z0\nG2 X10 Y0\n").find("prog.gcode:2: G2 needs a centre"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X0 Y0 Z0\nG2 X10 Y0 I3 J0\n").find("prog.gcode:2: the arc's end"),
            std::string::npos);
  EXPECT_NE(error_of("N10 G1 X0\n").find("prog.gcode:1: line numbers"), std::string::npos);
  EXPECT_NE(error_of("G20\n").find("prog.gcode:1: inch units"), std::string::npos);
  EXPECT_NE(error_of("G91\nG1 X5\n").find("prog.gcode:2: relative move of X"), std::string::npos);
  EXPECT_NE(error_of("G28\nG1 Z5\n").find("prog.gcode:2: X is unknown"), std::string::npos);
  EXPECT_NE(error_of("G1 X0 Y0 Z0\nX5\n").find("prog.gcode:2: 'X5' without a command"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X0 Y0 Z0 # x\n").find("prog.gcode:1: unexpected character '#'"),
            std::string::npos);
  EXPECT_NE(error_of("G18\nG1 X0 Y0 Z0\nG2 X1 Y1 R1\n").find("prog.gcode:3: arcs are supported"),
            std::string::npos);
}

TEST(GcodeProgram, RewriteWithExactModelKeepsCoordinates) {
  // Calibrated = nominal: p' = p, so the rewrite is the program in canonical form.
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  const CompensationModels models{&model, model.nominal_parameters(), model.nominal_parameters()};
  const GcodeRewrite r = rewrite_gcode(
      parse_gcode("G90\nG1 X10 Y-5 Z40 F600 ; go\nG91\nG1 X1 E0.5\n", "p.gcode"), models);
  EXPECT_EQ(r.text,
            "G90\nG1 X10.0000 Y-5.0000 Z40.0000 F600 ; go\nG91\nG1 X1.0000 Y0.0000 Z0.0000 "
            "E0.50000\n");
  EXPECT_LT(r.stats.max_correction, 1e-9);

  // Absolute extrusion over an arc cut into chords: rising to the line's E, ending exactly on it.
  const GcodeRewrite arc = rewrite_gcode(
      parse_gcode("G90\nM82\nG1 X10 Y0 Z40 E1\nG3 X-10 Y0 I-10 J0 E3\n", "a.gcode"), models);
  const GcodeProgram out = parse_gcode(arc.text, "out.gcode");
  double last_e = 0.0;
  int pieces = 0;
  for (const auto& line : out.lines) {
    const GcodeWord* e = line.word('E');
    if (e == nullptr) continue;
    EXPECT_GT(e->value, last_e);
    last_e = e->value;
    ++pieces;
  }
  EXPECT_GT(pieces, 10);
  EXPECT_DOUBLE_EQ(last_e, 3.0);
}

TEST(GcodeProgram, RefusesRobotsWithoutAPositionTask) {
  const Mechanism model = load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml");
  const CompensationModels models{&model, model.nominal_parameters(), model.nominal_parameters()};
  EXPECT_THROW((void)rewrite_gcode(parse_gcode("G1 X0 Y0 Z0\n", "p.gcode"), models),
               core::InputError);
}

}  // namespace
}  // namespace robocal::calib
