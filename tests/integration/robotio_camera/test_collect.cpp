// `robocal collect` as an operator runs it: the real program (a child process) drives
// `robocal sim-controller` (another process, a perturbed linear delta speaking Marlin over TCP)
// through a plan, and reads two simulated GigE Vision cameras (served by this test on 127.0.0.1
// and 127.0.0.2, run_in_netns.sh) that render the board where the simulator's truth channel says
// it is. The simulator's own log is the independent record of what moved.
#include "child_process.hpp"
#include "netns_skip.hpp"
#include "robocal/robotio/camera_aravis.hpp"
#include "robotio_sim.hpp"
#include "sim_camera_cell.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;
using testing::camera_spec;
using testing::sim_cell_mounting;

std::string vec(const Eigen::Vector3d& v) {
  return fmt::format("[{:.9f}, {:.9f}, {:.9f}]", v.x(), v.y(), v.z());
}

// The cell as the operator would describe it: the two cameras where the simulation has them
// (robot world), the simulator's declared box as the workspace, the board on the tool.
std::string cell_yaml() {
  const Eigen::Isometry3d base_T_world = sim_cell_mounting().world_T_base.inverse();
  std::string cams;
  for (int c = 0; c < 2; ++c) {
    const Eigen::Isometry3d base_T_cam = base_T_world * camera_spec(c).camera_T_world.inverse();
    const Eigen::Vector3d p = base_T_cam.translation();
    cams += fmt::format(
        "  - name: cam{}\n    file: {}\n    pose: {{position: {}, look_at: {}, up: {}}}\n", c,
        testing::testdata("vision/camera_640x480.yaml"), vec(p),
        vec(p + base_T_cam.linear().col(2)), vec(-base_T_cam.linear().col(1)));
  }
  const SafetyLimits l = test::delta_limits();
  return fmt::format(
      "cell: collect_test\nunits: m\ncameras:\n{}workspace: {{min: {}, max: {}}}\n"
      "margins: {{clearance: 0.005, self_clearance: 0.0005}}\n"
      "target:\n  file: {}\n  position: [0, 0, 0]\n  rpy: [0, 0, 0]\n",
      cams, vec(l.workspace_min), vec(l.workspace_max),
      testing::testdata("vision/apriltag_4x3.yaml"));
}

std::string plan_yaml(const std::vector<Eigen::VectorXd>& targets) {
  std::string text = "poses:\n";
  for (const auto& t : targets)
    text += fmt::format("  - {{actuators: [{:.9f}, {:.9f}, {:.9f}]}}\n", t[0], t[1], t[2]);
  return text;
}

void write(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text;
}

int moves_received(const std::string& log) {
  const auto l = test::read_sim_log(log);
  return test::received(l, "G0") + test::received(l, "G1");
}

std::set<std::string> pose_folders(const fs::path& session) {
  std::set<std::string> names;
  if (fs::exists(session / "poses"))
    for (const auto& e : fs::directory_iterator(session / "poses"))
      names.insert(e.path().filename().string());
  return names;
}

class Collect : public ::testing::Test {
 protected:
  void SetUp() override {
    SKIP_WITHOUT_NETNS();
    dir_ = fs::temp_directory_path() / "robocal_collect";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    log_ = (dir_ / "sim.jsonl").string();
    sim_ =
        std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, test::sim_args(log_, sim_extra()));
    truth_ = std::make_unique<SimControllerTruth>(sim_->pose(), sim_cell_mounting());
    const vision::TargetBoard board =
        vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml"));
    for (int c = 0; c < 2; ++c)
      cameras_.push_back(std::make_unique<SimulatedGigECamera>(camera_spec(c), board, *truth_));
    write(dir_ / "cell.yaml", cell_yaml());
  }

  // Simulator options beyond the tests' common ones.
  virtual std::vector<std::string> sim_extra() const { return {"--seed", "5"}; }

  // The operator's command line; `link` and `speed` replace the defaults (an option given twice
  // is a usage error).
  std::vector<std::string> args(const fs::path& session, const fs::path& plan,
                                std::vector<std::string> extra, std::string link = {},
                                const std::string& speed = "0.2",
                                const std::vector<std::string>& cameras = {
                                    "cam0=aravis:SIM-CAM0", "cam1=aravis:SIM-CAM1"}) const {
    if (link.empty()) link = sim_->tcp();
    std::vector<std::string> a = {"collect",        session.string(),
                                  "--robot",        "linear_delta",
                                  "--cell",         (dir_ / "cell.yaml").string(),
                                  "--plan",         plan.string(),
                                  "--link",         link,
                                  "--speed",        speed,
                                  "--acceleration", "4"};
    for (const auto& c : cameras) {
      a.push_back("--camera");
      a.push_back(c);
    }
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  }

  fs::path dir_;
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SimControllerTruth> truth_;
  std::vector<std::unique_ptr<SimulatedGigECamera>> cameras_;
};

