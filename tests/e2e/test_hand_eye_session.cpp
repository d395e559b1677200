// Hand-eye calibration of a robot whose controller reports its flange pose, end to end: `robocal
// sim-cell --protocol open` (the simulated controller in its own process serving the open link
// protocol, whose read replies carry the TRUE robot's base -> flange pose, as an accurate
// industrial controller reports it; the cameras rendered by the program that opens them), the
// wizard's hand-eye route through an answers file (intrinsics from the calibration views, plan,
// `collect` through the guarded link, the hand-eye step), then `robocal handeye SESSION` on the
// session collect recorded. Judged against the simulator's truth (its true robot and cameras),
// which neither the wizard nor the command reads.
//
// The cell's truth is idealised (--idealised-truth): a rigid arm. The realistic cell's elastic
// sag (the board sinks by 1e-4 /m times its squared distance from the base axis, 25 um on
// average at the UR5's reach) is what no controller reports: it lifts the camera found in the
// base frame by the sag's mean, which the pixel-noise covariance cannot know (docs/figures.md,
// hand-eye, gives that figure).
#include "child_process.hpp"
#include "run_robocal.hpp"
#include "scratch_dir.hpp"
#include "test_paths.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/calib/mechanism.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/sim_controller.hpp"
#include "robocal/vision/pose.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <Eigen/Dense>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
namespace rt = robocal::test;
using Iso = Eigen::Isometry3d;
using Vector6 = Eigen::Matrix<double, 6, 1>;
using namespace std::chrono_literals;

// 99.73 % (3 sigma) quantile of chi-square with 6 degrees of freedom: the estimate's error under
// its own reported covariance stays below it 997 times in 1000 when the covariance is right.
constexpr double kChi2Six3Sigma = 20.06;

std::string robocal() {
  return rt::robocal_binary();
}

// sim-cell started and ready (its answers for the wizard, by key), stopped at the end.
struct Cell {
  std::unique_ptr<rt::ChildProcess> process;
  std::map<std::string, std::string> answers;
  fs::path dir;
};

Cell start_cell(const fs::path& dir, unsigned seed) {
  Cell c;
  c.dir = dir;
  c.process = std::make_unique<rt::ChildProcess>(
      robocal(),
      std::vector<std::string>{"sim-cell", "--robot", "ur5", "--seed", std::to_string(seed),
                               "--quick", "--in-process", "--idealised-truth", "--protocol", "open",
                               "--out", dir.string()},
      (dir.parent_path() / "sim-cell.log").string());
  const auto end = std::chrono::steady_clock::now() + 600s;
  while (c.process->output().find("ready:") == std::string::npos) {
    if (!c.process->running() || std::chrono::steady_clock::now() > end) {
      ADD_FAILURE() << "sim-cell did not become ready:\n" << c.process->output();
      return c;
    }
    std::this_thread::sleep_for(200ms);
  }
  const YAML::Node root = YAML::LoadFile((dir / "wizard_answers.yaml").string());
  for (const auto& kv : root) c.answers[kv.first.as<std::string>()] = kv.second.as<std::string>();
  return c;
}

// The simulator's truth, in the frames the controller reports (its own base, its flange): the
// true robot's base and tool placement (the board's frame is the tool frame on the sim-cell's
// robot) and the true cameras.
struct Truth {
  Iso flange_T_board = Iso::Identity();
  std::map<std::string, Iso> base_T_camera;
  robocal::calib::Mechanism model;
  Eigen::VectorXd params;
  robocal::robotio::FlangeFrames frames;
};

