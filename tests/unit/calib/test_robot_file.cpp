// Robot files: the library loads, conventions agree with each other, collision geometry moves
// with its body, and bad input is reported with file, line and problem.
#include "calib_test_support.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/robot_file.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <sstream>

namespace robocal::calib {
namespace {

using testing::library;
using testing::load;

// The encoder scale as the encoder model applies it: one joint unit apart is 1 / scale readings
// apart (the wire robot's j1: 2 pi / 268000 rad per count; the Delta's arms: 1). Home joint values
// in actuator order, from the file.
TEST(RobotFile, EncoderScalesAndHomeFollowTheEncoderModel) {
  for (const std::string robot : {"wire_robot_branch", "rotary_delta", "ur5"}) {
    const Mechanism m =
        load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + robot + ".yaml");
    const Eigen::VectorXd p = m.nominal_parameters();
    const Eigen::VectorXd home = m.home_actuated();
    ASSERT_EQ(home.size(), static_cast<Eigen::Index>(m.actuated.size()));
    const Eigen::VectorXd apart = readings_from_joint_values(m, p, home.array() + 1.0) -
                                  readings_from_joint_values(m, p, home);
    const Eigen::VectorXd scale = encoder_scales(m, p);
    for (Eigen::Index i = 0; i < home.size(); ++i) {
      EXPECT_EQ(home[i], m.bodies[m.actuated[static_cast<std::size_t>(i)]].home) << robot;
      EXPECT_NEAR(apart[i] * scale[i], 1.0, 1e-9) << robot << " actuator " << i;
    }
    if (robot == "wire_robot_branch") {
      EXPECT_NEAR(scale[0], 2.0 * std::numbers::pi / (500.0 * 134.0 * 4.0), 1e-15);
    }
  }
}

TEST(RobotFile, EveryLibraryRobotLoadsWithNamedParameters) {
  for (const auto& robot : library()) {
    const Mechanism m = load(robot.file);
    EXPECT_FALSE(m.name.empty());
    EXPECT_EQ(m.actuated.size(), robot.lower.size()) << robot.file;
    EXPECT_GE(m.tool, 0);
    std::set<std::string> names;
    for (const Parameter& p : m.parameters) {
      EXPECT_TRUE(names.insert(p.name).second) << "duplicate " << p.name;
      EXPECT_GT(p.sigma, 0.0) << p.name;
      EXPECT_TRUE(std::isfinite(p.value));
    }
    // Pre-order: every parent precedes its children; subtree intervals nest.
    for (std::size_t b = 0; b < m.bodies.size(); ++b) {
      EXPECT_LT(m.bodies[b].parent, static_cast<int>(b));
      EXPECT_GT(m.bodies[b].subtree_end, static_cast<int>(b));
    }
  }
  const Mechanism delta = load("rotary_delta.yaml");
  EXPECT_EQ(delta.bodies.size(), 30u);
  EXPECT_EQ(delta.parameters.size(), 30u * 6 + 3 * 2);
  EXPECT_DOUBLE_EQ(delta.parameters[delta.parameter_index("body26.d1")].value, 0.9);
  EXPECT_DOUBLE_EQ(delta.parameters[delta.parameter_index("body3.a2")].value,
                   2 * std::numbers::pi / 3);
  EXPECT_NEAR(delta.parameters[delta.parameter_index("body11.d1")].value, 0.3947, 5e-5);
  EXPECT_NEAR(delta.parameters[delta.parameter_index("body11.d2")].value, -0.1641, 5e-5);
  EXPECT_FALSE(delta.parameters[delta.parameter_index("body2.encoder_offset")].free);
  const Mechanism ld = load("linear_delta.yaml");
  EXPECT_GE(ld.parameter_index("rod_b.length"), 0);
  EXPECT_TRUE(ld.parameters[ld.parameter_index("carriage_a.encoder_offset")].free);
}

TEST(RobotFile, ExpressionsEvaluateExactly) {
  EXPECT_DOUBLE_EQ(evaluate_expression("-2*pi/3"), -2 * std::numbers::pi / 3);
  EXPECT_DOUBLE_EQ(evaluate_expression("0.196*sqrt(3)/2 + 0.15"),
                   0.196 * std::sqrt(3.0) / 2 + 0.15);
  EXPECT_DOUBLE_EQ(evaluate_expression("deg(90)"), std::numbers::pi / 2);
  EXPECT_DOUBLE_EQ(evaluate_expression("2^3 - (1 - -1)"), 6.0);
  EXPECT_DOUBLE_EQ(evaluate_expression("1e-3"), 1e-3);
  EXPECT_THROW(evaluate_expression("1/0"), std::invalid_argument);
  EXPECT_THROW(evaluate_expression("nan"), std::invalid_argument);
  EXPECT_THROW(evaluate_expression("pi pi"), std::invalid_argument);
}

// UR5 DH table with non-zero theta offsets so every rotation slot is exercised.
struct DhRow {
  double theta, d, a, alpha;
};
std::vector<DhRow> ur5_rows() {
  const double h = std::numbers::pi / 2;
  return {{0.1, 0.089159, 0, h}, {-0.2, 0, -0.425, 0},    {0.3, 0, -0.39225, 0},
          {0.05, 0.10915, 0, h}, {-0.15, 0.09465, 0, -h}, {0.25, 0.0823, 0, 0}};
}

std::string num(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

std::string serial_yaml(const std::string& convention, const std::string& order = "xyz") {
  const auto rows = ur5_rows();
  std::ostringstream y;
  y << "robot: ur5_" << convention << order << "\nrotation_order: " << order
    << "\ntool: tool\nbodies:\n";
  std::string parent = "world";
  for (std::size_t i = 0; i <= rows.size(); ++i) {
    const bool tool = i == rows.size();
    std::ostringstream name_text;
    if (tool) {
      name_text << "tool";
    } else {
      name_text << 'j' << i + 1;
    }
    const std::string name = name_text.str();
    y << "  - name: " << name << "\n    parent: " << parent
      << "\n    joint: " << (tool ? "fixed" : "revolute") << "\n"
      << (tool ? "" : "    role: actuated\n");
    const DhRow prev = i == 0 ? DhRow{0, 0, 0, 0} : rows[i - 1];
    const DhRow cur = tool ? DhRow{0, 0, 0, 0} : rows[i];
    if (convention == "dh") {
      y << "    convention: dh\n    params: {theta: " << num(cur.theta) << ", d: " << num(cur.d)
        << ", a: " << num(cur.a) << ", alpha: " << num(cur.alpha) << "}\n";
      if (tool) {
        // DH bodies end after Rx(alpha) of their own row; the tool adds nothing.
      }
    } else if (convention == "mdh") {
      y << "    convention: mdh\n    params: {alpha: " << num(prev.alpha) << ", a: " << num(prev.a)
        << ", theta: " << num(cur.theta) << ", d: " << num(cur.d) << "}\n";
    } else if (convention == "mcpc") {
      y << "    convention: mcpc\n    params: {a1: " << num(prev.alpha) << ", d1: " << num(prev.a)
        << ", d3: " << num(cur.d) << ", a3: " << num(cur.theta) << "}\n";
    } else {  // xyz_rpy: translation Rx(alpha_prev) (a_prev, 0, d), rotation Rx(alpha) Rz(theta)
      const Eigen::Vector3d t = Eigen::AngleAxisd(prev.alpha, Eigen::Vector3d::UnitX()) *
                                Eigen::Vector3d(prev.a, 0, cur.d);
      const Eigen::Matrix3d R = (Eigen::AngleAxisd(prev.alpha, Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(cur.theta, Eigen::Vector3d::UnitZ()))
                                    .toRotationMatrix();
      double roll = prev.alpha, pitch = 0, yaw = cur.theta;
      if (order == "zyx") {
        const Eigen::Vector3d e = R.eulerAngles(2, 1, 0);  // R = Rz(e0) Ry(e1) Rx(e2)
        yaw = e[0], pitch = e[1], roll = e[2];
      }
      y << "    convention: xyz_rpy\n    params: {x: " << num(t.x()) << ", y: " << num(t.y())
        << ", z: " << num(t.z()) << ", roll: " << num(roll) << ", pitch: " << num(pitch)
        << ", yaw: " << num(yaw) << "}\n";
    }
    parent = name;
  }
  return y.str();
}

TEST(RobotFile, SerialArmIsIdenticalInDhMdhMcpcAndXyzRpy) {
  const Mechanism dh = parse_robot_yaml(serial_yaml("dh"), "dh");
  std::vector<Mechanism> others = {parse_robot_yaml(serial_yaml("mdh"), "mdh"),
                                   parse_robot_yaml(serial_yaml("mcpc"), "mcpc"),
                                   parse_robot_yaml(serial_yaml("xyz_rpy", "xyz"), "xyz"),
                                   parse_robot_yaml(serial_yaml("xyz_rpy", "zyx"), "zyx")};
  // The DH tool frame sits after Rx(alpha_6) of row 6; the MDH-style files need row 6's a/alpha
  // in the tool body, which they get from `prev` of the tool row.
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int k = 0; k < 20; ++k) {
    Eigen::VectorXd q(6);
    for (int i = 0; i < 6; ++i) q[i] = u(rng);
    const auto ref = forward_kinematics(dh, dh.nominal_parameters(), q, dh.tool).pose;
    for (const Mechanism& m : others) {
      const auto T = forward_kinematics(m, m.nominal_parameters(), q, m.tool).pose;
      EXPECT_LE((T.matrix() - ref.matrix()).cwiseAbs().maxCoeff(), 1e-12) << m.source;
    }
  }
  // Hayati with beta = 0 is DH with d = 0.
  const Mechanism h = parse_robot_yaml(
      "robot: h\nbodies:\n  - {name: a, convention: hayati, joint: revolute, role: actuated, "
      "params: {theta: 0.3, a: 0.4, alpha: 0.5}}\n",
      "h");
  const Mechanism d = parse_robot_yaml(
      "robot: d\nbodies:\n  - {name: a, convention: dh, joint: revolute, role: actuated, "
      "params: {theta: 0.3, a: 0.4, alpha: 0.5}}\n",
      "d");
  const Eigen::VectorXd q1 = Eigen::VectorXd::Constant(1, 0.7);
  EXPECT_LE((forward_kinematics(h, h.nominal_parameters(), q1, 0).pose.matrix() -
             forward_kinematics(d, d.nominal_parameters(), q1, 0).pose.matrix())
                .cwiseAbs()
                .maxCoeff(),
            1e-15);
}

TEST(RobotFile, UrdfAxisAndRotationOrder) {
  // URDF: origin xyz, rpy composed Rz(yaw) Ry(pitch) Rx(roll), motion about an explicit axis.
  const Mechanism m = parse_robot_yaml(
      "robot: u\nrotation_order: zyx\nbodies:\n"
      "  - {name: a, convention: xyz_rpy, joint: revolute, role: actuated, axis: -y,\n"
      "     params: {x: 0.1, y: 0.2, z: 0.3, roll: 0.4, pitch: 0.5, yaw: 0.6}}\n",
      "u");
  const double q = 0.35;
  const auto T =
      forward_kinematics(m, m.nominal_parameters(), Eigen::VectorXd::Constant(1, q), 0).pose;
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.6, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(-q, Eigen::Vector3d::UnitY()))
                                .toRotationMatrix();
  EXPECT_LE((T.linear() - R).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LE((T.translation() - Eigen::Vector3d(0.1, 0.2, 0.3)).norm(), 1e-15);
}

TEST(RobotFile, CollisionGeometryMovesWithItsBody) {
  const Mechanism m = load("rotary_delta.yaml");
  const Eigen::VectorXd p = m.nominal_parameters();
  const int arm = m.body_index("body2");
  ASSERT_EQ(m.bodies[arm].collision.size(), 1u);
  const CollisionShape& cap = m.bodies[arm].collision[0];
  EXPECT_EQ(cap.kind, ShapeKind::kCapsule);
  EXPECT_DOUBLE_EQ(cap.radius, 0.03);
  const int plate = m.body_index("body9");
  ASSERT_EQ(m.bodies[plate].collision.size(), 1u);
  EXPECT_EQ(m.bodies[plate].collision[0].kind, ShapeKind::kBox);
  for (double t : {-0.1, 0.3, 0.6}) {
    const Eigen::Vector3d q(t, 0.2, 0.4);
    const ForwardResult fk = forward_kinematics(m, p, q, m.tool);
    ASSERT_TRUE(fk.closure.ok());
    std::vector<Eigen::Isometry3d> poses;
    body_poses(m, p, fk.state, poses);
    // The upper-arm capsule ends at the elbow (body 5 origin); the rod capsule at the plate.
    EXPECT_LE((poses[arm] * cap.b - poses[m.body_index("body5")].translation()).norm(), 1e-12);
    const int rod = m.body_index("body6");
    EXPECT_LE(
        (poses[rod] * m.bodies[rod].collision[0].b - poses[m.body_index("body7")].translation())
            .norm(),
        1e-12);
    // The plate box is centred on the tool (plate centre) and stays level with it.
    EXPECT_LE((poses[plate] * m.bodies[plate].collision[0].a - fk.pose.translation()).norm(),
              1e-12);
  }
}

// Bad input: the message must name the file, the line and the problem.
void expect_error(const std::string& yaml, int line, const std::string& problem) {
  try {
    parse_robot_yaml(yaml, "bad_robot.yaml");
    FAIL() << "accepted bad input, expected: " << problem;
  } catch (const RobotFileError& e) {
    const std::string msg = e.what();
    std::string where = "bad_robot.yaml:";
    where += std::to_string(line);
    where += ':';
    EXPECT_NE(msg.find(where), std::string::npos) << msg;
    EXPECT_NE(msg.find(problem), std::string::npos) << msg;
  }
}

TEST(RobotFile, BadInputNamesFileLineAndProblem) {
  expect_error("robot: x\nbodies: [\n  {name: a\n", 4, "malformed YAML");
  expect_error(
      "robot: x\nbodies:\n  - {name: a, convention: mcpc}\n  - {name: b, parent: nope, "
      "convention: mcpc}\n",
      4, "unknown predecessor 'nope'");
  expect_error(
      "robot: x\nbodies:\n  - {name: a, parent: b, convention: mcpc}\n"
      "  - {name: b, parent: a, convention: mcpc}\n",
      3, "cycle");
  expect_error(
      "robot: x\nbodies:\n  - {name: a, convention: mcpc}\nclosures:\n"
      "  - {name: c, a: a,\n     b: ghost}\n",
      6, "missing body 'ghost'");
  expect_error("robot: x\nbodies:\n  - name: a\n    convention: mcpc\n    params: {d1: .nan}\n", 5,
               "a.d1");
  expect_error("robot: x\nbodies:\n  - name: a\n    convention: mcpc\n    params: {d1: inf}\n", 5,
               "unknown name 'inf'");
  expect_error("robot: x\nbodies:\n  - name: a\n    convention: mcpc\n    params: {d1: 1/0}\n", 5,
               "not finite");
  expect_error("robot: x\nbodies:\n  - name: a\n    convention: dh\n    params: {d1: 1}\n", 5,
               "unknown key 'd1'");
  expect_error("robot: x\nbodies:\n  - name: a\n    convention: euler\n", 4,
               "unknown convention 'euler'");
  expect_error("robot: x\nbodies:\n  - {name: a, convention: mcpc, joint: spherical}\n", 3,
               "not an end of any closure");
  expect_error(
      "robot: x\nbodies:\n  - {name: a, convention: mcpc}\n  - {name: a, convention: "
      "mcpc}\n",
      4, "duplicate body name");
}

TEST(RobotFile, ParameterOverrideNamesFileAndParameter) {
  const Mechanism m = load("rotary_delta.yaml");
  Eigen::VectorXd p = m.nominal_parameters();
  apply_parameter_override(m, p, "body26.d1=0.9 + 1e-3");
  EXPECT_DOUBLE_EQ(p[m.parameter_index("body26.d1")], 0.901);
  try {
    apply_parameter_override(m, p, "body26.length=1");
    FAIL();
  } catch (const RobotFileError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("rotary_delta.yaml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("no parameter named 'body26.length'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("body26.d1"), std::string::npos) << msg;  // suggestions
  }
  EXPECT_THROW(apply_parameter_override(m, p, "body26.d1=nan"), RobotFileError);
  EXPECT_THROW(apply_parameter_override(m, p, "body26.d1"), RobotFileError);
}

TEST(RobotFile, WorkspaceEntryIsParsedAndChecked) {
  const std::string head = "robot: x\nbodies:\n  - {name: a, convention: mcpc}\n";
  EXPECT_EQ(parse_robot_yaml(head, "x").workspace.min_task_conditioning, 0.0);
  const Mechanism m = parse_robot_yaml(head + "workspace: {min_task_conditioning: 1/4}\n", "x");
  EXPECT_DOUBLE_EQ(m.workspace.min_task_conditioning, 0.25);
  EXPECT_EQ(m.workspace.line, 4);
  expect_error(head + "workspace:\n  min_task_conditioning: 1.5\n", 5, "must be in (0, 1)");
  expect_error(head + "workspace:\n  min_task_conditioning: 0\n", 5, "must be in (0, 1)");
  expect_error(head + "workspace:\n  radius: 0.3\n", 5, "unknown key 'radius' in workspace");
  expect_error(head + "workspace: {}\n", 4, "workspace needs 'min_task_conditioning'");
  expect_error(head + "workspace: 0.3\n", 4, "workspace must be a map");
}

TEST(RobotFile, UnmodelledErrorHasDefaultsAndIsChecked) {
  const std::string head = "robot: x\nbodies:\n  - {name: a, convention: mcpc}\n";
  const Mechanism plain = parse_robot_yaml(head, "x");
  EXPECT_DOUBLE_EQ(plain.unmodelled_error.position, 20e-6);
  EXPECT_DOUBLE_EQ(plain.unmodelled_error.rotation, 1e-4);
  EXPECT_EQ(plain.unmodelled_error.line, 0);
  const Mechanism m =
      parse_robot_yaml(head + "unmodelled_error: {position: 50e-6, rotation: 0}\n", "x");
  EXPECT_DOUBLE_EQ(m.unmodelled_error.position, 50e-6);
  EXPECT_DOUBLE_EQ(m.unmodelled_error.rotation, 0.0);
  EXPECT_EQ(m.unmodelled_error.line, 4);
  expect_error(head + "unmodelled_error:\n  position: -1e-6\n", 5,
               "unmodelled_error.position must be in [0, 0.01] (m)");
  expect_error(head + "unmodelled_error:\n  rotation: 1\n", 5,
               "unmodelled_error.rotation must be in [0, 0.1] (rad)");
  expect_error(head + "unmodelled_error:\n  sag: 1e-4\n", 5,
               "unknown key 'sag' in unmodelled_error");
}

TEST(RobotFile, ExactParametersAreHeldAndNamedOnce) {
  const std::string head =
      "robot: x\nbodies:\n  - {name: a, convention: mcpc}\n"
      "  - name: b\n    parent: a\n    convention: mcpc\n    joint: revolute\n";
  const Mechanism m = parse_robot_yaml(head + "    exact: [d1]\n", "x");
  const Parameter& d1 = m.parameters[static_cast<std::size_t>(m.parameter_index("b.d1"))];
  EXPECT_TRUE(d1.exact);
  EXPECT_FALSE(d1.free);
  EXPECT_FALSE(m.parameters[static_cast<std::size_t>(m.parameter_index("b.d2"))].exact);
  expect_error(head + "    exact: [d9]\n", 8, "'exact' names unknown parameter 'd9'");
  expect_error(head + "    exact: [d1]\n    free:\n      - d1\n", 10,
               "'d1' is both 'exact' (cannot differ from the drawing) and 'free'");
}

TEST(RobotFile, MissingFileIsReported) {
  try {
    load_robot_file("/nonexistent/robot.yaml");
    FAIL();
  } catch (const RobotFileError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/robot.yaml"), std::string::npos);
  }
}

}  // namespace
}  // namespace robocal::calib
