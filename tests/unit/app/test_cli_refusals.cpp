// A user's mistakes, as a hostile tester makes them: each case is the command, the exit code it
// must end with, the words its message must contain, and that nothing the command could have
// written has changed. A bad value, an unknown command, options that conflict or do not apply are
// a bad command line (exit 2), refused before anything runs; a file with a key it does not know
// or values in the wrong units is a bad input file (exit 3) named with the line and the likely
// cause; a fit or an answer that cannot be relied on is no success (exit 1).
#include "cli/command_registry.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"
#include "stages/stages.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using robocal::test::CliRun;
using robocal::test::read_text;

struct RefusalCase {
  std::vector<std::string> args;
  int code;
  std::vector<std::string> says;  // each must be in the message
};

// `text` with its first `from` replaced by `to` (a test that does not find it fails).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

// `text` with every rotation vector's components multiplied by 180/π: degrees written where the
// file says radians.
std::string rotation_vectors_in_degrees(const std::string& text) {
  const std::string key = "rotation_vector: [";
  std::string out;
  std::size_t at = 0;
  for (std::size_t next = 0; (next = text.find(key, at)) != std::string::npos;) {
    const std::size_t begin = next + key.size();
    const std::size_t end = text.find(']', begin);
    out += text.substr(at, begin - at);
    std::stringstream in(text.substr(begin, end - begin));
    std::string item;
    for (int k = 0; std::getline(in, item, ','); ++k)
      out += (k > 0 ? ", " : "") + std::to_string(std::stod(item) * 180.0 / std::numbers::pi);
    at = end;
  }
  return out + text.substr(at);
}

std::string joined(const std::vector<std::string>& args) {
  std::string text = "robocal";
  for (const std::string& a : args) text += " " + a;
  return text;
}

// Every file under `dir`, by relative path, with its bytes: what "unchanged" is compared on.
std::map<std::string, std::string> files_under(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file())
      out[fs::relative(e.path(), dir).generic_string()] = read_text(e.path().string());
  return out;
}

struct CliRefusals : robocal::test::ScratchDirTest {
  CliRefusals() : ScratchDirTest("robocal_cli_refusals_") {}

  std::string testdata = ROBOCAL_TESTDATA_DIR;
  std::string robot = testdata + "/robots/linear_delta.yaml";
  std::string target = std::string(ROBOCAL_TESTDATA_DIR) + "/vision/apriltag_4x3.yaml";

  // A session folder with results a refused command must leave as they are.
  std::string session() {
    const fs::path s = dir / "session";
    fs::create_directories(s / "results");
    std::ofstream(s / "session.yaml") << "robot: linear_delta\n";
    std::ofstream(s / "results" / "identification.json") << "{\"status\": \"ok\"}\n";
    std::ofstream(s / "results" / "calibrated_robot.yaml") << "# previous result\n";
    return s.string();
  }

  // A copy of testdata file `from` at `name` in the scratch folder, with `edit` (from, to) made.
  std::string edited(const std::string& from, const std::string& name,
                     const std::pair<std::string, std::string>& edit) {
    std::ofstream(dir / name) << replaced(read_text(testdata + "/" + from), edit.first,
                                          edit.second);
    return file(name);
  }

  // Runs every case; each must end with its code and words, and leave the scratch folder as it
  // was (no file written, none changed).
  void expect_refused(const std::vector<RefusalCase>& cases) {
    for (const RefusalCase& c : cases) {
      const auto before = files_under(dir);
      const CliRun r = robocal::test::run_robocal_captured(c.args);
      EXPECT_EQ(r.code, c.code) << joined(c.args) << "\n" << r.err;
      for (const std::string& word : c.says)
        EXPECT_NE(r.err.find(word), std::string::npos)
            << joined(c.args) << ": no '" << word << "' in:\n"
            << r.err;
      EXPECT_EQ(files_under(dir), before) << joined(c.args) << " changed files";
    }
  }
};

