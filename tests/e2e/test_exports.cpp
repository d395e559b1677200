// End to end: exports of simulated sessions (`robocal demo --quick --route pose`) checked against
// the session's hidden truth (truth/truth.json), computed here through calib's forward kinematics
// on the true parameters, independently of the export code:
//  - linear delta, Klipper: nozzle targets commanded through the exported settings (Klipper's
//    documented inverse kinematics, written here) drive the TRUE robot; where its nozzle (the
//    robot file's tool, not the board) arrives, against where it was sent; and a program
//    rewritten by `robocal compensate --firmware klipper`, run through the same equations;
//  - UR5, URDF: link poses composed from urdfdom's joints; the board, base, camera and tool links
//    against the true board, the true base and the true camera;
//  - rotary Delta, `robocal compensate --gcode`: the axis words are shoulder angles; the true
//    robot driven along them reaches the meant path within the calibrated model's own error.
//
// Two things the cameras cannot see are taken in the identified model's convention
// (calib/EXPORTS.md, "The user's frames"), and only those:
//  - where the user's tool sits behind the board: the board's mount on the tool's body is
//    measured only where the robot turns the board (a translational robot's mount offset is one
//    direction with its base position; the UR5's mount along and about the flange's axis is one
//    with its last joint's d and zero). The true tool is taken where the true BOARD puts it
//    through the identified mount (`true_tool`): a tool placed at the board, or at the wrong side
//    of the mount, still shows;
//  - the UR5's base height and turn against its first joint's d and zero (`base_regauged`).
// Everything is compared from camera 0 (the frame the calibration measured in: no rotation of
// the robot's frames is left free) or, for the base, in the robot's own frame.
#include "run_robocal.hpp"
#include "session/results_files.hpp"
#include "session/results_layout.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism_predictor.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/core/files.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace robocal {
namespace {

namespace fs = std::filesystem;
constexpr auto& run = test::run_robocal_captured;

// One simulated session per robot. ROBOCAL_E2E_SESSIONS=DIR keeps the sessions in DIR and
// reuses those an earlier run made there (while changing the checks only).
fs::path session(const std::string& robot) {
  const char* keep = std::getenv("ROBOCAL_E2E_SESSIONS");
  const fs::path dir = (keep != nullptr ? fs::path(keep) : fs::temp_directory_path()) /
                       ("robocal_e2e_exports_" + robot);
  if (keep != nullptr && fs::exists(dir / "results" / "calibrated_robot.yaml")) return dir;
  fs::remove_all(dir);
  const test::CliRun r = run({"demo", "--quick", "--route", "pose", "--robot", robot, "--seed", "1",
                              "--out", dir.string()});
  EXPECT_EQ(r.code, 0) << r.err;
  return dir;
}

struct Truth {
  calib::Mechanism model;    // the session's robot file
  Eigen::VectorXd file;      // its own values (the user's tool, the robot's own base)
  Eigen::VectorXd params;    // the true robot; its tool frame carries the board (as simulated)
  Eigen::VectorXd estimate;  // the identified robot (results/calibrated_robot.yaml)
  Eigen::Isometry3d camera_T_world = Eigen::Isometry3d::Identity();  // camera 0
  Eigen::Isometry3d board_T_tool = Eigen::Isometry3d::Identity();    // through the identified mount
};

// World pose of `body` at readings `r` (closures solved: the robot assembled).
Eigen::Isometry3d pose_at(const calib::Mechanism& m, const Eigen::VectorXd& params,
                          const Eigen::VectorXd& r, int body) {
  const calib::ForwardResult fk = calib::forward_kinematics(m, params, r, body);
  EXPECT_TRUE(fk.closure.ok());
  return fk.pose;
}

Truth truth_of(const fs::path& dir) {
  Truth t;
  t.model = calib::load_robot_file((dir / "robot.yaml").string());
  t.file = t.model.nominal_parameters();
  const app::TruthFile truth = app::read_truth(app::ResultsLayout{dir}, t.model);
  t.params = truth.truth;
  t.camera_T_world = truth.cameras.at(0).camera_T_world;
  t.estimate = calib::load_robot_file((dir / "results" / "calibrated_robot.yaml").string())
                   .nominal_parameters();
  // The user's tool behind the board: the file's tool on the tool's body, the board where the
  // identification mounted it there.
  const int tool = t.model.tool;
  const int body = t.model.bodies[static_cast<std::size_t>(tool)].parent;
  Eigen::VectorXd user = t.estimate;
  for (std::size_t i = 0; i < t.model.parameters.size(); ++i)
    if (t.model.parameters[i].body == tool)
      user[static_cast<Eigen::Index>(i)] = t.file[static_cast<Eigen::Index>(i)];
  const Eigen::VectorXd r =
      calib::readings_from_joint_values(t.model, t.estimate, t.model.home_actuated());
  const calib::JointState state =
      calib::make_joint_state(t.model, t.estimate, r, t.model.home_passive());
  const Eigen::Isometry3d body_T_board =
      calib::frame_pose(t.model, t.estimate, state, body).inverse() *
      calib::frame_pose(t.model, t.estimate, state, tool);
  const Eigen::Isometry3d body_T_tool = calib::frame_pose(t.model, user, state, body).inverse() *
                                        calib::frame_pose(t.model, user, state, tool);
  t.board_T_tool = body_T_board.inverse() * body_T_tool;
  return t;
}

// The true board (the tool frame of the simulated truth) and the user's tool behind it.
Eigen::Isometry3d true_board(const Truth& t, const Eigen::VectorXd& r) {
  return pose_at(t.model, t.params, r, t.model.tool);
}
Eigen::Isometry3d true_tool(const Truth& t, const Eigen::VectorXd& r) {
  return true_board(t, r) * t.board_T_tool;
}

// The true base in the identified model's convention: the parameters named in `confounded` at
// their file values, the base moved so that `anchor_body` keeps its true world pose (and with
// it every body after it).
Eigen::Isometry3d base_regauged(const Truth& t, const std::vector<std::string>& confounded,
                                int anchor_body, const Eigen::VectorXd& r) {
  const Eigen::Isometry3d anchor = pose_at(t.model, t.params, r, anchor_body);
  Eigen::VectorXd out = t.params;
  for (const std::string& name : confounded) {
    const int i = t.model.parameter_index(name);
    EXPECT_GE(i, 0) << name;
    out[i] = t.file[i];
  }
  const Eigen::Isometry3d anchor_in_base =
      pose_at(t.model, out, r, 0).inverse() * pose_at(t.model, out, r, anchor_body);
  calib::set_fixed_frame_pose(t.model, out, 0, r, anchor * anchor_in_base.inverse());
  const Eigen::Isometry3d moved = pose_at(t.model, out, r, anchor_body);
  EXPECT_LT((moved.translation() - anchor.translation()).norm(), 1e-9);
  EXPECT_LT((moved.linear() - anchor.linear()).norm(), 1e-9);
  return pose_at(t.model, out, r, 0);
}

struct Stats {
  double rms = 0.0, max = 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  int n = 0;
  void add(const Eigen::Vector3d& e) {
    rms += e.squaredNorm();
    max = std::max(max, e.norm());
    mean += e;
    ++n;
  }
  void done() {
    rms = std::sqrt(rms / std::max(n, 1));
    mean /= std::max(n, 1);
  }
};

std::vector<Eigen::VectorXd> workspace(const Truth& t, std::size_t count) {
  const calib::MechanismPredictor predictor(t.model);
  std::mt19937 rng(17);
  return calib::sample_actuators(predictor, {t.params, t.file}, count, rng);
}

double distance_to_polyline(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& line);

// ---- linear delta, Klipper ----------------------------------------------------------------

struct KlipperTower {
  double x, y, arm, offset;  // m; carriage height = reading + offset
};

TEST(ExportsAgainstTruth, KlipperSettingsPutTheTrueNozzleWhereTheyAreSent) {
  const fs::path dir = session("linear_delta");
  const Truth t = truth_of(dir);
  const test::CliRun r = run({"export", dir.string(), "--format", "klipper", "--json", "-"});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const auto& s = j.at("settings");
  // Klipper's delta kinematics (klippy/kinematics/delta.py): tower i at delta_radius, angle_i;
  // the carriage height at the endstop is position_endstop_i + sqrt(arm_i² - delta_radius²).
  const double R = s.at("delta_radius").get<double>() * 1e-3;
  std::vector<KlipperTower> towers;
  for (int i = 0; i < 3; ++i) {
    const std::string k(1, "abc"[i]);
    const double angle = s.at("angle_" + k).get<double>() * M_PI / 180.0;
    const double arm = s.at("arm_length_" + k).get<double>() * 1e-3;
    const double endstop_height =
        s.at("position_endstop_" + k).get<double>() * 1e-3 + std::sqrt(arm * arm - R * R);
    towers.push_back({R * std::cos(angle), R * std::sin(angle), arm,
                      endstop_height - j.at("endstop_readings_m")[i].get<double>()});
  }
  // Klipper's inverse kinematics with these settings: the carriage readings for a nozzle target in
  // the firmware's frame; nullopt where a rod cannot reach it.
  const auto klipper_readings = [&](const Eigen::Vector3d& p) -> std::optional<Eigen::VectorXd> {
    Eigen::VectorXd readings(3);
    for (int i = 0; i < 3; ++i) {
      const KlipperTower& k = towers[static_cast<std::size_t>(i)];
      const double d2 = k.arm * k.arm - std::pow(p.x() - k.x, 2) - std::pow(p.y() - k.y, 2);
      if (d2 <= 0.0) return std::nullopt;
      readings[i] = p.z() + std::sqrt(d2) - k.offset;
    }
    return readings;
  };
  // The firmware frame in the robot's base frame: p_firmware = Ry(pitch) Rx(roll) p_base + (x, y).
  const auto& f = j.at("firmware_frame");
  const Eigen::Matrix3d Rf =
      (Eigen::AngleAxisd(f.at("pitch_rad").get<double>(), Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(f.at("roll_rad").get<double>(), Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  const Eigen::Vector3d tf(f.at("x_m").get<double>(), f.at("y_m").get<double>(), 0.0);

  // The exported camera in the robot's base frame (what links the firmware to the truth).
  const auto& cam = j.at("frames").at("camera0").at("pose");
  Eigen::Isometry3d base_T_camera = Eigen::Isometry3d::Identity();
  Eigen::Vector3d w;
  for (int k = 0; k < 3; ++k) {
    base_T_camera.translation()[k] = cam.at("translation_m")[k].get<double>();
    w[k] = cam.at("rotation_vector_rad")[k].get<double>();
  }
  base_T_camera.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();

  // Targets: where the true nozzle goes over the workspace (camera 0's frame).
  const std::vector<Eigen::VectorXd> configs = workspace(t, 2000);
  ASSERT_GT(configs.size(), 1000U);
  std::vector<Eigen::Vector3d> errors;
  std::vector<Eigen::Vector3d> targets;  // in the firmware's frame, for the compensated route
  Stats model;
  for (const Eigen::VectorXd& q : configs) {
    // Where a printer works and the settings were fitted: every rod sloping down from its
    // carriage by at least a tenth of its length (the firmware's equation has no other branch).
    const Eigen::Vector3d in_base =
        pose_at(t.model, t.params, q, 0).inverse() * true_tool(t, q).translation();
    bool printer = true;
    for (int i = 0; i < 3; ++i) printer = printer && q[i] - in_base.z() >= 0.1 * towers[0].arm;
    if (!printer) continue;
    const Eigen::Vector3d target = t.camera_T_world * true_tool(t, q).translation();
    const Eigen::Vector3d p = Rf * (base_T_camera * target) + tf;  // in the firmware's frame
    const std::optional<Eigen::VectorXd> sent_readings = klipper_readings(p);
    if (!sent_readings) continue;
    const Eigen::VectorXd& readings = *sent_readings;
    const Eigen::Vector3d reached = t.camera_T_world * true_tool(t, readings).translation();
    errors.push_back(reached - target);
    targets.push_back(p);
    // Where the identified model (identify's file, camera 0's world) says the nozzle arrives:
    // its own error against the truth is identification's, not the export's.
    const Eigen::Vector3d predicted =
        (pose_at(t.model, t.estimate, readings, t.model.tool) * t.board_T_tool).translation();
    model.add(reached - predicted);
  }
  Stats sent, shape;
  for (const auto& e : errors) sent.add(e);
  sent.done();
  model.done();
  for (const auto& e : errors) shape.add(e - sent.mean);
  shape.done();
  const double firmware_rms = j.at("residual_rms_m").get<double>();
  fmt::print(
      "klipper: sent->reached RMS {:.1f} um, max {:.1f} um over {}; mean ({:.1f}, {:.1f}, {:.1f}) "
      "um; about the mean RMS {:.1f} um; firmware residual against the calibrated model RMS "
      "{:.1f} um; the calibrated model's own error there: mean ({:.1f}, {:.1f}, {:.1f}) um, RMS "
      "{:.1f} um; base origin in the firmware frame x {:.3f} y {:.3f} mm\n",
      sent.rms * 1e6, sent.max * 1e6, sent.n, sent.mean.x() * 1e6, sent.mean.y() * 1e6,
      sent.mean.z() * 1e6, shape.rms * 1e6, firmware_rms * 1e6, model.mean.x() * 1e6,
      model.mean.y() * 1e6, model.mean.z() * 1e6, model.rms * 1e6, tf.x() * 1e3, tf.y() * 1e3);
  RecordProperty("nozzle_error_mean_um", std::to_string(sent.mean.norm() * 1e6));
  RecordProperty("nozzle_error_rms_um", std::to_string(sent.rms * 1e6));
  RecordProperty("firmware_residual_rms_um", std::to_string(firmware_rms * 1e6));
  EXPECT_GT(sent.n, 100);
  // Where the nozzle and the base are: the constant part (an export that took the board for the
  // nozzle would put it 205 mm off, one that took camera 0's frame for the base 1.25 m off),
  // beyond the calibrated model's own constant error (camera 0's frame as its quick calibration
  // realises it: up to 0.1 mm).
  // Over 1000 targets the firmware's residual (0.4-0.65 mm RMS, seeds 1-3) averages out to
  // 20-40 um about the mean it has over its own fit's workspace (zero).
  EXPECT_LT((sent.mean - model.mean).norm(), 0.1e-3);
  // What varies over the workspace is the firmware's own residual (its model is smaller), with
  // the calibrated model's error against the truth.
  EXPECT_LT(sent.rms, firmware_rms + 0.1e-3);

  // The same targets through `robocal compensate --firmware klipper --targets` (the firmware's
  // coordinates it should be sent instead, computed with robocal's full model), then through
  // Klipper's equations above to the true robot: where the nozzle arrives against the target.
  // The full model itself, as a controller would run it: the identified model's own error at the
  // configurations above (`model`).
  const fs::path target_file = dir / "held_out_targets.csv";
  std::string csv = "x,y,z\n";
  for (const auto& p : targets) csv += fmt::format("{:.9f},{:.9f},{:.9f}\n", p.x(), p.y(), p.z());
  core::write_file_atomic(target_file, csv);
  const test::CliRun ct =
      run({"compensate", dir.string(), "--firmware", "klipper", "--targets", target_file.string(),
           "--out", (dir / "held_out_commands.csv").string(), "--json", "-"});
  // A target the true robot reaches at the very end of a carriage's travel can lie a few µm
  // beyond the calibrated robot's limits: refused with its line (exit code 1), never sent.
  ASSERT_TRUE(ct.code == 0 || ct.code == 1) << ct.err;
  const auto rows = nlohmann::json::parse(ct.out).at("rows");
  ASSERT_EQ(rows.size(), targets.size());
  Stats compensated_targets;
  int refused = 0;
  for (std::size_t k = 0; k < targets.size(); ++k) {
    if (!rows[k].contains("commanded")) {
      ++refused;
      continue;
    }
    const auto& c = rows[k].at("commanded");
    const Eigen::Vector3d sent_p(c[0].get<double>(), c[1].get<double>(), c[2].get<double>());
    const std::optional<Eigen::VectorXd> readings = klipper_readings(sent_p);
    ASSERT_TRUE(readings) << "line " << k + 2 << ": Klipper cannot reach the compensated command";
    const Eigen::Vector3d reached =
        Rf * (base_T_camera * t.camera_T_world * true_tool(t, *readings).translation()) + tf;
    compensated_targets.add(reached - targets[k]);
  }
  compensated_targets.done();
  fmt::print(
      "printer three ways over {} held-out targets (RMS / max, um): Klipper's model with the "
      "exported settings {:.1f} / {:.1f}; robocal's full model {:.1f} / {:.1f}; the exported "
      "settings with compensated commands {:.1f} / {:.1f} ({} refused)\n",
      sent.n, sent.rms * 1e6, sent.max * 1e6, model.rms * 1e6, model.max * 1e6,
      compensated_targets.rms * 1e6, compensated_targets.max * 1e6, refused);
  RecordProperty("full_model_rms_um", std::to_string(model.rms * 1e6));
  RecordProperty("compensated_targets_rms_um", std::to_string(compensated_targets.rms * 1e6));
  EXPECT_EQ(ct.code == 0, refused == 0) << ct.err;
  EXPECT_LE(refused, static_cast<int>(targets.size()) / 100) << ct.err;
  // Compensation against the full model is exact to its IK tolerance (nanometres) and Klipper's
  // equations here do not round steps: the compensated commands leave the full model's own
  // error, whatever the settings' residual (hundreds of µm); 10 µm covers the two sets of
  // configurations differing by that residual.
  EXPECT_LT(compensated_targets.rms, model.rms + 10e-6);
  EXPECT_LT(compensated_targets.rms, sent.rms);

  // What the settings leave, `robocal compensate --firmware klipper` carries: a program in the
  // firmware's frame, rewritten, run by Klipper on the true robot (carriage heights by the
  // equation above at every 0.2 mm of its straight lines), against the path it meant.
  const fs::path program = dir / "part.gcode", out = dir / "part.klipper.gcode";
  core::write_file_atomic(program, "G90\nG1 X0 Y0 Z50 F3000\nG1 X40 Y0\nG3 X0 Y40 I-40 J0\n");
  const test::CliRun c = run({"compensate", dir.string(), "--firmware", "klipper", "--gcode",
                              program.string(), "--out", out.string()});
  ASSERT_EQ(c.code, 0) << c.err;
  const auto firmware_path = [&](const std::string& text) {
    std::vector<Eigen::Vector3d> points;  // the commanded points, absolute (G90), metres
    std::istringstream lines(text);
    for (std::string line; std::getline(lines, line);) {
      if (line.rfind("G1 ", 0) != 0) continue;
      Eigen::Vector3d v = points.empty() ? Eigen::Vector3d::Zero() : points.back();
      for (int a = 0; a < 3; ++a)
        if (const auto at = line.find(std::string(" ") + "XYZ"[a]); at != std::string::npos)
          v[a] = std::stod(line.substr(at + 2)) * 1e-3;
      points.push_back(v);
    }
    return points;
  };
  const auto run_on_truth = [&](const std::vector<Eigen::Vector3d>& commanded) {
    std::vector<Eigen::Vector3d> nozzle;  // in the firmware's frame
    for (std::size_t k = 1; k < commanded.size(); ++k) {
      const int n = std::max(1, static_cast<int>((commanded[k] - commanded[k - 1]).norm() / 2e-4));
      for (int step = 0; step <= n; ++step) {
        const Eigen::Vector3d p = commanded[k - 1] + (commanded[k] - commanded[k - 1]) * step / n;
        const std::optional<Eigen::VectorXd> readings = klipper_readings(p);
        EXPECT_TRUE(readings) << "the program's point " << p.transpose() << " is out of reach";
        if (!readings) continue;
        nozzle.emplace_back(
            Rf * (base_T_camera * t.camera_T_world * true_tool(t, *readings).translation()) + tf);
      }
    }
    return nozzle;
  };
  std::vector<Eigen::Vector3d> meant;
  for (int k = 0; k <= 400; ++k) meant.emplace_back(0.04 * k / 400.0, 0.0, 0.05);
  for (int k = 0; k <= 800; ++k)
    meant.emplace_back(0.04 * std::cos(M_PI / 2 * k / 800.0), 0.04 * std::sin(M_PI / 2 * k / 800.0),
                       0.05);
  const auto worst = [&](const std::vector<Eigen::Vector3d>& nozzle) {
    double most = 0.0;
    for (const auto& p : nozzle) most = std::max(most, distance_to_polyline(p, meant));
    return most;
  };
  const double compensated = worst(run_on_truth(firmware_path(core::read_text_file(out))));
  const double settings_alone = worst(
      run_on_truth({{0, 0, 0.05}, {0.04, 0, 0.05}, {0.04, 0, 0.05}}));  // the straight move alone
  fmt::print(
      "klipper program on the true robot: settings alone {:.1f} um (its straight move), "
      "compensated {:.1f} um off the meant path\n",
      settings_alone * 1e6, compensated * 1e6);
  RecordProperty("compensated_program_um", std::to_string(compensated * 1e6));
  EXPECT_LT(compensated, 0.1e-3);
  EXPECT_LT(compensated, settings_alone);
}

// ---- UR5, URDF ------------------------------------------------------------------------------

Eigen::Isometry3d pose_of(const urdf::Pose& o) {
  double x = 0, y = 0, z = 0, w = 1;
  o.rotation.getQuaternion(x, y, z, w);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(w, x, y, z).toRotationMatrix();
  T.translation() = Eigen::Vector3d(o.position.x, o.position.y, o.position.z);
  return T;
}

// Pose of every link in the URDF's root link for joint values by joint name.
std::map<std::string, Eigen::Isometry3d> urdf_link_poses(const urdf::ModelInterface& model,
                                                         const std::map<std::string, double>& q) {
  std::map<std::string, Eigen::Isometry3d> poses;
  std::vector<std::pair<urdf::LinkConstSharedPtr, Eigen::Isometry3d>> stack = {
      {model.getRoot(), Eigen::Isometry3d::Identity()}};
  while (!stack.empty()) {
    auto [link, pose] = stack.back();
    stack.pop_back();
    poses[link->name] = pose;
    for (const auto& j : link->child_joints) {
      Eigen::Isometry3d T = pose * pose_of(j->parent_to_joint_origin_transform);
      const Eigen::Vector3d axis(j->axis.x, j->axis.y, j->axis.z);
      const double v = q.count(j->name) ? q.at(j->name) : 0.0;
      if (j->type == urdf::Joint::PRISMATIC) T.translate(v * axis);
      if (j->type == urdf::Joint::REVOLUTE || j->type == urdf::Joint::CONTINUOUS)
        T.rotate(Eigen::AngleAxisd(v, axis));
      stack.emplace_back(model.getLink(j->child_link_name), T);
    }
  }
  return poses;
}

double angle_between(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

TEST(ExportsAgainstTruth, Ur5UrdfHasTheTrueFlangeAsToolAndTheRobotsOwnBase) {
  const fs::path dir = session("ur5");
  const Truth t = truth_of(dir);
  const test::CliRun r = run({"export", dir.string(), "--format", "urdf", "--json", "-"});
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const urdf::ModelInterfaceSharedPtr urdf = urdf::parseURDF(j.at("text").get<std::string>());
  ASSERT_TRUE(urdf);
  // No joint that MoveIt would read as unable to move.
  for (const auto& [name, joint] : urdf->joints_)
    if (joint->type != urdf::Joint::FIXED) {
      ASSERT_TRUE(joint->limits) << name;
      EXPECT_GT(joint->limits->velocity, 0.0) << name;
      EXPECT_GT(joint->limits->effort, 0.0) << name;
    }
  const std::vector<Eigen::VectorXd> configs = workspace(t, 60);
  ASSERT_GT(configs.size(), 30U);
  const Eigen::Isometry3d world_T_camera = t.camera_T_world.inverse();
  Stats board, tool, camera, own, model_board, model_tool;
  double turn = 0.0;
  for (const Eigen::VectorXd& q : configs) {
    std::map<std::string, double> values;
    for (std::size_t a = 0; a < t.model.actuated.size(); ++a)
      values[t.model.bodies[static_cast<std::size_t>(t.model.actuated[a])].name] =
          q[static_cast<Eigen::Index>(a)];
    const auto links = urdf_link_poses(*urdf, values);
    const Eigen::Isometry3d& camera0 = links.at("camera0");
    // From the camera (what the calibration measured): the board link is the true board, the
    // tool link the true flange.
    const Eigen::Isometry3d cam_board = camera0.inverse() * links.at("board");
    const Eigen::Isometry3d true_cam_board = t.camera_T_world * true_board(t, q);
    board.add(cam_board.translation() - true_cam_board.translation());
    turn = std::max(turn, angle_between(cam_board.linear(), true_cam_board.linear()));
    const Eigen::Isometry3d cam_tool = camera0.inverse() * links.at("tool");
    const Eigen::Vector3d true_cam_tool = (t.camera_T_world * true_tool(t, q)).translation();
    tool.add(cam_tool.translation() - true_cam_tool);
    // The identified model's own error there (identify's file: camera 0's world, the board).
    const Eigen::Isometry3d identified = pose_at(t.model, t.estimate, q, t.model.tool);
    model_board.add(identified.translation() - true_cam_board.translation());
    model_tool.add((identified * t.board_T_tool).translation() - true_cam_tool);
    // In the robot's own frame: the base link's camera and tool. The UR5's base height is one
    // direction with joint 1's d, its turn about z with joint 1's zero: the identified model
    // keeps the file's d and zero (identification.json says so) and carries both in its base.
    const Eigen::Isometry3d true_base =
        base_regauged(t, {"shoulder_pan.d", "shoulder_pan.theta", "shoulder_pan.encoder_offset"},
                      t.model.body_index("shoulder_pan"), q);
    const Eigen::Isometry3d& base = links.at("base");
    camera.add((base.inverse() * camera0).translation() -
               (true_base.inverse() * world_T_camera).translation());
    own.add((base.inverse() * links.at("tool")).translation() -
            (true_base.inverse() * true_tool(t, q)).translation());
  }
  for (Stats* st : {&board, &tool, &camera, &own, &model_board, &model_tool}) st->done();
  fmt::print(
      "ur5 urdf from camera0: board RMS {:.1f} max {:.1f} um, {:.3f} mrad; tool RMS {:.1f} max "
      "{:.1f} um (the identified model's own error: board RMS {:.1f} max {:.1f} um, tool max "
      "{:.1f} um); in the base frame: camera {:.1f} um, tool RMS {:.1f} max {:.1f} um\n",
      board.rms * 1e6, board.max * 1e6, turn * 1e3, tool.rms * 1e6, tool.max * 1e6,
      model_board.rms * 1e6, model_board.max * 1e6, model_tool.max * 1e6, camera.max * 1e6,
      own.rms * 1e6, own.max * 1e6);
  RecordProperty("board_from_camera_max_um", std::to_string(board.max * 1e6));
  RecordProperty("tool_from_camera_max_um", std::to_string(tool.max * 1e6));
  RecordProperty("camera_in_base_um", std::to_string(camera.max * 1e6));
  RecordProperty("tool_in_base_max_um", std::to_string(own.max * 1e6));
  // Seen from the true camera 0, the URDF is the identified model itself: its error against the
  // truth is the model's own, to rounding. (That error, ~0.1 mm RMS here, is mostly camera 0's
  // frame as its quick calibration realises it, 12 views per camera: validate's figures in the
  // calibrated camera frame are 30 um RMS. In the robot's own frame below it is gone.)
  EXPECT_LT(board.max, model_board.max + 1e-6);
  EXPECT_LT(tool.max, model_tool.max + 1e-6);
  EXPECT_LT(turn, 0.5e-3);
  // The robot's own frame: the camera link and the tool link where the truth has them.
  EXPECT_LT(camera.max, 0.1e-3);
  EXPECT_LT(own.max, 0.1e-3);
  // The tool link is the flange, not the board (the board is 20 cm across the flange's face).
  EXPECT_GT(t.board_T_tool.translation().norm(), 0.1);
}

// ---- rotary Delta, compensated G-code ------------------------------------------------------

// A program in the robot's base frame (mm): a square with a half circle, 0.9 m below the base.
const char* const kDeltaProgram = R"(G21
G90
G1 X-50 Y-50 Z-900 F3000
G1 X50 Y-50
G1 X50 Y50
G3 X-50 Y50 I-50 J0
G1 X-50 Y-50 Z-880
)";

std::vector<Eigen::Vector3d> meant_polyline() {
  // The program's meant path, sampled finely (straight lines and the half circle).
  std::vector<Eigen::Vector3d> pts;
  const auto line = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    for (int k = 0; k <= 200; ++k) pts.push_back(a + (b - a) * (k / 200.0));
  };
  const Eigen::Vector3d a(-0.05, -0.05, -0.9), b(0.05, -0.05, -0.9), c(0.05, 0.05, -0.9),
      d(-0.05, 0.05, -0.9);
  line(a, b);
  line(b, c);
  for (int k = 0; k <= 400; ++k) {  // centre (0, 0.05), from angle 0 to pi, counter-clockwise
    const double angle = M_PI * k / 400.0;
    pts.emplace_back(0.05 * std::cos(angle), 0.05 + 0.05 * std::sin(angle), -0.9);
  }
  line(d, Eigen::Vector3d(-0.05, -0.05, -0.88));
  return pts;
}

double distance_to_polyline(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& line) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k + 1 < line.size(); ++k) {
    const Eigen::Vector3d d = line[k + 1] - line[k];
    const double len2 = d.squaredNorm();
    const double u = len2 > 0.0 ? std::clamp((p - line[k]).dot(d) / len2, 0.0, 1.0) : 0.0;
    best = std::min(best, (line[k] + u * d - p).norm());
  }
  return best;
}

TEST(ExportsAgainstTruth, RotaryDeltaProgramIsWrittenInShoulderAnglesTheTrueRobotFollows) {
  const fs::path dir = session("rotary_delta");
  const Truth t = truth_of(dir);
  const fs::path program = dir / "square.gcode", out = dir / "square.robocal.gcode";
  core::write_file_atomic(program, kDeltaProgram);
  const test::CliRun r = run({"compensate", dir.string(), "--gcode", program.string(), "--out",
                              out.string(), "--tolerance", "10"});
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string text = core::read_text_file(out);
  EXPECT_NE(text.find("axis words are actuator positions"), std::string::npos) << text;
  // The calibrated model as identify wrote it (camera 0's world, the board as its tool), and the
  // same in the robot's own frames: base and tool at the file's values.
  const Eigen::VectorXd& estimate = t.estimate;
  Eigen::VectorXd own = estimate;
  for (std::size_t i = 0; i < t.model.parameters.size(); ++i) {
    const int body = t.model.parameters[i].body;
    if (body == 0 || body == t.model.tool)
      own[static_cast<Eigen::Index>(i)] = t.file[static_cast<Eigen::Index>(i)];
  }
  const Eigen::VectorXd home = Eigen::VectorXd::Zero(3);
  const Eigen::Isometry3d camera_T_base = pose_at(t.model, estimate, home, 0);

  // The axis words, as the controller holds them (absolute degrees), line by line.
  std::vector<Eigen::Vector3d> angles;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("G1 ", 0) != 0 && line.rfind("G0 ", 0) != 0) continue;
    Eigen::Vector3d v = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) {
      const auto at = line.find(std::string(" ") + "XYZ"[a]);
      ASSERT_NE(at, std::string::npos) << line;
      v[a] = std::stod(line.substr(at + 2));
    }
    angles.push_back(v);
  }
  ASSERT_GT(angles.size(), 5U) << text;
  const std::vector<Eigen::Vector3d> meant = meant_polyline();
  Stats model_error;
  double off_path = 0.0, worst_gap = 0.0;
  for (std::size_t k = 0; k < angles.size(); ++k) {
    for (int a = 0; a < 3; ++a) {  // the shoulders' range, -60..90 degrees
      EXPECT_GT(angles[k][a], -60.0) << k;
      EXPECT_LT(angles[k][a], 90.0) << k;
    }
    const Eigen::Vector3d to = angles[k] * M_PI / 180.0;
    const Eigen::Vector3d from = k == 0 ? to : Eigen::Vector3d(angles[k - 1] * M_PI / 180.0);
    for (const double u : {0.0, 0.25, 0.5, 0.75}) {
      const Eigen::VectorXd q = from + u * (to - from);
      // The calibrated model, driven along the written angles, is on the meant path ...
      const Eigen::Vector3d planned = pose_at(t.model, own, q, t.model.tool).translation();
      off_path = std::max(off_path, distance_to_polyline(planned, meant));
      // ... and the true robot is where the calibrated model says, to the model's own error
      // (compared from camera 0, the frame the calibration measured in).
      const Eigen::Vector3d truly = t.camera_T_world * true_tool(t, q).translation();
      const Eigen::Vector3d predicted = camera_T_base * planned;
      model_error.add(truly - predicted);
      worst_gap = std::max(worst_gap, distance_to_polyline(camera_T_base.inverse() * truly, meant));
    }
  }
  model_error.done();
  fmt::print(
      "rotary delta program: {} moves; calibrated model off the meant path {:.1f} um; true "
      "tool vs calibrated model RMS {:.1f} max {:.1f} um; true tool off the meant path max "
      "{:.1f} um\n",
      angles.size(), off_path * 1e6, model_error.rms * 1e6, model_error.max * 1e6, worst_gap * 1e6);
  RecordProperty("true_off_path_max_um", std::to_string(worst_gap * 1e6));
  EXPECT_LT(off_path, 10e-6 + 1e-6);  // the tolerance and the angles' rounding
  EXPECT_LE(worst_gap, model_error.max + off_path + 1e-9);
  EXPECT_LT(worst_gap, 0.1e-3);
}

}  // namespace
}  // namespace robocal
