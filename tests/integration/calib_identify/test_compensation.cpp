// Compensation checked on a simulated true robot with a known perturbation:
//  - a G-code program with arcs, relative moves and G92, rewritten for the nominal controller,
//    then executed as that controller does (straight lines in its model, its inverse kinematics)
//    on the true geometry: the tool follows the program's meant path within the tolerance, where
//    the original program misses it by the perturbation's size;
//  - held-out targets: a model identified from simulated measurements, its compensated commands
//    executed through the nominal controller on the truth, against the model's own held-out error.
#include "printer_scenario.hpp"

#include "robocal/calib/compensation.hpp"
#include "robocal/calib/firmware_delta.hpp"
#include "robocal/calib/gcode_program.hpp"
#include "robocal/calib/identification.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/input_error.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace robocal::calib {
namespace {

Mechanism linear_delta() {
  return load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
}

double distance_to_polyline(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& line) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k + 1 < line.size(); ++k) {
    const Eigen::Vector3d d = line[k + 1] - line[k];
    const double len2 = d.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((p - line[k]).dot(d) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, (line[k] + t * d - p).norm());
  }
  if (line.size() == 1) best = (p - line[0]).norm();
  return best;
}

// The tool positions a controller that knows only `models.nominal` produces on the robot `truth`
// when it runs `program`: it interpolates straight lines in its model (sampled every 0.2 mm) and
// drives the actuators by its inverse kinematics.
std::vector<Eigen::Vector3d> run_on_robot(const GcodeProgram& program,
                                          const CompensationModels& models,
                                          const Eigen::VectorXd& truth) {
  std::vector<Eigen::Vector3d> tool;
  for (const auto& p : gcode_path(program, 0.2e-3)) {
    Eigen::Vector3d reached;
    std::string why;
    if (!executed_position(models, truth, p.position, reached, why)) {
      ADD_FAILURE() << "line " << p.line << ": " << why;
      return tool;
    }
    tool.push_back(reached);
  }
  return tool;
}

std::vector<Eigen::Vector3d> positions(const std::vector<GcodePathPoint>& path) {
  std::vector<Eigen::Vector3d> out;
  out.reserve(path.size());
  for (const auto& p : path) out.push_back(p.position);
  return out;
}

// Largest distance from the executed tool positions to the meant path, and from the meant path
// to the executed one (a skipped move shows in the second).
double path_error(const std::vector<Eigen::Vector3d>& tool,
                  const std::vector<Eigen::Vector3d>& meant) {
  double worst = 0.0;
  for (const auto& p : tool) worst = std::max(worst, distance_to_polyline(p, meant));
  for (const auto& p : meant) worst = std::max(worst, distance_to_polyline(p, tool));
  return worst;
}

const char* const kProgram = R"(; a small part: straight, arcs (I/J and R), relative moves, G92
G21
G90
M83 ; relative extrusion
G28 ; home
G1 X0 Y0 Z50 F3000
G1 X60 Y0 Z50 E2.5 ; a long straight move
G3 X0 Y60 I-60 J0 E3.1 (quarter circle, counter-clockwise)
G91
G1 X-30 Y-30 Z5 F1200
G2 X20 Y0 R15 E0.8
G90
M83 ; G90 also made extrusion absolute (Marlin)
G92 X0 Y0
G1 X10 Y-90 F3000
G3 X10 Y-90 I0 J60 E9.4 ; full circle about the machine origin
G0 Z80
)";