TEST_F(CliRefusals, BadValuesAreABadCommandLine) {
  expect_refused({
      {{"kin", "fk", robot, "--actuators", "abc"}, 2, {"--actuators", "abc"}},
      {{"kin", "fk", robot, "--actuators", "0.1,0.2"}, 2, {"--actuators needs 3"}},
      {{"identify", "--robot", robot, "--simulate", file("m.yaml"), "--kind", "foo"},
       2,
       {"--kind", "point, pose, probe or pixel", "got 'foo'"}},
      {{"intrinsics", "--images", dir.string(), "--target", target, "--model", "foo"},
       2,
       {"--model", "foo", "pinhole_radtan"}},
      {{"sim-controller", "--robot", "linear_delta", "--firmware", "foo", "--max-seconds", "1"},
       2,
       {"--firmware", "foo"}},
      {{"sim-controller", "--robot", "linear_delta", "--faults", "bogus=0.5", "--max-seconds", "1"},
       2,
       {"--faults", "bogus", "unknown kind"}},
  });
}

TEST_F(CliRefusals, AnUnknownCommandIsNamedWithTheCommands) {
  expect_refused({
      {{"frobnicate"}, 2, {"unknown command 'frobnicate'", "measure", "identify", "wizard"}},
      {{"frobnicate", "--help"}, 2, {"unknown command 'frobnicate'"}},
  });
}

TEST_F(CliRefusals, ConflictingOptionsAreRefused) {
  expect_refused({
      {{"identify", "--robot", robot, "--measurements", file("m.yaml"), "--priors", "--no-priors"},
       2,
       {"--priors", "--no-priors"}},
  });
}

TEST_F(CliRefusals, OptionsOfAnotherModeAreRefusedNotIgnored) {
  const std::string s = session();
  expect_refused({
      {{"identify", s, "--measurements", file("m.yaml")}, 2, {"--measurements", "SESSION"}},
      {{"identify", s, "--kfold", "5"}, 2, {"--kfold", "does not apply", "SESSION"}},
      {{"identify", s, "--holdout-every", "4"}, 2, {"--holdout-every", "SESSION"}},
      {{"identify", s, "--kfold", "5", "--holdout-every", "4"},
       2,
       {"--kfold, --holdout-every do not apply"}},
      {{"measure", s, "--rig", file("rig.json")}, 2, {"--rig", "SESSION"}},
      {{"measure", s, "--target", target}, 2, {"--target", "SESSION"}},
      {{"identify", "--robot", robot, "--measurements", file("m.yaml"), "--route", "pose"},
       2,
       {"--route", "--measurements"}},
      {{"identify", "--robot", robot, "--measurements", file("m.yaml"), "--no-priors"},
       2,
       {"--no-priors"}},
      {{"measure", "--rig", file("rig.json"), "--target", target, "--poses", dir.string(), "--json",
        file("m.json")},
       2,
       {"--json", "SESSION"}},
  });
}

TEST_F(CliRefusals, SimControllerValuesOutOfRangeNameTheOption) {
  const std::vector<std::string> sim = {"sim-controller", "--robot", "linear_delta",
                                        "--max-seconds", "1"};
  const auto with = [&sim](const std::vector<std::string>& more) {
    std::vector<std::string> args = sim;
    args.insert(args.end(), more.begin(), more.end());
    return args;
  };
  expect_refused({
      {with({"--tcp-port", "99999"}), 2, {"--tcp-port", "99999"}},
      {with({"--pose-port", "70000"}), 2, {"--pose-port"}},
      {with({"--steps-per-mm", "-80"}), 2, {"--steps-per-mm"}},
      {with({"--steps-per-degree", "-1"}), 2, {"--steps-per-degree"}},
      {with({"--noise", "-1e-6"}), 2, {"--noise"}},
      {with({"--backlash", "-1e-6"}), 2, {"--backlash"}},
  });
}

// Keys a file does not know are refused at their line with the keys allowed there: a misspelled
// optional key (target_mount) would otherwise be ignored, and the run fail later for another
// reason.
TEST_F(CliRefusals, UnknownKeysOfSessionAndAnswersFilesAreNamed) {
  const std::string s = session();
  std::ofstream(dir / "session" / "session.yaml")
      << "format: robocal-session-1\n"
         "robot:\n"
         "  file: robot.yaml\n"
         "  name: linear_delta\n"
         "  actuators: 3\n"
         "  target_mont: {tool.z: 0.01}\n"
         "cameras:\n"
         "  - {name: cam0, width: 640, height: 480}\n"
         "targets: {end_effector: ee.yaml, calibration: cal.yaml}\n"
         "folders: {intrinsics: i, rig: r, poses: p}\n";
  std::ofstream(dir / "answers.yaml") << "robot:\n  model: linear_delta\nplan:\n  cuont: 6\n";
  expect_refused({
      {{"measure", s},
       3,
       {"session.yaml:6: unknown key 'target_mont'", "allowed:", "target_mount"}},
      {{"identify", s}, 3, {"session.yaml:6: unknown key 'target_mont'"}},
      {{"wizard", file("wizard_run"), "--answers", file("answers.yaml")},
       3,
       {"answers.yaml: unknown key 'plan.cuont'", "plan.count"}},
  });
  EXPECT_FALSE(fs::exists(dir / "wizard_run"));
}

