// Serial-arm exports: URDF written by robocal, read back by urdfdom; forward kinematics
// of every link composed here from urdfdom's joints equals robocal's to 1e-9 m; the URDF imported
// back as a robot file gives the same tool; the DH table's printed numbers rebuild the model.
#include "../calib/calib_test_support.hpp"
#include "robocal/calib/compensation.hpp"
#include "robocal/calib/frame_placement.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/calib/serial_exports.hpp"

#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>
#include <Eigen/Geometry>

#include <cmath>
#include <map>
#include <numbers>
#include <random>
#include <sstream>

namespace robocal::calib {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

// A calibrated-looking robot: every parameter off its drawing (encoder scales kept at 1: URDF's
// joint value is the reading).
Eigen::VectorXd perturbed(const Mechanism& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd p = m.nominal_parameters();
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    if (m.parameters[i].group == ParamGroup::kEncoderScale) continue;
    p[static_cast<Eigen::Index>(i)] +=
        (m.parameters[i].unit == ParamUnit::kAngle ? 0.01 : 0.002) * n(rng);
  }
  return p;
}

Eigen::Isometry3d pose_of(const urdf::Pose& o) {
  double x = 0, y = 0, z = 0, w = 1;
  o.rotation.getQuaternion(x, y, z, w);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(w, x, y, z).toRotationMatrix();
  T.translation() = Eigen::Vector3d(o.position.x, o.position.y, o.position.z);
  return T;
}

// World pose of every link of a URDF for joint values by joint name, composed from urdfdom.
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

Eigen::VectorXd readings_of(const Mechanism& m, std::mt19937& rng) {
  Eigen::VectorXd r(static_cast<Eigen::Index>(m.actuated.size()));
  for (Eigen::Index i = 0; i < r.size(); ++i) r[i] = std::uniform_real_distribution(-1.5, 1.5)(rng);
  return r;
}

Eigen::Isometry3d body_pose(const Mechanism& m, const Eigen::VectorXd& p, const Eigen::VectorXd& r,
                            int body) {
  return frame_pose(m, p, make_joint_state(m, p, r, Eigen::VectorXd()), body);
}

class UrdfRoundTrip : public ::testing::TestWithParam<std::string> {};