TEST(Compensation, RewrittenProgramFollowsTheMeantPathOnTheTrueRobot) {
  const Mechanism model = linear_delta();
  std::mt19937 rng(20);
  const Eigen::VectorXd truth = test::printer_truth(model, rng);
  // The calibrated model here is the truth itself: the rewrite alone is under test.
  const CompensationModels models{&model, model.nominal_parameters(), truth};
  const GcodeProgram program = parse_gcode(kProgram, "part.gcode");
  GcodeRewriteOptions options;
  options.tolerance = 10e-6;
  const GcodeRewrite rewrite = rewrite_gcode(program, models, options);
  const GcodeProgram rewritten = parse_gcode(rewrite.text, "rewritten.gcode");

  const auto meant = positions(gcode_path(program, 0.2e-3));
  const double compensated = path_error(run_on_robot(rewritten, models, truth), meant);
  const double original = path_error(run_on_robot(program, models, truth), meant);
  RecordProperty("compensated_path_error_um", std::to_string(compensated * 1e6));
  RecordProperty("original_path_error_um", std::to_string(original * 1e6));
  EXPECT_LE(compensated, options.tolerance) << rewrite.text;
  EXPECT_GT(original, 20.0 * options.tolerance);  // the perturbation is visible without it
  EXPECT_GT(rewrite.stats.max_correction, 0.2e-3);
  EXPECT_EQ(rewrite.stats.moves, 8);
  EXPECT_GT(rewrite.stats.emitted_moves, rewrite.stats.moves);

  // Feeds, comments and modal lines are kept; arcs became straight pieces.
  EXPECT_NE(rewrite.text.find("F3000\n"), std::string::npos);
  EXPECT_NE(rewrite.text.find("; a long straight move"), std::string::npos);
  EXPECT_NE(rewrite.text.find("(quarter circle, counter-clockwise)"), std::string::npos);
  EXPECT_NE(rewrite.text.find("\nG91\n"), std::string::npos);
  EXPECT_NE(rewrite.text.find("\nG92 X0 Y0\n"), std::string::npos);
  EXPECT_EQ(rewrite.text.find("G2 "), std::string::npos);
  EXPECT_EQ(rewrite.text.find("G3 "), std::string::npos);
  // Extrusion is only redistributed: its sum (relative mode) is the program's.
  double e_total = 0.0;
  for (const auto& line : rewritten.lines)
    if (const GcodeWord* e = line.word('E')) e_total += e->value;
  EXPECT_NEAR(e_total, 2.5 + 3.1 + 0.8 + 9.4, 1e-4);
}

// The rotary Delta's controller has no Delta kinematics: its G-code axes are the three shoulders
// (degrees). A program meant in millimetres, rewritten for it, must put the true robot's tool on
// the meant path when the controller drives the shoulders along straight lines between the
// written angles; and every piece must take the time the program meant for it.
const char* const kDeltaProgram = R"(; a small part under the Delta
G21
G90
G28
G1 X0 Y0 Z-900 F3000
G1 X60 Y0 Z-900 ; a long straight move
G3 X0 Y60 I-60 J0 (quarter circle)
G91
G1 X-30 Y-30 Z-20 F1200
G90
G92 X0 Y0
G1 X10 Y-50
)";

// Axis values of every move of a rewritten program, in order, as the controller holds them
// (absolute), with the line's F when it has one.
struct AxisMove {
  Eigen::Vector3d values = Eigen::Vector3d::Zero();
  double feed = 0.0;  // 0: no F on the line
};
std::vector<AxisMove> axis_moves(const GcodeProgram& program, bool actuator_axes) {
  std::vector<AxisMove> moves;
  bool absolute = true;
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  for (const auto& line : program.lines) {
    if (line.command == "G90") absolute = true;
    if (line.command == "G91") absolute = false;
    if (line.command == "G92" && actuator_axes) {
      EXPECT_TRUE(line.word('X') == nullptr && line.word('Y') == nullptr &&
                  line.word('Z') == nullptr)
          << "line " << line.number << ": the controller's axes must not be redefined";
    }
    if (line.command != "G0" && line.command != "G1") continue;
    AxisMove m;
    for (int a = 0; a < 3; ++a) {
      const GcodeWord* w = line.word("XYZ"[a]);
      if (w == nullptr) continue;
      at[a] = absolute ? w->value : at[a] + w->value;
    }
    m.values = at;
    if (const GcodeWord* f = line.word('F')) m.feed = f->value;
    moves.push_back(m);
  }
  return moves;
}