Truth read_truth(const fs::path& cell) {
  const auto j =
      nlohmann::json::parse(rt::read_text((cell / "simulator/truth/truth.json").string()));
  Truth t;
  t.model = robocal::calib::load_robot_file(rt::testdata_dir() + std::string("/robots/ur5.yaml"));
  t.params = t.model.nominal_parameters();
  for (const auto& [name, value] : j.at("truth").items())
    robocal::calib::apply_parameter_override(t.model, t.params,
                                             fmt::format("{}={:.17g}", name, value.get<double>()));
  t.frames = robocal::robotio::flange_frames(t.model);
  // Fixed frames: any configuration places them alike.
  const Eigen::VectorXd q =
      Eigen::VectorXd::Zero(static_cast<Eigen::Index>(t.model.actuated.size()));
  const auto pose = [&](int frame) {
    return robocal::calib::forward_kinematics(t.model, t.params, q, frame).pose;
  };
  const Iso world_T_base = pose(t.frames.base);
  t.flange_T_board = pose(t.frames.flange).inverse() * pose(t.model.tool);
  for (const auto& c : j.at("cameras")) {
    const auto& e = c.at("camera_T_world");
    const Iso camera_T_world = robocal::vision::pose_from_rvec_tvec(
        Eigen::Vector3d(e["rvec"][0], e["rvec"][1], e["rvec"][2]),
        Eigen::Vector3d(e["tvec"][0], e["tvec"][1], e["tvec"][2]));
    t.base_T_camera[c.at("name").get<std::string>()] =
        world_T_base.inverse() * camera_T_world.inverse();
  }
  return t;
}

// One transform of a hand-eye result file, with its covariance ([dp; dphi], world frame).
struct Estimate {
  Iso pose = Iso::Identity();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  std::string parent, child;
};