TEST_P(UrdfRoundTrip, UrdfdomReadsTheSameRobotAndTheImportGivesItBack) {
  const Mechanism m = testing::load(GetParam());
  const Eigen::VectorXd p = perturbed(m, 3);
  const std::string xml = urdf_text(m, p);
  const urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(xml);
  ASSERT_TRUE(model) << xml;
  const Mechanism back =
      parse_robot_yaml(robot_yaml_from_urdf(xml, "exported.urdf"), "imported.yaml");
  ASSERT_EQ(back.actuated.size(), m.actuated.size());
  std::mt19937 rng(5);
  double worst = 0.0;
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::VectorXd r = readings_of(m, rng);
    std::map<std::string, double> q;
    for (std::size_t a = 0; a < m.actuated.size(); ++a)
      q[m.bodies[static_cast<std::size_t>(m.actuated[a])].name] = r[static_cast<Eigen::Index>(a)];
    const auto links = urdf_link_poses(*model, q);
    for (std::size_t b = 0; b < m.bodies.size(); ++b) {
      const Eigen::Isometry3d expected = body_pose(m, p, r, static_cast<int>(b));
      const Eigen::Isometry3d got = links.at(m.bodies[b].name);
      worst = std::max(worst, (got.translation() - expected.translation()).norm());
      EXPECT_LT((got.linear() - expected.linear()).norm(), 1e-9) << m.bodies[b].name;
    }
    const Eigen::Isometry3d tool_back = body_pose(back, back.nominal_parameters(), r, back.tool);
    const Eigen::Isometry3d tool = body_pose(m, p, r, m.tool);
    EXPECT_LT((tool_back.translation() - tool.translation()).norm(), 1e-9);
    EXPECT_LT((tool_back.linear() - tool.linear()).norm(), 1e-9);
  }
  EXPECT_LT(worst, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(SerialArms, UrdfRoundTrip,
                         ::testing::Values("ur5.yaml", "modular_arm.yaml"));

TEST(UrdfExport, JointLimitsCarryTheRobotFilesSpeedAndForceOrNamedDefaults) {
  // The UR5's file gives its data sheet's speed and torque: written per joint, never 0 (MoveIt
  // reads 0 as "cannot move").
  const Mechanism ur5 = testing::load("ur5.yaml");
  const urdf::ModelInterfaceSharedPtr a = urdf::parseURDF(urdf_text(ur5, ur5.nominal_parameters()));
  ASSERT_TRUE(a);
  const std::map<std::string, double> torque = {{"shoulder_pan", 150}, {"shoulder_lift", 150},
                                                {"elbow", 150},        {"wrist1", 28},
                                                {"wrist2", 28},        {"wrist3", 28}};
  for (const auto& [name, effort] : torque) {
    const urdf::JointConstSharedPtr j = a->getJoint(name);
    ASSERT_TRUE(j && j->limits) << name;
    EXPECT_DOUBLE_EQ(j->limits->velocity, std::numbers::pi) << name;
    EXPECT_DOUBLE_EQ(j->limits->effort, effort) << name;
    // Position limits from the file (readings = joint values: encoder offset 0, scale 1).
    const Body& b = ur5.bodies[static_cast<std::size_t>(ur5.body_index(name))];
    EXPECT_DOUBLE_EQ(j->limits->lower, b.limits.lower) << name;
    EXPECT_DOUBLE_EQ(j->limits->upper, b.limits.upper) << name;
  }
  // A file without ratings: the documented defaults, and a comment that says so.
  const Mechanism arm = testing::load("modular_arm.yaml");
  const std::string xml = urdf_text(arm, arm.nominal_parameters());
  const urdf::ModelInterfaceSharedPtr b = urdf::parseURDF(xml);
  ASSERT_TRUE(b);
  for (const int k : arm.actuated) {
    const Body& body = arm.bodies[static_cast<std::size_t>(k)];
    const urdf::JointConstSharedPtr j = b->getJoint(body.name);
    ASSERT_TRUE(j && j->limits) << body.name;
    const bool revolute = body.joint == JointType::kRevolute;
    EXPECT_DOUBLE_EQ(j->limits->velocity,
                     revolute ? kDefaultRevoluteVelocity : kDefaultPrismaticVelocity);
    EXPECT_DOUBLE_EQ(j->limits->effort,
                     revolute ? kDefaultRevoluteEffort : kDefaultPrismaticEffort);
  }
  EXPECT_NE(xml.find("the robot file gives no velocity/effort"), std::string::npos) << xml;
}

// An identified UR5 as identification leaves it: its base placed in a camera's frame, its tool
// frame's values replaced by the end-effector board's mount.
struct Identified {
  Mechanism model;
  Eigen::VectorXd file, estimate;
  Eigen::Isometry3d camera_T_base, flange_T_board;
};

Identified identified_ur5() {
  Identified id{testing::load("ur5.yaml"), {}, {}, {}, {}};
  id.file = id.model.nominal_parameters();
  id.estimate = perturbed(id.model, 11);
  id.camera_T_base = Eigen::Translation3d(0.3, -0.1, 1.2) *
                     Eigen::AngleAxisd(2.9, Eigen::Vector3d(0.2, 1.0, 0.1).normalized());
  id.flange_T_board = Eigen::Translation3d(-0.145, -0.145, 0.01) *
                      Eigen::AngleAxisd(3.14159, Eigen::Vector3d::UnitX());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(6);
  set_fixed_frame_pose(id.model, id.estimate, 0, zero, id.camera_T_base);
  const int tool = id.model.tool;
  const int wrist3 = id.model.bodies[static_cast<std::size_t>(tool)].parent;
  set_fixed_frame_pose(id.model, id.estimate, tool, zero,
                       body_pose(id.model, id.estimate, zero, wrist3) * id.flange_T_board);
  return id;
}

TEST(UserFrames, TheRobotsOwnBaseAndToolWithTheBoardAndTheCameraBeside) {
  const Identified id = identified_ur5();
  const Mechanism& m = id.model;
  const UserFrames user = user_frames(m, id.estimate, id.file, m.tool, true);
  // Base and tool at the file's values; everything between as identified.
  for (std::size_t i = 0; i < m.parameters.size(); ++i) {
    const int body = m.parameters[i].body;
    const bool own = body == 0 || body == m.tool;
    EXPECT_DOUBLE_EQ(
        user.params[static_cast<Eigen::Index>(i)],
        own ? id.file[static_cast<Eigen::Index>(i)] : id.estimate[static_cast<Eigen::Index>(i)])
        << m.parameters[i].name;
  }
  EXPECT_TRUE(user.world_T_measurement.isApprox(id.camera_T_base.inverse(), 1e-12));
  EXPECT_EQ(user.measured_parent, m.bodies[static_cast<std::size_t>(m.tool)].parent);
  EXPECT_TRUE(user.parent_T_measured.isApprox(id.flange_T_board, 1e-12));
  // At any readings, the board in the camera's frame is where the identified model puts it.
  std::mt19937 rng(2);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd r = readings_of(m, rng);
    const Eigen::Isometry3d identified = body_pose(m, id.estimate, r, m.tool);
    const Eigen::Isometry3d rebuilt = user.world_T_measurement.inverse() *
                                      body_pose(m, user.params, r, user.measured_parent) *
                                      user.parent_T_measured;
    EXPECT_LT((identified.translation() - rebuilt.translation()).norm(), 1e-12);
    EXPECT_LT((identified.linear() - rebuilt.linear()).norm(), 1e-12);
  }
}