TEST(Compensation, ARotaryDeltaProgramIsWrittenInShoulderAngles) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  ASSERT_EQ(model.controller.gcode_axes, GcodeAxes::kActuators);  // what its file says
  std::mt19937 rng(31);
  const Eigen::VectorXd truth = perturb_parameters(
      model.nominal_parameters(), tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  // The calibrated model is the truth itself: the rewrite alone is under test.
  const CompensationModels models{&model, model.nominal_parameters(), truth};
  const GcodeProgram program = parse_gcode(kDeltaProgram, "delta.gcode");
  GcodeRewriteOptions options;
  options.tolerance = 10e-6;
  options.axes = GcodeAxes::kActuators;
  const GcodeRewrite rewrite = rewrite_gcode(program, models, options);
  const GcodeProgram rewritten = parse_gcode(rewrite.text, "rewritten.gcode");
  const std::vector<AxisMove> moves = axis_moves(rewritten, true);
  ASSERT_GT(moves.size(), 6U) << rewrite.text;

  // The axis words are shoulder angles in degrees (the joint limits are -60..90 degrees), and
  // the true robot driven to them, and along the straight lines between them, stays on the
  // meant path.
  const auto meant = positions(gcode_path(program, 0.2e-3));
  double worst = 0.0;
  for (std::size_t k = 0; k < moves.size(); ++k) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(moves[k].values[a], -60.0 - 1e-6) << rewrite.text;
      EXPECT_LE(moves[k].values[a], 90.0 + 1e-6) << rewrite.text;
    }
    const Eigen::Vector3d to = moves[k].values * M_PI / 180.0;
    const Eigen::Vector3d from = k == 0 ? to : Eigen::Vector3d(moves[k - 1].values * M_PI / 180.0);
    for (const double t : {0.0, 0.2, 0.4, 0.5, 0.6, 0.8, 1.0}) {
      const Eigen::VectorXd r = from + t * (to - from);
      const ForwardResult fk = forward_kinematics(model, truth, r, model.task.frame);
      ASSERT_TRUE(fk.closure.ok()) << "move " << k;
      worst = std::max(worst, distance_to_polyline(fk.pose.translation(), meant));
    }
  }
  RecordProperty("path_error_um", std::to_string(worst * 1e6));
  // The tolerance, plus the angles' rounding (1e-5 degree at arms of 0.6 m and rods of 0.9 m).
  EXPECT_LE(worst, options.tolerance + 0.5e-6);
  // Straight lines in the shoulders are not straight for the tool: the moves were divided.
  EXPECT_GT(rewrite.stats.emitted_moves, rewrite.stats.moves + 5);
  // The first point was 0.9 m below the base: read as degrees, X0 Y0 Z-900 would be far outside
  // the shoulders' range, so it was not copied.
  EXPECT_EQ(rewrite.text.find("Z-900"), std::string::npos);

  // Feeds: each piece takes the program's time, its meant length at the program's F.
  int checked = 0;
  const auto tool_at = [&](const Eigen::Vector3d& degrees) -> Eigen::Vector3d {
    const Eigen::VectorXd q = degrees * M_PI / 180.0;
    const ForwardResult fk = forward_kinematics(model, truth, q, model.task.frame);
    EXPECT_TRUE(fk.closure.ok());
    return fk.pose.translation();
  };
  for (std::size_t k = 1; k < moves.size(); ++k) {
    if (moves[k].feed <= 0.0) continue;
    const double axes_minutes = (moves[k].values - moves[k - 1].values).norm() / moves[k].feed;
    const double tool_mm = (tool_at(moves[k].values) - tool_at(moves[k - 1].values)).norm() * 1e3;
    // The program's feed: 3000 mm/min up to the relative move, 1200 after it. The written
    // angles put the tool on the meant path to the tolerance, so the piece's meant length is
    // its true chord to twice that.
    const double length_error = std::min(std::abs(axes_minutes * 3000.0 - tool_mm),
                                         std::abs(axes_minutes * 1200.0 - tool_mm));
    EXPECT_LT(length_error, 2.0 * options.tolerance * 1e3 + 1e-3) << "move " << k;
    ++checked;
  }
  EXPECT_GT(checked, 5);

  // Written for a controller that reads X Y Z as the tool position, the same program stays in
  // millimetres; a controller nobody described is refused.
  options.axes = GcodeAxes::kTool;
  const GcodeRewrite task_space = rewrite_gcode(program, models, options);
  const std::vector<AxisMove> task_moves =
      axis_moves(parse_gcode(task_space.text, "task.gcode"), false);
  ASSERT_FALSE(task_moves.empty());
  EXPECT_NEAR(task_moves.front().values.z(), -900.0, 5.0) << task_space.text;
  options.axes = GcodeAxes::kUnknown;
  EXPECT_THROW((void)rewrite_gcode(program, models, options), core::InputError);
}