// Millimetres among metres, degrees among radians: the file is refused at the value's line with
// the likely cause, by `kin check` and by every command that reads the file.
TEST_F(CliRefusals, RobotAndCellValuesInTheWrongUnitsAreRefused) {
  const std::string mm_length = edited("robots/linear_delta.yaml", "mm_length.yaml",
                                       {"params: {y: 0.174}", "params: {y: 174}"});
  const std::string mm_limits = edited("robots/linear_delta.yaml", "mm_limits.yaml",
                                       {"limits: [0.0, 0.45]", "limits: [0.0, 450]"});
  const std::string degree_limits = edited("robots/rotary_delta.yaml", "degree_limits.yaml",
                                           {"limits: [-pi/3, pi/2]", "limits: [-60, 90]"});
  const std::string degree_angle = edited(
      "robots/rotary_delta.yaml", "degree_angle.yaml",
      {"params: {a1: -pi/2, a2: 2*pi/3, d1: 0.2805}", "params: {a1: -90, a2: 2*pi/3, d1: 0.2805}"});
  fs::copy(testdata + "/cells/linear_delta", dir / "cell", fs::copy_options::recursive);
  std::ofstream(dir / "cell" / "cell.yaml")
      << replaced(read_text(testdata + "/cells/linear_delta/cell.yaml"),
                  "rpy: [1.570796326795, 3.141592653590, 1.570796326795]", "rpy: [90, 180, 90]");
  expect_refused({
      {{"kin", "check", mm_length}, 3, {"mm_length.yaml:", "tower_c.y", "174", "millimetres"}},
      {{"kin", "check", mm_limits},
       3,
       {"mm_limits.yaml:", "carriage_a", "limit", "450", "millimetres"}},
      {{"kin", "check", degree_limits},
       3,
       {"degree_limits.yaml:", "limit", "-60", "degrees", "deg(-60)"}},
      {{"kin", "check", degree_angle}, 3, {"degree_angle.yaml:", "a1", "-90", "degrees"}},
      {{"kin", "fk", degree_limits, "--actuators", "0,0,0"}, 3, {"degrees"}},
      {{"plan", "--cell", file("cell/cell.yaml"), "--robot", robot, "--out", file("p.yaml")},
       3,
       {"cell.yaml:", "target.rpy", "90", "degrees"}},
  });
}

// The measurements file route refuses what the session route refuses, in its words: rotation
// vectors written in degrees under `angle: rad` fit 57x beyond their stated noise. No calibrated
// robot file is written unless the user accepts the fit.
TEST_F(CliRefusals, AnImplausibleFitFromAMeasurementsFileIsRefused) {
  const CliRun sim = robocal::test::run_robocal_captured(
      {"identify", "--robot", robot, "--simulate", file("m.yaml"), "--kind", "pose", "--poses",
       "30", "--json", file("sim.json")});
  ASSERT_EQ(sim.code, 0) << sim.err;
  std::ofstream(file("degrees.yaml")) << rotation_vectors_in_degrees(read_text(file("m.yaml")));
  const std::vector<std::string> identify = {"identify",
                                             "--robot",
                                             robot,
                                             "--measurements",
                                             file("degrees.yaml"),
                                             "--out-robot",
                                             file("calibrated.yaml")};
  expect_refused({{identify,
                   1,
                   {"identification failed: the fit residuals of the pose rotation measurements",
                    "their stated noise", "the model cannot explain the measurements"}}});
  EXPECT_FALSE(fs::exists(file("calibrated.yaml")));
  // Accepted by the user: written (the linear delta's positions hardly depend on the rotation
  // vectors, so the calibrated model still predicts them better than the nominal one), and the
  // report says it was overridden.
  std::vector<std::string> accepted = identify;
  accepted.insert(accepted.end(), {"--accept-implausible", "--json", file("r.json")});
  const CliRun r = robocal::test::run_robocal_captured(accepted);
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(file("calibrated.yaml")));
  EXPECT_NE(read_text(file("r.json")).find("\"overridden\": true"), std::string::npos);
}