TEST_F(Collect, RecordsEveryPlannedPoseWhereTheControllerSaysTheRobotStood) {
  const calib::Mechanism model = test::linear_delta();
  const auto goals = testing::sim_cell_targets(model, 6);
  write(dir_ / "plan.yaml", plan_yaml(goals));
  const fs::path session = dir_ / "s1";
  test::ChildProcess run(
      ROBOCAL_BINARY,
      args(session, dir_ / "plan.yaml", {"--yes", "--json", (dir_ / "s1.json").string()}),
      (dir_ / "s1.out").string());
  ASSERT_EQ(run.wait(std::chrono::seconds(120)), 0) << run.output();
  ASSERT_EQ(pose_folders(session).size(), goals.size()) << run.output();
  for (std::size_t i = 0; i < goals.size(); ++i) {
    const fs::path pose = session / "poses" / pose_folder_name(static_cast<int>(i));
    const YAML::Node y = YAML::LoadFile((pose / "pose.yaml").string());
    for (int a = 0; a < 3; ++a)  // the controller's settled readings: the target to half a step
      EXPECT_NEAR(y["actuators"][a].as<double>(), goals[i][a], 0.5 / 80.0 / 1000.0 + 1e-12);
    for (const char* cam : {"cam0", "cam1"})
      for (int k = 0; k < 2; ++k)
        EXPECT_TRUE(fs::exists(pose / fmt::format("{}_{}.png", cam, k))) << pose;
  }
  // The simulator's record: one move per pose, nothing else.
  EXPECT_EQ(moves_received(log_), static_cast<int>(goals.size()));
  // The session is a session: robot, target, camera intrinsics, plan.
  for (const char* f : {"session.yaml", "robot.yaml", "targets/end_effector.yaml",
                        "cameras/cam0.yaml", "cameras/cam1.yaml", "plan.yaml"})
    EXPECT_TRUE(fs::exists(session / f)) << f;
  std::ifstream json(dir_ / "s1.json");
  const auto summary = nlohmann::json::parse(json);
  EXPECT_EQ(summary.value("status", ""), "ok");
  EXPECT_EQ(summary.value("recorded", -1), static_cast<int>(goals.size()));

  // Run again with --resume: everything is recorded, nothing moves, nothing is rewritten.
  const auto written = fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml");
  test::ChildProcess again(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes", "--resume"}),
                           (dir_ / "s1b.out").string());
  EXPECT_EQ(again.wait(std::chrono::seconds(60)), 0) << again.output();
  EXPECT_EQ(moves_received(log_), static_cast<int>(goals.size()));
  EXPECT_EQ(fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml"), written);
}

TEST_F(Collect, CtrlCStopsTheRobotAndResumeFinishesWithNoPoseTakenTwice) {
  const calib::Mechanism model = test::linear_delta();
  const auto goals = testing::sim_cell_targets(model, 10);
  write(dir_ / "plan.yaml", plan_yaml(goals));
  const fs::path session = dir_ / "s2";
  int recorded_before = 0;
  {
    // Slow moves, so the Ctrl-C lands in the middle of the plan.
    test::ChildProcess run(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes"}, {}, "0.01"),
                           (dir_ / "s2.out").string());
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (!fs::exists(session / "poses" / "pose_001") && run.running() &&
           std::chrono::steady_clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    run.signal(SIGINT);
    EXPECT_EQ(run.wait(std::chrono::seconds(60)), 130) << run.output();
    EXPECT_NE(run.output().find("--resume"), std::string::npos) << run.output();
    recorded_before = static_cast<int>(pose_folders(session).size());
    EXPECT_GE(recorded_before, 2);
    EXPECT_LT(recorded_before, static_cast<int>(goals.size()));
    // The controller was told to stop (its own record).
    EXPECT_GE(test::received(test::read_sim_log(log_), "M410"), 1) << run.output();
  }
  const int moves_before = moves_received(log_);
  const auto written = fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml");
  test::ChildProcess resumed(ROBOCAL_BINARY,
                             args(session, dir_ / "plan.yaml", {"--yes", "--resume"}),
                             (dir_ / "s2b.out").string());
  ASSERT_EQ(resumed.wait(std::chrono::seconds(120)), 0) << resumed.output();
  EXPECT_EQ(pose_folders(session).size(), goals.size());
  EXPECT_EQ(fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml"), written);
  // Only the missing poses were driven to (the pose cut short by Ctrl-C, if any, among them).
  EXPECT_EQ(moves_received(log_) - moves_before, static_cast<int>(goals.size()) - recorded_before);
}

TEST_F(Collect, DryRunNamesTheRefusedPoseAndMovesNothing) {
  const calib::Mechanism model = test::linear_delta();
  auto goals = testing::sim_cell_targets(model, 4);
  // Pose 2 moves every carriage 9 cm: the effector moves 9 cm vertically, out of the declared
  // box (z 0.02..0.16 m; the plan's poses are at 0.09 +- 0.02 m).
  goals[2] = goals[1] - Eigen::Vector3d::Constant(0.09);
  write(dir_ / "plan.yaml", plan_yaml(goals));
  test::ChildProcess run(ROBOCAL_BINARY, args(dir_ / "s3", dir_ / "plan.yaml", {"--dry-run"}),
                         (dir_ / "s3.out").string());
  EXPECT_EQ(run.wait(std::chrono::seconds(60)), 1) << run.output();
  EXPECT_NE(run.output().find("pose   2: REFUSED"), std::string::npos) << run.output();
  EXPECT_EQ(moves_received(log_), 0);
  EXPECT_FALSE(fs::exists(dir_ / "s3"));
}

// The whole plan passes the guard before the first motion: a LAST pose outside the
// declared box stops `collect` (not --dry-run) before it connects, homes or moves, naming that
// pose; the simulator's own record shows no homing and no move.
TEST_F(Collect, ALastPoseTheGuardRefusesStopsItBeforeHomingOrAnyMove) {
  const calib::Mechanism model = test::linear_delta();
  auto goals = testing::sim_cell_targets(model, 5);
  goals[4] = goals[3] - Eigen::Vector3d::Constant(0.09);  // 9 cm below the box (see above)
  write(dir_ / "plan.yaml", plan_yaml(goals));
  const fs::path session = dir_ / "s_last";
  test::ChildProcess run(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes"}),
                         (dir_ / "s_last.out").string());
  EXPECT_EQ(run.wait(std::chrono::seconds(60)), 1) << run.output();
  EXPECT_NE(run.output().find("to pose 4:"), std::string::npos) << run.output();
  EXPECT_NE(run.output().find("before anything moved"), std::string::npos) << run.output();
  EXPECT_EQ(run.output().find("homing"), std::string::npos) << run.output();
  const auto log = test::read_sim_log(log_);
  EXPECT_EQ(test::received(log, "G28"), 0) << "homed before the plan was checked";
  EXPECT_EQ(moves_received(log_), 0);
  EXPECT_TRUE(test::events(log, "motion_start").empty());
  EXPECT_FALSE(fs::exists(session));
}

// A plan whose own status is `infeasible` is refused with that word before anything connects;
// accepted on request, its status and the expected duration of its motions are shown before the
// confirmation (here: none, no terminal, so nothing moves).
TEST_F(Collect, AnInfeasiblePlanIsRefusedAndThePlansStatusAndDurationAreShown) {
  const calib::Mechanism model = test::linear_delta();
  write(dir_ / "plan.yaml",
        "status: infeasible\n" + plan_yaml(testing::sim_cell_targets(model, 3)));
  const fs::path session = dir_ / "s_infeasible";
  test::ChildProcess refused(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes"}),
                             (dir_ / "s_infeasible.out").string());
  EXPECT_EQ(refused.wait(std::chrono::seconds(60)), 3) << refused.output();
  for (const char* word : {"plan.yaml:1", "status is 'infeasible'", "--accept-infeasible-plan"})
    EXPECT_NE(refused.output().find(word), std::string::npos) << word << "\n" << refused.output();
  EXPECT_FALSE(fs::exists(session));

  test::ChildProcess shown(ROBOCAL_BINARY,
                           args(session, dir_ / "plan.yaml", {"--accept-infeasible-plan"}),
                           (dir_ / "s_infeasible2.out").string());
  EXPECT_EQ(shown.wait(std::chrono::seconds(60)), 1) << shown.output();
  for (const char* word : {"status infeasible", "duration:  about ", "did not confirm"})
    EXPECT_NE(shown.output().find(word), std::string::npos) << word << "\n" << shown.output();
  EXPECT_EQ(test::received(test::read_sim_log(log_), "G28"), 0);
  EXPECT_EQ(moves_received(log_), 0);
}

TEST_F(Collect, BadInputIsRefusedBeforeAnythingMoves) {
  const calib::Mechanism model = test::linear_delta();
  write(dir_ / "plan.yaml", plan_yaml(testing::sim_cell_targets(model, 2)));
  struct Case {
    std::vector<std::string> cameras;
    std::string link;  // empty: the simulator
    int code;
    std::string says;
  };
  const std::vector<std::string> kCameras = {"cam0=aravis:SIM-CAM0", "cam1=aravis:SIM-CAM1"};
  const std::vector<Case> cases = {
      // A camera the cell does not have.
      {{"cam0=aravis:SIM-CAM0", "cam9=aravis:SIM-CAM1"}, "", 3, "has no camera 'cam9'"},
      // A camera that is not there.
      {{"cam0=aravis:SIM-CAM0", "cam1=aravis:NO-SUCH-CAMERA"}, "", 1, "NO-SUCH-CAMERA"},
      // A controller that does not answer (nothing listens on port 9 of 127.0.0.1).
      {kCameras, "tcp:127.0.0.1:9", 1, "tcp:127.0.0.1:9"},
      // No terminal and no --yes: nothing moves.
      {kCameras, "", 1, "did not confirm"},
  };
  int k = 0;
  for (const Case& c : cases) {
    const fs::path session = dir_ / fmt::format("bad{}", k++);
    test::ChildProcess run(ROBOCAL_BINARY,
                           args(session, dir_ / "plan.yaml",
                                c.says == "did not confirm" ? std::vector<std::string>{}
                                                            : std::vector<std::string>{"--yes"},
                                c.link, "0.2", c.cameras),
                           (dir_ / "bad.out").string());
    EXPECT_EQ(run.wait(std::chrono::seconds(60)), c.code) << run.output();
    EXPECT_NE(run.output().find(c.says), std::string::npos) << run.output();
    EXPECT_FALSE(fs::exists(session / "poses")) << c.says;
  }
  EXPECT_EQ(moves_received(log_), 0);
}

// A camera another application still controls (here this test holds SIM-CAM0, as a killed
// `robocal collect` does until the camera's heartbeat timeout runs out): collect refuses before
// anything moves, naming the camera, that another application controls it, the camera's own
// heartbeat timeout (set to 7000 ms here, not the fake camera's default) and what to do.
TEST_F(Collect, ACameraAnotherApplicationControlsIsNamedWithItsHeartbeatTimeout) {
  const calib::Mechanism model = test::linear_delta();
  write(dir_ / "plan.yaml", plan_yaml(testing::sim_cell_targets(model, 2)));
  cameras_[0]->server().set_heartbeat_timeout_ms(7000);
  const AravisCamera holder("SIM-CAM0", "holder");
  const fs::path session = dir_ / "held";
  test::ChildProcess run(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes"}),
                         (dir_ / "held.out").string());
  EXPECT_EQ(run.wait(std::chrono::seconds(60)), 1) << run.output();
  for (const std::string& says :
       {std::string("cam0"), std::string("SIM-CAM0"),
        std::string("is controlled by another application"),
        std::string("7000 ms after its last heartbeat"), std::string("close it first")})
    EXPECT_NE(run.output().find(says), std::string::npos) << says << " not in:\n" << run.output();
  EXPECT_FALSE(fs::exists(session / "poses"));
  EXPECT_EQ(moves_received(log_), 0);
}

// The operator's case: `robocal collect` killed with SIGKILL while it records (no handler runs,
// nothing releases the camera), and collect run again at once: the camera still counts the killed
// program as its controller until its heartbeat timeout, and the second run says so.
TEST_F(Collect, ACollectRunAfterAKilledOneNamesTheCameraStillHeldByIt) {
  const calib::Mechanism model = test::linear_delta();
  write(dir_ / "plan.yaml", plan_yaml(testing::sim_cell_targets(model, 8)));
  for (const auto& camera : cameras_) camera->server().set_heartbeat_timeout_ms(7000);
  const fs::path session = dir_ / "killed";
  test::ChildProcess first(ROBOCAL_BINARY, args(session, dir_ / "plan.yaml", {"--yes"}),
                           (dir_ / "killed.out").string());
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (first.running() && std::chrono::steady_clock::now() < until &&
         pose_folders(session).empty())
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_FALSE(pose_folders(session).empty()) << first.output();
  ASSERT_TRUE(first.running()) << "collect finished before it could be killed";
  first.signal(SIGKILL);
  first.wait(std::chrono::seconds(10));
  test::ChildProcess again(ROBOCAL_BINARY, args(dir_ / "again", dir_ / "plan.yaml", {"--yes"}),
                           (dir_ / "again.out").string());
  EXPECT_EQ(again.wait(std::chrono::seconds(60)), 1) << again.output();
  for (const std::string says : {"SIM-CAM", "is controlled by another application",
                                 "7000 ms after its last heartbeat", "was killed, wait"})
    EXPECT_NE(again.output().find(says), std::string::npos) << says << " not in:\n"
                                                            << again.output();
  EXPECT_FALSE(fs::exists(dir_ / "again" / "poses"));
}

// The same collection through the open link (robotio/OPEN_LINK.md): `--link open:HOST:PORT`
// against the simulator serving the open protocol, with the same true robot and cameras.
class CollectOpenLink : public Collect {
 protected:
  std::vector<std::string> sim_extra() const override {
    return {"--seed", "5", "--protocol", "open"};
  }
  std::string open_address() const { return "open:" + sim_->tcp().substr(4); }
};

TEST_F(CollectOpenLink, RecordsEveryPlannedPoseWhereTheControllerSaysTheRobotStood) {
  const calib::Mechanism model = test::linear_delta();
  const auto goals = testing::sim_cell_targets(model, 4);
  write(dir_ / "plan.yaml", plan_yaml(goals));
  const fs::path session = dir_ / "s_open";
  test::ChildProcess run(ROBOCAL_BINARY,
                         args(session, dir_ / "plan.yaml",
                              {"--yes", "--json", (dir_ / "s_open.json").string()}, open_address()),
                         (dir_ / "s_open.out").string());
  ASSERT_EQ(run.wait(std::chrono::seconds(120)), 0) << run.output();
  ASSERT_EQ(pose_folders(session).size(), goals.size()) << run.output();
  for (std::size_t i = 0; i < goals.size(); ++i) {
    const fs::path pose = session / "poses" / pose_folder_name(static_cast<int>(i));
    const YAML::Node y = YAML::LoadFile((pose / "pose.yaml").string());
    for (int a = 0; a < 3; ++a)  // the controller's settled readings: the target to half a step
      EXPECT_NEAR(y["actuators"][a].as<double>(), goals[i][a], 0.5 / 80.0 / 1000.0 + 1e-12);
  }
  // The simulator's record: one move request and one motion per pose.
  int moves = 0;
  for (const auto& rx : test::events(test::read_sim_log(log_), "rx"))
    if (rx.value("line", "").find("\"cmd\":\"move\"") != std::string::npos) ++moves;
  EXPECT_EQ(moves, static_cast<int>(goals.size()));
  int motions = 0;
  for (const auto& m : test::events(test::read_sim_log(log_), "motion_start"))
    if (!m.value("homing", false)) ++motions;
  EXPECT_EQ(motions, static_cast<int>(goals.size())) << "each pose's move executed once";
  EXPECT_NE(run.output().find("robocal simulated controller (linear_delta)"), std::string::npos)
      << run.output();
}

}  // namespace
}  // namespace robocal::robotio