// A printer running the delta settings `robocal export` fits (Klipper here) keeps what its smaller
// model cannot hold (tower tilts, towers off one circle: hundreds of um); a program rewritten for
// that printer, with the calibrated robot, follows its meant path to the tolerance. The printer
// is run as Klipper runs it: straight lines in its frame, carriage heights by its equation
// h_i = z + sqrt(L_i^2 - (x - R cos a_i)^2 - (y - R sin a_i)^2), reading = h_i - c_i.
TEST(Compensation, ProgramsForAPrinterRunningTheFittedSettingsFollowTheCalibratedRobot) {
  const Mechanism model = linear_delta();
  std::mt19937 rng(41);
  const Eigen::VectorXd truth = perturb_parameters(
      model.nominal_parameters(), tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  const FirmwareDeltaFit fit = fit_firmware_delta(model, truth, DeltaFirmware::kKlipper);
  ASSERT_GT(fit.residual_rms, 50e-6);  // more than the firmware's model holds
  const FirmwareController controller = firmware_delta_controller(model, truth, fit);
  const FirmwareDeltaModel& k = fit.model;
  const auto klipper_readings = [&](const Eigen::Vector3d& p) {
    Eigen::VectorXd r(3);
    for (std::size_t i = 0; i < 3; ++i) {
      const double dx = p.x() - k.delta_radius * std::cos(k.tower_angle[i]);
      const double dy = p.y() - k.delta_radius * std::sin(k.tower_angle[i]);
      r[static_cast<Eigen::Index>(i)] =
          p.z() + std::sqrt(k.arm_length[i] * k.arm_length[i] - dx * dx - dy * dy) -
          k.carriage_offset[i];
    }
    return r;
  };
  // The true robot's nozzle in the firmware's frame: p_firmware = Ry(pitch) Rx(roll) p + (x, y).
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(fit.frame.pitch, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(fit.frame.roll, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  const Eigen::Vector3d t(fit.frame.x, fit.frame.y, 0.0);
  const auto printed = [&](const GcodeProgram& p) {
    std::vector<Eigen::Vector3d> tool;
    for (const auto& point : gcode_path(p, 0.2e-3)) {
      const ForwardResult fk =
          forward_kinematics(model, truth, klipper_readings(point.position), model.tool);
      EXPECT_TRUE(fk.closure.ok()) << "line " << point.line;
      tool.emplace_back(R * fk.pose.translation() + t);
    }
    return tool;
  };
  const GcodeProgram program = parse_gcode(
      "G90\nG1 X0 Y0 Z50 F3000\nG1 X40 Y0\nG3 X0 Y40 I-40 J0\nG1 X-30 Y-30 Z60\n", "part.gcode");
  GcodeRewriteOptions options;
  options.tolerance = 10e-6;
  const CompensationModels models{&model, controller.controller, controller.calibrated};
  const GcodeRewrite rewrite = rewrite_gcode(program, models, options);
  const auto meant = positions(gcode_path(program, 0.2e-3));
  const double compensated =
      path_error(printed(parse_gcode(rewrite.text, "rewritten.gcode")), meant);
  const double settings_alone = path_error(printed(program), meant);
  RecordProperty("compensated_um", std::to_string(compensated * 1e6));
  RecordProperty("settings_alone_um", std::to_string(settings_alone * 1e6));
  EXPECT_LE(compensated, options.tolerance + 0.2e-6) << rewrite.text;  // + the 0.1 um rounding
  EXPECT_GT(settings_alone, 5.0 * options.tolerance);
}

TEST(Compensation, UnreachablePointIsNamedByItsLine) {
  const Mechanism model = linear_delta();
  const CompensationModels models{&model, model.nominal_parameters(), model.nominal_parameters()};
  const std::string text = "G90\nG1 X0 Y0 Z50\nG1 X400 Y0 Z50\n";
  try {
    (void)rewrite_gcode(parse_gcode(text, "far.gcode"), models);
    FAIL() << "no error";
  } catch (const core::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("far.gcode:3:"), std::string::npos) << e.what();
  }
  TaskTarget t;
  t.pose.translation() = Eigen::Vector3d(0.4, 0.0, 0.05);
  const CompensatedTarget c = compensate_target(models, t);
  EXPECT_EQ(c.verdict, TargetVerdict::kUnreachable);
  EXPECT_FALSE(c.usable());
  EXPECT_FALSE(c.problem.empty());
}

// A Delta target above the base: the loops close there only with the plate above the base (another
// assembly mode than the robot file declares), so no command is given, and the verdict says why.
TEST(Compensation, TargetOnlyOnAnotherAssemblyModeIsRefused) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  const CompensationModels models{&model, model.nominal_parameters(), model.nominal_parameters()};
  TaskTarget above;
  above.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.5);
  const CompensatedTarget c = compensate_target(models, above);
  EXPECT_EQ(c.verdict, TargetVerdict::kOtherMode);
  EXPECT_FALSE(c.usable());
  EXPECT_NE(c.problem.find("plate_below_base"), std::string::npos) << c.problem;
  // The same robot's nominal working position is fine.
  TaskTarget below;
  below.pose.translation() = Eigen::Vector3d(0.0, 0.0, -0.8);
  EXPECT_EQ(compensate_target(models, below).verdict, TargetVerdict::kOk);
}