// The UR5's rotation vectors in degrees lead its fit astray: the calibrated model predicts the
// measured positions worse than the nominal one (6.9 mm RMS -> 34 mm). Such a model is never
// written as a calibrated robot, even when the user overrides the fit gate; the report says why.
TEST_F(CliRefusals, AFitWorseThanTheNominalModelIsNeverWritten) {
  const std::string ur5 = testdata + "/robots/ur5.yaml";
  const CliRun sim = robocal::test::run_robocal_captured(
      {"identify", "--robot", ur5, "--simulate", file("m.yaml"), "--kind", "pose", "--poses", "30",
       "--json", file("sim.json")});
  ASSERT_EQ(sim.code, 0) << sim.err;
  std::ofstream(file("degrees.yaml")) << rotation_vectors_in_degrees(read_text(file("m.yaml")));
  const CliRun r = robocal::test::run_robocal_captured(
      {"identify", "--robot", ur5, "--measurements", file("degrees.yaml"), "--out-robot",
       file("calibrated.yaml"), "--accept-implausible", "--json", file("r.json")});
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("worse than the nominal one"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(file("calibrated.yaml")));
  const std::string report = read_text(file("r.json"));
  EXPECT_NE(report.find("\"overridden\": true"), std::string::npos) << report;
  EXPECT_NE(report.find("\"nominal_gate\""), std::string::npos);
  EXPECT_NE(report.find("\"status\": \"implausible\""), std::string::npos);
}

// The session route's nominal gate (stages/identify.cpp, also called by the file route): an
// estimate that predicts the measured positions worse than the nominal model it started from is
// refused, whatever the fit gate said; one that predicts them better passes.
TEST(NominalGate, AnEstimateWorseThanTheNominalModelIsRefused) {
  const robocal::calib::Mechanism model = robocal::calib::load_robot_file(
      std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  const robocal::calib::MechanismPredictor predictor(model);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  Eigen::VectorXd truth = nominal;
  std::size_t rod = model.parameters.size();
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (model.parameters[i].name == "rod_a.length") rod = i;
  ASSERT_LT(rod, model.parameters.size());
  truth[static_cast<Eigen::Index>(rod)] += 0.001;  // the real rod is 1 mm longer
  std::vector<robocal::calib::PoseMeasurement> poses;
  for (const double h : {0.25, 0.28, 0.31, 0.34}) {
    robocal::calib::PoseMeasurement p;
    p.id = "pose_" + std::to_string(poses.size());
    p.actuators = Eigen::Vector3d(h, h + 0.02, h - 0.015);
    robocal::calib::FramePrediction f;
    std::string why;
    ASSERT_TRUE(predictor.predict(truth, p.actuators, -1, false, f, why)) << why;
    p.observations.emplace_back(
        robocal::calib::PointObservation::with_sigma(f.pose.translation(), 1e-5));
    poses.push_back(p);
  }
  robocal::app::PipelineLog quiet;
  quiet.out = nullptr;
  robocal::calib::IdentificationResult fit;
  // Led astray: the rod 10 mm the wrong way.
  fit.estimate = nominal;
  fit.estimate[static_cast<Eigen::Index>(rod)] -= 0.01;
  nlohmann::json report = {{"status", "ok"}};
  EXPECT_FALSE(robocal::app::apply_nominal_gate(predictor, nominal, fit, poses, "pose route",
                                                report, quiet));
  EXPECT_EQ(report["status"], "implausible");
  EXPECT_NE(report.value("message", "").find("worse than the nominal one"), std::string::npos)
      << report.dump(2);
  EXPECT_FALSE(report["nominal_gate"]["passed"].get<bool>());
  // The truth itself: better than the nominal model.
  fit.estimate = truth;
  report = {{"status", "ok"}};
  EXPECT_TRUE(robocal::app::apply_nominal_gate(predictor, nominal, fit, poses, "pose route", report,
                                               quiet));
  EXPECT_EQ(report["status"], "ok");
  EXPECT_TRUE(report["nominal_gate"]["passed"].get<bool>());
}

// A good fit passes the nominal gate: the calibrated model predicts the measurements better than
// the nominal one, and is written.
TEST_F(CliRefusals, AFitBetterThanTheNominalModelIsWritten) {
  const CliRun sim = robocal::test::run_robocal_captured(
      {"identify", "--robot", robot, "--simulate", file("m.yaml"), "--kind", "pose", "--poses",
       "30", "--json", file("sim.json")});
  ASSERT_EQ(sim.code, 0) << sim.err;
  const CliRun r = robocal::test::run_robocal_captured(
      {"identify", "--robot", robot, "--measurements", file("m.yaml"), "--out-robot",
       file("calibrated.yaml"), "--json", file("r.json")});
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(file("calibrated.yaml")));
  EXPECT_NE(read_text(file("r.json")).find("\"passed\": true"), std::string::npos);
}