TEST(UserFrames, UrdfAndDhCarryTheBoardAndTheCameraAsTheirOwnFrames) {
  const Identified id = identified_ur5();
  const Mechanism& m = id.model;
  const UserFrames user = user_frames(m, id.estimate, id.file, m.tool, true);
  const std::vector<ExtraFrame> extra = {
      {"board", user.measured_parent, user.parent_T_measured, "the measured board"},
      {"camera0", 0, user.world_T_measurement, "camera 0"}};
  const std::string xml = urdf_text(m, user.params, extra);
  const urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(xml);
  ASSERT_TRUE(model) << xml;
  std::mt19937 rng(4);
  const Eigen::VectorXd r = readings_of(m, rng);
  std::map<std::string, double> q;
  for (std::size_t a = 0; a < m.actuated.size(); ++a)
    q[m.bodies[static_cast<std::size_t>(m.actuated[a])].name] = r[static_cast<Eigen::Index>(a)];
  const auto links = urdf_link_poses(*model, q);
  // camera0 -> board in the URDF = the identified camera -> board.
  const Eigen::Isometry3d camera_T_board = links.at("camera0").inverse() * links.at("board");
  const Eigen::Isometry3d identified = body_pose(m, id.estimate, r, m.tool);
  EXPECT_LT((camera_T_board.translation() - identified.translation()).norm(), 1e-9);
  EXPECT_LT((camera_T_board.linear() - identified.linear()).norm(), 1e-9);
  // The tool link is the flange (the file's tool), the world the robot's own.
  const Eigen::Isometry3d flange = links.at("tool");
  EXPECT_LT((flange.translation() - body_pose(m, user.params, r, m.tool).translation()).norm(),
            1e-9);
  EXPECT_NE(xml.find("<!-- link board: the measured board -->"), std::string::npos);
  // A frame named like a link is refused, naming it.
  try {
    (void)urdf_text(m, user.params, {{"wrist3", 0, Eigen::Isometry3d::Identity(), ""}});
    FAIL() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'wrist3'"), std::string::npos) << e.what();
  }
  const std::string dh = dh_table_text(m, user.params, extra);
  EXPECT_NE(dh.find("  board (wrist3 -> board): xyz [-145.0000, -145.0000, 10.0000] mm"),
            std::string::npos)
      << dh;
  EXPECT_NE(dh.find("  camera0 (base -> camera0): "), std::string::npos) << dh;
}

TEST(UrdfExport, ParallelRobotsAreRefusedWithTheReason) {
  const Mechanism delta = testing::load("rotary_delta.yaml");
  EXPECT_NE(urdf_mismatch(delta).find("closed loops"), std::string::npos);
  EXPECT_THROW(urdf_text(delta, delta.nominal_parameters()), std::invalid_argument);
}