// A model identified in the cameras' world with a board mounted on the tool frame, brought back
// into the robot file's frame: the same robot moved rigidly (the base placement undone), with the
// robot file's tool instead of the board.
TEST(Compensation, CalibratedModelInTheRobotFrameIsTheSameRobotMovedRigidly) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  const Eigen::VectorXd file = model.nominal_parameters();
  std::mt19937 rng(11);
  Eigen::VectorXd estimate =
      perturb_parameters(file, tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  const int base = model.body_index("body1");
  const int tool = model.tool;
  for (std::size_t i = 0; i < model.parameters.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    if (model.parameters[i].body == base) estimate[k] += 0.3 + 0.01 * static_cast<double>(i);
    if (model.parameters[i].body == tool) estimate[k] += 0.05;  // the board, not the tool
  }
  const Eigen::VectorXd local = calibrated_in_robot_frame(model, estimate, file, tool);
  // What the estimate says of the tool: its own geometry with the file's tool offset.
  Eigen::VectorXd estimate_tool = estimate;
  for (std::size_t i = 0; i < model.parameters.size(); ++i)
    if (model.parameters[i].body == tool)
      estimate_tool[static_cast<Eigen::Index>(i)] = file[static_cast<Eigen::Index>(i)];
  const Eigen::VectorXd q = Eigen::Vector3d(0.2, 0.35, 0.1);
  const auto world = forward_kinematics(model, estimate_tool, q, tool);
  const auto own = forward_kinematics(model, local, q, tool);
  ASSERT_TRUE(world.closure.ok() && own.closure.ok());
  const Eigen::Isometry3d world_T_base = frame_pose(model, estimate_tool, world.state, base);
  const Eigen::Isometry3d file_T_base = frame_pose(model, local, own.state, base);
  EXPECT_LT(
      (world_T_base * file_T_base.inverse() * own.pose.translation() - world.pose.translation())
          .norm(),
      1e-9);
  EXPECT_GT((world.pose.translation() - own.pose.translation()).norm(), 0.1);  // it did move
}

// The previous implementation of compensate_target, written out: the general IK (joint limits
// respected, the file's assembly mode enforced), then the nominal model's FK of its readings.
struct Reference {
  TargetVerdict verdict = TargetVerdict::kUnreachable;
  Eigen::Vector3d commanded = Eigen::Vector3d::Zero();
};
Reference general_solvers(const CompensationModels& models, const TaskTarget& target,
                          const IkSeed& seed = {}) {
  IkOptions options;
  options.respect_limits = true;
  const IkResult ik = solve_ik(*models.model, models.calibrated, target, seed, options);
  Reference out;
  if (ik.status == SolveStatus::kOtherMode || (ik.ok() && ik.mode.verdict == ModeVerdict::kOther)) {
    out.verdict = TargetVerdict::kOtherMode;
    return out;
  }
  if (!ik.ok()) return out;
  const ForwardResult fk = forward_kinematics(*models.model, models.nominal, ik.actuator_readings,
                                              models.model->task.frame, ik.passive);
  if (!fk.closure.ok() || fk.closure.mode.verdict == ModeVerdict::kOther) return out;
  out.commanded = fk.pose.translation();
  out.verdict =
      ik.mode.verdict == ModeVerdict::kAmbiguous ? TargetVerdict::kAmbiguous : TargetVerdict::kOk;
  return out;
}