// Readings near a singularity of the rotary Delta, where the loops close on more than one
// assembly mode: the JSON's status is "ambiguous", never "converged" with exit 0.
TEST_F(CliRefusals, AnAmbiguousForwardAnswerIsNoSuccess) {
  const std::vector<std::string> fk = {"kin", "fk", testdata + "/robots/rotary_delta.yaml",
                                       "--actuators", "0.9,0,0.2"};
  expect_refused({{fk, 1, {"assembly mode ambiguous", "move away from the singularity"}}});
  const CliRun r = robocal::test::run_robocal_captured(fk);
  EXPECT_NE(r.out.find("\"status\": \"ambiguous\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"verdict\": \"ambiguous\""), std::string::npos) << r.out;
}

// A robot file that cannot assemble over its actuator range (rods of 0.05 m for 0.27 m, of
// 0.1 m for 0.9 m) is the user's mistake: named with the cause (exit 3), never an internal
// error; nothing written.
TEST_F(CliRefusals, ARobotThatCannotAssembleIsNamedNotAnInternalError) {
  std::string short_rods = read_text(testdata + "/robots/rotary_delta.yaml");
  for (std::size_t at = 0; (at = short_rods.find("d1: 0.9}", at)) != std::string::npos;)
    short_rods.replace(at, 8, "d1: 0.1}");
  std::ofstream(dir / "short_rods.yaml") << short_rods;
  std::string linear = read_text(robot);
  for (std::size_t at = 0; (at = linear.find("length: 0.27}", at)) != std::string::npos;)
    linear.replace(at, 13, "length: 0.05}");
  std::ofstream(dir / "short_linear.yaml") << linear;
  std::string sliver = read_text(robot);
  for (std::size_t at = 0; (at = sliver.find("limits: [0.0, 0.45]", at)) != std::string::npos;)
    sliver.replace(at, 19, "limits: [0.3, 0.3005]");
  std::ofstream(dir / "sliver.yaml") << sliver;
  expect_refused({
      {{"simulate", "--robot", file("short_linear.yaml"), "--quick", "--out", file("s")},
       3,
       {"short_linear.yaml", "too few reachable configurations", "cannot assemble"}},
      {{"plan", "--cell", testdata + "/cells/rotary_delta/cell.yaml", "--robot",
        file("short_rods.yaml"), "--count", "10", "--out", file("p.yaml")},
       3,
       {"short_rods.yaml", "cannot assemble"}},
      // The linear delta's loops close nowhere in the cell: refused with the file it read, the
      // cause and readings where it failed, not only the robot's name.
      {{"plan", "--cell", testdata + "/cells/linear_delta/cell.yaml", "--robot",
        file("short_linear.yaml"), "--count", "10", "--out", file("p.yaml")},
       3,
       {file("short_linear.yaml"), "robot 'linear_delta' cannot assemble",
        "e.g. at actuator readings [", "kin check " + file("short_linear.yaml")}},
      // Carriages that move half a millimetre (limits a typo away from the drawing's): a
      // session of no poses was written with exit code 0.
      {{"simulate", "--robot", file("sliver.yaml"), "--quick", "--out", file("s2")},
       3,
       {"sliver.yaml", "too few reachable configurations", "joint limits"}},
      // A simulated controller of it would announce itself ready and have no pose to report.
      {{"sim-controller", "--robot", file("short_linear.yaml"), "--no-pty", "--max-seconds", "1"},
       3,
       {"short_linear.yaml", "cannot assemble at its home position", "kin check"}},
  });
}

}  // namespace