Estimate read_transform(const YAML::Node& node) {
  Estimate e;
  const auto t = node["translation_m"].as<std::vector<double>>();
  const auto q = node["quaternion_xyzw"].as<std::vector<double>>();
  e.pose.linear() = Eigen::Quaterniond(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
  e.pose.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
  const auto c = node["covariance"].as<std::vector<double>>();
  for (int i = 0; i < 36; ++i) e.covariance(i / 6, i % 6) = c[static_cast<std::size_t>(i)];
  e.parent = node["parent"].as<std::string>();
  e.child = node["child"].as<std::string>();
  return e;
}

Vector6 error_of(const Iso& estimate, const Iso& truth) {
  Vector6 d;
  d.head<3>() = estimate.translation() - truth.translation();
  const Eigen::AngleAxisd turn(estimate.linear() * truth.linear().transpose());
  d.tail<3>() = turn.angle() * turn.axis();
  return d;
}

// The estimate's error against the truth, printed with its reported 1-sigma; its chi-square
// under the reported covariance (6 dof) is returned.
double report_error(const Estimate& e, const Iso& truth, const std::string& what) {
  const Vector6 d = error_of(e.pose, truth);
  const double chi2 = d.dot(e.covariance.ldlt().solve(d));
  fmt::print(
      "{}: position error {:.1f} um (1-sigma {:.1f} um), rotation error {:.2f} mdeg, "
      "chi2 {:.2f} (3 sigma: {:.2f})\n",
      what, 1e6 * d.head<3>().norm(), 1e6 * std::sqrt(e.covariance.topLeftCorner<3, 3>().trace()),
      1e3 * d.tail<3>().norm() * 180.0 / std::numbers::pi, chi2, kChi2Six3Sigma);
  return chi2;
}

// Both cameras' files (PREFIX_<camera>.yaml) against the truth: the figure, a position
// error of at most 0.2 mm at the demo's noise, and a rotation error of at most 0.01 degrees
// (0.2 mm over the board's 1.2 m from the cameras).
//
// Not asserted: the error within 3 sigma of the reported covariance. On this rendered cell the
// covariance is optimistic (docs/figures.md#hand-eye): with the intrinsics fixed it leaves their
// own uncertainty out (chi-square up to thousands against the 20.06 of 3 sigma), and with them
// estimated one transform of four still lands at 22. The chi-square is printed beside each error.
void expect_files_match_truth(const fs::path& prefix, const Truth& truth) {
  for (const auto& [name, base_T_camera] : truth.base_T_camera) {
    SCOPED_TRACE(name);
    const fs::path file = prefix.string() + "_" + name + ".yaml";
    ASSERT_TRUE(fs::exists(file)) << file;
    const YAML::Node doc = YAML::LoadFile(file.string());
    const Estimate camera = read_transform(doc["camera"]);
    const Estimate board = read_transform(doc["target"]);
    EXPECT_EQ(camera.parent, "base");
    EXPECT_EQ(board.parent, "flange");
    const std::vector<std::pair<const Estimate*, const Iso*>> pairs = {
        {&camera, &base_T_camera}, {&board, &truth.flange_T_board}};
    for (const auto& [estimate, true_pose] : pairs) {
      const std::string what =
          file.filename().string() + " " + estimate->child + " in " + estimate->parent;
      (void)report_error(*estimate, *true_pose, what);
      const Vector6 d = error_of(estimate->pose, *true_pose);
      EXPECT_LT(d.head<3>().norm(), 0.2e-3) << what;
      EXPECT_LT(d.tail<3>().norm(), 0.01 * std::numbers::pi / 180.0) << what;
    }
  }
}

// Every pose collect recorded carries the flange pose the controller reported, and it is the true
// robot's at the recorded readings (to its actuators' repeatability: 2 and 5 micro-radians of
// noise and backlash, a few micrometres at the UR5's reach).
void expect_recorded_flange_poses(const fs::path& session, const Truth& truth) {
  int poses = 0;
  for (const auto& entry : fs::directory_iterator(session / "poses")) {
    const YAML::Node y = YAML::LoadFile((entry.path() / "pose.yaml").string());
    ASSERT_TRUE(y["flange_pose"]) << entry.path();
    const auto a = y["actuators"].as<std::vector<double>>();
    const Eigen::VectorXd readings =
        Eigen::Map<const Eigen::VectorXd>(a.data(), static_cast<Eigen::Index>(a.size()));
    const auto at = [&](int frame) {
      return robocal::calib::forward_kinematics(truth.model, truth.params, readings, frame).pose;
    };
    const Iso expected = at(truth.frames.base).inverse() * at(truth.frames.flange);
    const YAML::Node f = y["flange_pose"];
    const Eigen::Vector3d p(f["x"].as<double>(), f["y"].as<double>(), f["z"].as<double>());
    EXPECT_LT((p - expected.translation()).norm(), 20e-6) << entry.path();
    ++poses;
  }
  EXPECT_GE(poses, 10);
}

class HandEyeFromController : public rt::ScratchDirTest {
 protected:
  HandEyeFromController() : rt::ScratchDirTest("handeye_controller") {}
};

TEST_F(HandEyeFromController, Ur5WizardRouteAndHandeyeCommandAgainstTheSimulatorsTruth) {
  Cell cell = start_cell(dir / "cell", 1);
  ASSERT_FALSE(cell.answers.empty());
  // The operator's answers: sim-cell's, the hand-eye goal, a small plan, yes to the motion.
  std::string answers;
  for (const auto& [key, value] : cell.answers) answers += fmt::format("{}: \"{}\"\n", key, value);
  answers += "robot.goal: handeye\nplan.count: 15\nsafety.confirm: yes\n";
  std::ofstream(dir / "answers.yaml") << answers;
  const fs::path wizard = dir / "w";
  rt::ChildProcess run(
      robocal(),
      {"wizard", wizard.string(), "--answers", (dir / "answers.yaml").string(), "--defaults"},
      (dir / "wizard.log").string());
  ASSERT_EQ(run.wait(1500s), 0) << run.output();
  const std::string out = run.output();
  EXPECT_NE(out.find("Locate the cameras and the board (hand-eye)"), std::string::npos) << out;
  EXPECT_EQ(out.find("Identify the geometry"), std::string::npos) << out;
  EXPECT_NE(out.find("flange poses: as the controller reported them"), std::string::npos) << out;
  EXPECT_NE(out.find("ros2 run tf2_ros static_transform_publisher"), std::string::npos) << out;

  const Truth truth = read_truth(cell.dir);
  const fs::path session = wizard / "session";
  expect_recorded_flange_poses(session, truth);
  // The wizard keeps the intrinsics its intrinsics step calibrated.
  expect_files_match_truth(wizard / "export" / "handeye", truth);

  // The command on the session collect recorded, the intrinsics estimated with the transforms.
  const auto cmd = rt::run_robocal_captured(
      {"handeye", session.string(), "--estimate-intrinsics", "-o", file("he.yaml")});
  ASSERT_EQ(cmd.code, 0) << cmd.out << cmd.err;
  EXPECT_NE(cmd.out.find("flange poses: as the controller reported them"), std::string::npos)
      << cmd.out;
  expect_files_match_truth(dir / "he", truth);

  cell.process->signal(SIGINT);
  EXPECT_EQ(cell.process->wait(60s), 0) << cell.process->output();
}

}  // namespace