// The reusable Compensator (Newton fast path, general solvers as fallback) against the general
// solvers on a perturbed Delta and a perturbed linear delta: the same verdict for every target
// (reachable ones sampled in the workspace, and points only another mode or nothing reaches),
// cold, warm from the previous target and through compensate_targets; its readings put the
// calibrated robot on the target (FK solved afresh) and its command is the nominal FK of them,
// both to 1e-9 m; and most answers come from the fast path (else this tests only the fallback).
TEST(Compensation, CompensatorAgreesWithTheGeneralSolvers) {
  for (const char* robot : {"rotary_delta", "linear_delta"}) {
    SCOPED_TRACE(robot);
    const Mechanism model =
        load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + robot + ".yaml");
    const Eigen::VectorXd nominal = model.nominal_parameters();
    std::mt19937 rng(23);
    const Eigen::VectorXd calibrated =
        perturb_parameters(nominal, tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
    const CompensationModels models{&model, nominal, calibrated};
    const MechanismPredictor predictor(model);
    std::vector<TaskTarget> targets;
    for (const auto& q : sample_actuators(predictor, {nominal, calibrated}, 120, rng)) {
      TaskTarget t;
      t.pose.translation() =
          forward_kinematics(model, calibrated, q, model.task.frame).pose.translation();
      targets.push_back(t);
    }
    ASSERT_GE(targets.size(), 100U);
    // Far outside, and above the base (a Delta reaches that only with the plate flipped up).
    for (const Eigen::Vector3d& p : {Eigen::Vector3d(3.0, 0.0, -0.5), Eigen::Vector3d(0, 0, 0.5),
                                     Eigen::Vector3d(0.0, 0.0, 5.0)}) {
      TaskTarget t;
      t.pose.translation() = p;
      targets.push_back(t);
    }
    Compensator cold(models), warm(models), ik_only(models);
    const std::vector<CompensatedTarget> listed = compensate_targets(models, targets);
    ASSERT_EQ(listed.size(), targets.size());
    IkSeed previous;
    int usable = 0;
    for (std::size_t k = 0; k < targets.size(); ++k) {
      SCOPED_TRACE(k);
      const TaskTarget& t = targets[k];
      const Reference reference = general_solvers(models, t);
      const CompensatedTarget c = cold.compensate(t);
      const CompensatedTarget w = warm.compensate(t, previous);
      EXPECT_EQ(c.verdict, reference.verdict) << c.problem;
      EXPECT_EQ(w.verdict, reference.verdict) << w.problem;
      EXPECT_EQ(listed[k].verdict, reference.verdict) << listed[k].problem;
      if (w.usable()) previous = {w.ik.actuator_q, w.ik.passive};
      // The calibrated IK alone reaches the target by the calibrated FK (checked below for the
      // full compensations), with compensate()'s readings and verdict.
      const IkResult ik = ik_only.calibrated_ik(t);
      EXPECT_EQ(ik.status, c.ik.status);
      EXPECT_EQ(ik.mode.verdict, c.ik.mode.verdict);
      if (c.usable()) {
        ASSERT_EQ(ik.actuator_readings.size(), c.ik.actuator_readings.size());
        EXPECT_LE((ik.actuator_readings - c.ik.actuator_readings).cwiseAbs().maxCoeff(), 1e-12);
        const ForwardResult by_ik =
            forward_kinematics(model, calibrated, ik.actuator_readings, model.task.frame);
        ASSERT_TRUE(by_ik.closure.ok());
        EXPECT_LE((by_ik.pose.translation() - t.pose.translation()).norm(), 1e-9);
      }
      for (const CompensatedTarget* a : {&c, &w, &listed[k]}) {
        if (!a->usable()) continue;
        const ForwardResult reached =
            forward_kinematics(model, calibrated, a->ik.actuator_readings, model.task.frame);
        ASSERT_TRUE(reached.closure.ok());
        EXPECT_LE((reached.pose.translation() - t.pose.translation()).norm(), 1e-9);
        const ForwardResult told =
            forward_kinematics(model, nominal, a->ik.actuator_readings, model.task.frame);
        ASSERT_TRUE(told.closure.ok());
        EXPECT_LE((told.pose.translation() - a->commanded.translation()).norm(), 1e-9);
        EXPECT_LE((reference.commanded - a->commanded.translation()).norm(), 1e-9);
      }
      usable += c.usable() ? 1 : 0;
    }
    EXPECT_GE(usable, 100);
    // Most answers from the fast path (the general solver remains the fallback).
    EXPECT_GE(cold.counts().fast_ik, usable * 9 / 10);
    EXPECT_GE(cold.counts().fast_fk, usable * 9 / 10);
    EXPECT_GE(warm.counts().fast_ik, usable * 9 / 10);
  }
}

