// `robocal compensate` through its command line, on a session folder whose
// identification result is a known perturbed printer (the truth itself, so every command can be
// checked exactly on the true robot): targets -> commands, refused targets named, bad inputs.
#include "printer_scenario.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"

#include "session/json_values.hpp"
#include "session/results_files.hpp"
#include "session/session.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"

#include <gtest/gtest.h>

#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace robocal {
namespace {

class CompensateCli : public test::ScratchDirTest {
 protected:
  CompensateCli() : ScratchDirTest("robocal_compensate_") {}

  void SetUp() override {
    ScratchDirTest::SetUp();
    robot_file = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
    model = calib::load_robot_file(robot_file);
    std::mt19937 rng(3);
    truth = test::printer_truth(model, rng);
    session = dir / "session";
    std::filesystem::create_directories(session);
    app::Session s;
    s.source = "recorded";
    s.robot_name = model.name;
    s.actuators = static_cast<int>(model.actuated.size());
    s.cameras = {{"cam0", 640, 480}};
    core::write_file_atomic(session / "session.yaml", app::session_to_yaml(s));
    core::write_file_atomic(session / "robot.yaml", core::read_text_file(robot_file));
  }

  void identify() const {
    std::filesystem::create_directories(session / "results");
    app::write_identification(app::ResultsLayout{session},
                              {{"status", "ok"},
                               {"start", app::params_json(model, model.nominal_parameters())},
                               {"estimate", app::params_json(model, truth)}});
  }

  int run(const std::vector<std::string>& args, std::string* err = nullptr) const {
    std::vector<std::string> all = {"compensate", session.string()};
    all.insert(all.end(), args.begin(), args.end());
    testing::internal::CaptureStderr();
    const int code = test::run_robocal(all);
    const std::string e = testing::internal::GetCapturedStderr();
    if (err != nullptr) *err = e;
    return code;
  }

  std::string robot_file;
  calib::Mechanism model;
  Eigen::VectorXd truth;
  std::filesystem::path session;
};

TEST_F(CompensateCli, SessionWithoutIdentificationIsRefused) {
  core::write_file_atomic(file("t.csv"), "0, 0, 0.05\n");
  std::string err;
  EXPECT_EQ(run({"--targets", file("t.csv"), "--out", file("c.csv")}, &err), 3);
  EXPECT_NE(err.find("run `robocal identify`"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(file("c.csv")));
}

TEST_F(CompensateCli, TargetCommandsPutTheTrueToolOnTheTargetAndRefusedOnesAreNamed) {
  identify();
  core::write_file_atomic(file("t.csv"),
                          "# x, y, z (m)\nx,y,z\n0.0, 0.0, 0.05\n0.03,-0.02,0.08\n0.5, 0, 0.05\n");
  std::string err;
  EXPECT_EQ(run({"--targets", file("t.csv"), "--out", file("c.csv")}, &err), 1);
  EXPECT_NE(err.find("t.csv:5: unreachable"), std::string::npos) << err;
  const std::vector<Eigen::Vector3d> targets = {{0.0, 0.0, 0.05}, {0.03, -0.02, 0.08}};
  std::istringstream rows(test::read_text(file("c.csv")));
  std::string row;
  std::size_t checked = 0;
  bool refused_row = false;
  while (std::getline(rows, row)) {
    if (row.empty() || row[0] == '#' || row.rfind("line", 0) == 0) continue;
    std::vector<std::string> f;
    std::stringstream ss(row);
    for (std::string cell; std::getline(ss, cell, ',');) f.push_back(cell);
    if (f[0] == "5") {
      refused_row = true;
      EXPECT_EQ(f[1], "unreachable");
      EXPECT_TRUE(f[2].empty());  // no command for it
      continue;
    }
    ASSERT_EQ(f[1], "ok") << row;
    const Eigen::Vector3d readings(std::stod(f[2]), std::stod(f[3]), std::stod(f[4]));
    // The commanded readings, on the true robot, reach the target.
    const auto fk = calib::forward_kinematics(model, truth, readings, model.task.frame);
    ASSERT_TRUE(fk.closure.ok());
    ASSERT_LT(checked, targets.size());
    EXPECT_LT((fk.pose.translation() - targets[checked]).norm(), 1e-7) << row;
    // The task-space command, through the nominal model, gives the same readings.
    const Eigen::Vector3d commanded(std::stod(f[5]), std::stod(f[6]), std::stod(f[7]));
    calib::TaskTarget t;
    t.pose.translation() = commanded;
    const auto ik = calib::solve_ik(model, model.nominal_parameters(), t);
    ASSERT_TRUE(ik.ok());
    EXPECT_LT((ik.actuator_readings - readings).norm(), 1e-7);
    ++checked;
  }
  EXPECT_EQ(checked, targets.size());
  EXPECT_TRUE(refused_row);
}

TEST_F(CompensateCli, MalformedGcodeNamesTheLineAndOverwritesNothing) {
  identify();
  core::write_file_atomic(file("part.gcode"), "G90\nG1 X0 Y0 Z50 F3000\nG1 X10 Y\n");
  core::write_file_atomic(file("out.gcode"), "keep me\n");
  std::string err;
  EXPECT_EQ(run({"--gcode", file("part.gcode"), "--out", file("out.gcode")}, &err), 3);
  EXPECT_NE(err.find("part.gcode:3: 'Y' at column 8 has no number"), std::string::npos) << err;
  EXPECT_EQ(test::read_text(file("out.gcode")), "keep me\n");
  // Nor is the program itself ever the output.
  EXPECT_EQ(run({"--gcode", file("part.gcode"), "--out", file("part.gcode")}, &err), 3);
  EXPECT_NE(err.find("is the program itself"), std::string::npos) << err;
}

TEST_F(CompensateCli, GcodeIsRewritten) {
  identify();
  core::write_file_atomic(file("part.gcode"),
                          "G90\nG1 X0 Y0 Z50 F3000\nG2 X20 Y0 I10 J0 ; half circle\n");
  std::string err;
  EXPECT_EQ(
      run({"--gcode", file("part.gcode"), "--out", file("out.gcode"), "--tolerance", "5"}, &err), 0)
      << err;
  const std::string out = test::read_text(file("out.gcode"));
  EXPECT_EQ(out.rfind("; robocal compensate:", 0), 0U) << out;
  EXPECT_NE(out.find("; half circle"), std::string::npos);
  EXPECT_EQ(run({}, &err), 2);  // neither --targets nor --gcode
}

}  // namespace
}  // namespace robocal