TEST(UrdfImport, WhatRobocalCannotTakeIsNamed) {
  const auto error = [](const std::string& joint) {
    const std::string xml =
        R"(<robot name="r"><link name="a"/><link name="b"/>)" + joint + R"(</robot>)";
    try {
      robot_yaml_from_urdf(xml, "r.urdf");
    } catch (const core::InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string tilted = error(
      R"(<joint name="j1" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0.6 0.8 0"/></joint>)");
  EXPECT_NE(tilted.find("r.urdf: joint 'j1'"), std::string::npos) << tilted;
  const std::string planar =
      error(R"(<joint name="j2" type="floating"><parent link="a"/><child link="b"/></joint>)");
  EXPECT_NE(planar.find("joint 'j2' is planar or floating"), std::string::npos) << planar;
  EXPECT_THROW(robot_yaml_from_urdf("<robot", "bad.urdf"), core::InputError);
}

// The DH table's printed numbers, composed here by the classic DH formula (joint value = the
// reading), give the robot's tool position; worst distance over random readings, m.
double dh_rebuild_error(const Mechanism& m, const Eigen::VectorXd& p, const std::string& table) {
  std::istringstream in(table);
  std::string line;
  struct Row {
    bool revolute;
    double theta, d, a, alpha;  // rad, m
  };
  std::vector<Row> rows;
  std::array<double, 6> base{}, tool{};
  const auto frame = [](const std::string& l, std::array<double, 6>& f) {
    std::string s = l.substr(l.find('[') + 1);
    std::replace(s.begin(), s.end(), ',', ' ');
    std::replace(s.begin(), s.end(), ']', ' ');
    std::replace(s.begin(), s.end(), '[', ' ');
    std::istringstream v(s.substr(0, s.find("mm")) + s.substr(s.find("rpy") + 3));
    for (double& x : f) v >> x;
  };
  while (std::getline(in, line)) {
    std::istringstream v(line);
    std::string name, type;
    double theta = 0, d = 0, a = 0, alpha = 0;
    if (line.find("  base") == 0) frame(line, base);
    if (line.find("  tool") == 0) frame(line, tool);
    if (v >> name >> type >> theta >> d >> a >> alpha &&
        (type == "revolute" || type == "prismatic"))
      rows.push_back({type == "revolute", theta * kDeg, d * 1e-3, a * 1e-3, alpha * kDeg});
  }
  EXPECT_EQ(rows.size(), m.actuated.size()) << table;
  const auto xyz_rpy = [](const std::array<double, 6>& f) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = Eigen::Vector3d(f[0], f[1], f[2]) * 1e-3;
    T.linear() = (Eigen::AngleAxisd(f[5] * kDeg, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(f[4] * kDeg, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(f[3] * kDeg, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    return T;
  };
  std::mt19937 rng(2);
  double worst = 0.0;
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::VectorXd r = readings_of(m, rng);
    Eigen::Isometry3d T = xyz_rpy(base);
    for (std::size_t i = 0; i < rows.size() && i < static_cast<std::size_t>(r.size()); ++i) {
      const Row& row = rows[i];
      const double q = r[static_cast<Eigen::Index>(i)];
      T = T * Eigen::AngleAxisd(row.theta + (row.revolute ? q : 0.0), Eigen::Vector3d::UnitZ());
      T = T * Eigen::Translation3d(0, 0, row.d + (row.revolute ? 0.0 : q));
      T = T * Eigen::Translation3d(row.a, 0, 0) *
          Eigen::AngleAxisd(row.alpha, Eigen::Vector3d::UnitX());
    }
    T = T * xyz_rpy(tool);
    worst = std::max(worst, (T.translation() - body_pose(m, p, r, m.tool).translation()).norm());
  }
  return worst;
}

TEST(DhTable, ThePrintedNumbersRebuildTheRobot) {
  // ur5 gives its joints in DH: the table reads them; modular_arm gives xyz_rpy frames: the
  // table is derived from its joint axes (parallel vertical axes, a prismatic joint).
  for (const char* file : {"ur5.yaml", "modular_arm.yaml"}) {
    const Mechanism m = testing::load(file);
    Eigen::VectorXd p = perturbed(m, 11);
    // modular_arm's joint axes stay parallel (lengths perturbed only): tilted, they would be
    // nearly parallel, which the next test shows is refused.
    if (m.name == "modular_arm")
      for (std::size_t i = 0; i < m.parameters.size(); ++i)
        if (m.parameters[i].unit == ParamUnit::kAngle)
          p[static_cast<Eigen::Index>(i)] = m.parameters[i].value;
    const std::string table = dh_table_text(m, p);
    // The text keeps 0.1 um and 1e-6 deg: the rebuild agrees to a micrometre.
    EXPECT_LT(dh_rebuild_error(m, p, table), 1e-6) << file << "\n" << table;
  }
}

TEST(DhTable, NearlyParallelAxesAreRefusedWithTheReason) {
  // Two revolute joints whose axes are 0.1 m apart and tilted 0.01 deg towards each other: they
  // meet 570 m away, where DH's common normal goes.
  const Mechanism m = parse_robot_yaml(R"(robot: skew
bodies:
  - {name: j1, convention: xyz_rpy, joint: revolute, role: actuated}
  - {name: j2, parent: j1, convention: xyz_rpy, joint: revolute, role: actuated, params: {x: 0.1, pitch: deg(0.01)}}
  - {name: j3, parent: j2, convention: xyz_rpy, joint: revolute, role: actuated, params: {x: 0.3}}
  - {name: tool, parent: j3, convention: xyz_rpy, joint: fixed, params: {x: 0.1}}
)",
                                       "skew.yaml");
  try {
    dh_table_text(m, m.nominal_parameters());
    ADD_FAILURE() << "nearly parallel axes";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("nearly parallel"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace robocal::calib