// Targets where the perturbed Delta's loops are nearly singular (closure conditioning under the
// design check's band, 2.5 x the ambiguity threshold, where a perturbed model's loops can close in
// several configurations that all keep the declared invariants): the Compensator must judge them
// as the general solver does (ambiguous near the singularity; its design-branch check, answered
// or refused), not call them plainly reachable. Targets: the calibrated model's own tool positions
// on an 8^3 grid over the actuators' whole range, kept where its forward kinematics is in that
// band.
TEST(Compensation, CompensatorJudgesNearlySingularTargetsAsTheGeneralSolver) {
  const Mechanism model =
      load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/rotary_delta.yaml");
  const Eigen::VectorXd nominal = model.nominal_parameters();
  std::mt19937 rng(29);
  const Eigen::VectorXd calibrated =
      perturb_parameters(nominal, tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  const CompensationModels models{&model, nominal, calibrated};
  const double band = 2.5 * model.assembly_mode.min_conditioning;
  std::vector<TaskTarget> targets;
  int ambiguous_by_fk = 0;
  constexpr int kValues = 8;
  const auto value = [&](int actuator, int k) {
    const Body& b = model.bodies[static_cast<std::size_t>(model.actuated[actuator])];
    return b.limits.lower + (b.limits.upper - b.limits.lower) * k / (kValues - 1);
  };
  for (int i = 0; i < kValues; ++i)
    for (int j = 0; j < kValues; ++j)
      for (int k = 0; k < kValues; ++k) {
        const Eigen::Vector3d qa(value(0, i), value(1, j), value(2, k));
        const ForwardResult fk = forward_kinematics(
            model, calibrated, readings_from_joint_values(model, calibrated, qa), model.task.frame);
        if (!fk.closure.ok() || !fk.closure.mode.acceptable()) continue;
        const double c = fk.closure.mode.conditioning;
        if (c < 0.0 || c >= band) continue;
        ambiguous_by_fk += fk.closure.mode.verdict == ModeVerdict::kAmbiguous ? 1 : 0;
        TaskTarget t;
        t.pose.translation() = fk.pose.translation();
        targets.push_back(t);
      }
  // Enough of them, and some the forward kinematics itself calls ambiguous (else this test
  // could not see a verdict that ignores the conditioning).
  ASSERT_GE(targets.size(), 100U);
  ASSERT_GE(ambiguous_by_fk, 20);
  Compensator cold(models), warm(models);
  IkSeed previous;
  int ambiguous = 0;
  for (std::size_t k = 0; k < targets.size(); ++k) {
    SCOPED_TRACE(k);
    const TaskTarget& t = targets[k];
    const Reference reference = general_solvers(models, t);
    ambiguous += reference.verdict == TargetVerdict::kAmbiguous ? 1 : 0;
    const CompensatedTarget c = cold.compensate(t);
    EXPECT_EQ(c.verdict, reference.verdict) << c.problem;
    // Where the verdict is ambiguous the loops are at a singularity: the robot's own forward
    // kinematics has more than one answer there (the design's answer cannot be followed), so only
    // clear answers have one command to agree on.
    if (c.verdict == TargetVerdict::kOk && reference.verdict == TargetVerdict::kOk) {
      EXPECT_LE((reference.commanded - c.commanded.translation()).norm(), 1e-9);
    }
    // Warm from the previous target's answer (another part of the grid: Newton may carry the
    // seed to another branch, which the checks must catch as they do cold), against the general
    // solver from the same seed.
    const CompensatedTarget w = warm.compensate(t, previous);
    EXPECT_EQ(w.verdict, general_solvers(models, t, previous).verdict) << w.problem;
    if (w.usable()) previous = {w.ik.actuator_q, w.ik.passive};
    if (w.verdict == TargetVerdict::kOk) {
      const ForwardResult reached =
          forward_kinematics(model, calibrated, w.ik.actuator_readings, model.task.frame);
      ASSERT_TRUE(reached.closure.ok());
      EXPECT_LE((reached.pose.translation() - t.pose.translation()).norm(), 1e-9);
    }
  }
  EXPECT_GE(ambiguous, 20);
}

// Held-out targets: identify the perturbed printer from simulated 3-D point measurements, then
// command each held-out target through the nominal controller with compensation and measure where
// the true robot puts the tool.
TEST(Compensation, HeldOutTargetsThroughTheNominalControllerMatchTheCalibratedModel) {
  const Mechanism model = linear_delta();
  const MechanismPredictor predictor(model);
  std::mt19937 rng(7);
  const Eigen::VectorXd nominal = model.nominal_parameters();
  const Eigen::VectorXd truth =
      perturb_parameters(nominal, tolerance_sigmas(model, 0.5e-3, 0.2 * M_PI / 180.0), rng);
  const auto design = sample_actuators(predictor, {nominal, truth}, 60, rng);
  SimulationOptions sim;
  sim.position_sigma = 20e-6;
  const Measurements meas = simulate_measurements(predictor, truth, design, sim, rng);
  const IdentificationResult id =
      identify(predictor, nominal, meas, solve_options_from_model(model, false));
  ASSERT_TRUE(id.status == IdentificationStatus::kConverged) << id.message;

  const CompensationModels models{&model, nominal, id.estimate};
  const auto held_out = sample_actuators(predictor, {nominal, truth, id.estimate}, 100, rng);
  double calibrated_sq = 0.0, compensated_sq = 0.0, nominal_sq = 0.0;
  int n = 0;
  int n_nominal = 0;
  int refused = 0;  // targets whose calibrated readings leave the joint limits (sampled at edges)
  for (const auto& q : held_out) {
    const Eigen::Vector3d target =
        forward_kinematics(model, truth, q, model.task.frame).pose.translation();
    const Eigen::Vector3d calibrated =
        forward_kinematics(model, id.estimate, q, model.task.frame).pose.translation();
    TaskTarget t;
    t.pose.translation() = target;
    const CompensatedTarget c = compensate_target(models, t);
    if (!c.usable()) {
      EXPECT_EQ(c.verdict, TargetVerdict::kUnreachable) << c.problem;
      ++refused;
      continue;
    }
    Eigen::Vector3d executed, uncompensated;
    std::string why;
    ASSERT_TRUE(executed_position(models, truth, c.commanded.translation(), executed, why)) << why;
    calibrated_sq += (calibrated - target).squaredNorm();
    compensated_sq += (executed - target).squaredNorm();
    ++n;
    // Without compensation (where the nominal controller reaches the target at all).
    if (executed_position(models, truth, target, uncompensated, why)) {
      nominal_sq += (uncompensated - target).squaredNorm();
      ++n_nominal;
    }
  }
  ASSERT_GE(n, 80);
  EXPECT_LE(refused, 5);
  const double calibrated_rms = std::sqrt(calibrated_sq / n);
  const double compensated_rms = std::sqrt(compensated_sq / n);
  ASSERT_GT(n_nominal, 0);
  const double nominal_rms = std::sqrt(nominal_sq / n_nominal);
  RecordProperty("calibrated_rms_um", std::to_string(calibrated_rms * 1e6));
  RecordProperty("compensated_rms_um", std::to_string(compensated_rms * 1e6));
  RecordProperty("nominal_rms_um", std::to_string(nominal_rms * 1e6));
  EXPECT_LE(compensated_rms, 1.1 * calibrated_rms);
  EXPECT_LT(compensated_rms, 0.2 * nominal_rms);
}

}  // namespace
}  // namespace robocal::calib
