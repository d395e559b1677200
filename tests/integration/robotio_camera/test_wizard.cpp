// `robocal wizard` as an operator runs it: the real program on a real pseudo-terminal (keys typed,
// Ctrl-C included) or from an answers file without a terminal, against `robocal sim-controller`
// (a perturbed linear delta speaking Marlin over TCP) and two simulated GigE Vision cameras
// served by this test (127.0.0.1 and 127.0.0.2, run_in_netns.sh) that render the board where the
// simulator's truth says it is. The simulator's own log is the independent record of what moved.
#include "child_process.hpp"
#include "netns_skip.hpp"
#include "pty_process.hpp"
#include "robotio_sim.hpp"
#include "sim_camera_cell.hpp"

#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/renderer.hpp"

#include <opencv2/imgcodecs.hpp>

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;
using testing::camera_spec;
using namespace std::chrono_literals;

std::string vec(const Eigen::Vector3d& v) {
  return fmt::format("[{:.9f}, {:.9f}, {:.9f}]", v.x(), v.y(), v.z());
}

// The test's cell: the two simulated cameras 0.25 m above the delta's workspace centre, looking
// down at a small board (3 x 2 tags of 12 mm) on top of the effector, inside its plate's
// outline, so that the planner's line-of-sight test (the rods and links are in its model) agrees
// with what the cameras render.
constexpr double kPi = 3.14159265358979323846;
const Eigen::Vector3d kBoardCentre(0.022, 0.014, 0.0);      // in board coordinates
const Eigen::Vector3d kBoardOnTool(-0.022, 0.014, 0.0055);  // task_T_board translation

std::string board_yaml() {
  return "type: apriltag_grid\nname: wizard test board\ncols: 3\nrows: 2\ntag_size: 0.012\n"
         "tag_spacing: 0.004\n";
}

BoardMounting mounting() {
  BoardMounting m;
  m.task_T_board =
      Eigen::Translation3d(kBoardOnTool) * Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitX());
  const Eigen::Isometry3d world_T_board = vision::camera_T_board_look_at(
      kBoardCentre + Eigen::Vector3d(0.0, 0.0, -0.25), kBoardCentre, Eigen::Vector3d(0, -1, 0));
  m.world_T_base =
      world_T_board * m.task_T_board.inverse() * Eigen::Translation3d(-testing::kSimCellCentre);
  return m;
}

// The operator's robot file: the library's linear delta with its tool frame where the board
// sits on the effector (the board's frame), as the robot file format describes a tool.
std::string robot_yaml() {
  std::ifstream in(testing::testdata("robots/linear_delta.yaml"));
  std::stringstream text;
  text << in.rdbuf();
  std::string s = text.str();
  const std::string tool = "params: {z: 0}}";
  const auto at = s.find("{name: tool,");
  const auto p = s.find(tool, at);
  if (at == std::string::npos || p == std::string::npos) return {};
  s.replace(p, tool.size(),
            fmt::format("params: {{x: {:.6f}, y: {:.6f}, z: {:.6f}, roll: deg(180)}}}}",
                        kBoardOnTool.x(), kBoardOnTool.y(), kBoardOnTool.z()));
  return s;
}

// The cell as the operator describes it: the cameras where the simulation has them, a safe
// workspace box, the board on the tool.
std::string cell_yaml(const fs::path& board, const Eigen::Vector3d& ws_min,
                      const Eigen::Vector3d& ws_max) {
  const Eigen::Isometry3d base_T_world = mounting().world_T_base.inverse();
  std::string cams;
  for (int c = 0; c < 2; ++c) {
    const Eigen::Isometry3d base_T_cam = base_T_world * camera_spec(c).camera_T_world.inverse();
    const Eigen::Vector3d p = base_T_cam.translation();
    cams += fmt::format(
        "  - name: cam{}\n    file: {}\n    pose: {{position: {}, look_at: {}, up: {}}}\n", c,
        testing::testdata("vision/camera_640x480.yaml"), vec(p),
        vec(p + base_T_cam.linear().col(2)), vec(-base_T_cam.linear().col(1)));
  }
  return fmt::format(
      "cell: wizard_test\nunits: m\ncameras:\n{}workspace: {{min: {}, max: {}}}\n"
      "margins: {{clearance: 0.005, self_clearance: 0.0005}}\n"
      "target:\n  file: {}\n  position: [0, 0, 0]\n  rpy: [0, 0, 0]\n",
      cams, vec(ws_min), vec(ws_max), board.string());
}

// A board pose in a camera's frame: the board centre on the ray through pixel (u, v) at `depth`,
// the board tilted by `tilt` (rad) about an axis at `azimuth` in its plane.
Eigen::Isometry3d board_in_view(const vision::CameraModel& cam, double u, double v, double depth,
                                double tilt, double azimuth) {
  const Eigen::Vector3d eye =
      kBoardCentre + depth * Eigen::Vector3d(std::sin(tilt) * std::cos(azimuth),
                                             std::sin(tilt) * std::sin(azimuth), -std::cos(tilt));
  const Eigen::Isometry3d centred =
      vision::camera_T_board_look_at(eye, kBoardCentre, Eigen::Vector3d(0, -1, 0));
  const Eigen::Vector3d ray((u - cam.params[2]) / cam.params[0],
                            (v - cam.params[3]) / cam.params[1], 1.0);
  Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
  turn.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), ray.normalized())
                      .toRotationMatrix();
  return turn * centred;
}

// Calibration views as an operator would record them with the board held in front of the
// cameras (rendered like the simulated cameras' frames): per camera 24 views at 7-11 cm, tilted,
// over the whole image, for its intrinsics; 8 views both cameras share, for the rig. Laid out
// as app/SESSION.md's calibration/ folder.
void render_calibration_views(const fs::path& out, const vision::TargetBoard& board) {
  for (int c = 0; c < 2; ++c) {
    const auto spec = camera_spec(c);
    const auto rays = vision::precompute_rays(spec.model);
    fs::create_directories(out / "intrinsics" / fmt::format("cam{}", c));
    for (int k = 0; k < 24; ++k) {
      const double u = 110.0 + 140.0 * (k % 4);
      const double v = 100.0 + 140.0 * ((k / 4) % 3);
      const double tilt = (20.0 + 10.0 * (k % 3)) * kPi / 180.0;
      const double azimuth = (45.0 * k) * kPi / 180.0;
      vision::RenderOptions o = spec.render;
      o.seed = 50U + static_cast<unsigned>(k);
      const auto r = vision::render(
          rays, {{board, board_in_view(spec.model, u, v, 0.07 + 0.02 * (k % 3), tilt, azimuth)}},
          o);
      cv::imwrite((out / "intrinsics" / fmt::format("cam{}", c) / fmt::format("view_{:03}.png", k))
                      .string(),
                  r.image);
    }
  }
  const auto spec0 = camera_spec(0);
  for (int k = 0; k < 8; ++k) {
    const fs::path view = out / "rig" / fmt::format("view_{:03}", k);
    fs::create_directories(view);
    const Eigen::Isometry3d cam0_T_board = board_in_view(
        spec0.model, 300.0 + 20.0 * (k % 3), 220.0 + 20.0 * (k % 2), 0.2 + 0.02 * (k % 4),
        (15.0 + 5.0 * (k % 3)) * kPi / 180.0, 60.0 * k * kPi / 180.0);
    for (int c = 0; c < 2; ++c) {
      const auto spec = camera_spec(c);
      vision::RenderOptions o = spec.render;
      o.seed = 500U + static_cast<unsigned>(10 * k + c);
      const auto r = vision::render(vision::precompute_rays(spec.model),
                                    {{board, spec.camera_T_world * cam0_T_board}}, o);
      cv::imwrite((view / fmt::format("cam{}.png", c)).string(), r.image);
    }
  }
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

YAML::Node state_of(const fs::path& folder) {
  return YAML::LoadFile((folder / "wizard.yaml").string());
}

// What the cameras see: the board on the robot, or, while the operator holds the calibration
// board in front of a camera (live calibration views), the pose the test gives it.
class HeldOrMounted final : public TruePoseSource {
 public:
  explicit HeldOrMounted(TruePoseSource& robot) : robot_(robot) {}
  Eigen::Isometry3d world_T_board() override {
    const std::lock_guard<std::mutex> lock(mutex_);
    return held_ ? *held_ : robot_.world_T_board();
  }
  void hold(std::optional<Eigen::Isometry3d> world_T_board) {
    const std::lock_guard<std::mutex> lock(mutex_);
    held_ = std::move(world_T_board);
  }

 private:
  TruePoseSource& robot_;
  std::mutex mutex_;
  std::optional<Eigen::Isometry3d> held_;
};

class Wizard : public ::testing::Test {
 protected:
  void SetUp() override {
    SKIP_WITHOUT_NETNS();
    dir_ = fs::temp_directory_path() / "robocal_wizard";
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    log_ = (dir_ / "sim.jsonl").string();
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY,
                                                  test::sim_args(log_, {"--seed", "5"}));
    truth_ = std::make_unique<SimControllerTruth>(sim_->pose(), mounting());
    seen_ = std::make_unique<HeldOrMounted>(*truth_);
    board_ = dir_ / "board.yaml";
    write(board_, board_yaml());
    const vision::TargetBoard board = vision::load_target_file(board_);
    for (int c = 0; c < 2; ++c)
      cameras_.push_back(std::make_unique<SimulatedGigECamera>(camera_spec(c), board, *seen_));
    const SafetyLimits l = test::delta_limits();
    write(dir_ / "cell.yaml", cell_yaml(board_, l.workspace_min, l.workspace_max));
    robot_ = dir_ / "linear_delta_board.yaml";
    write(robot_, robot_yaml());
    ASSERT_NE(robot_yaml().find("roll: deg(180)"), std::string::npos);
    // The operator has jogged the robot so that the board is in both cameras' view.
    {
      const calib::Mechanism model = test::linear_delta();
      SafetyGuard guard(model, model.nominal_parameters(), l);
      guard.arm("test: simulated cell");
      GcodeLink link(guard, test::link_options(model, sim_->tcp()));
      link.connect();
      link.home();
      link.move_actuators(testing::sim_cell_targets(model, 1).front(), testing::kSimCellSpeed);
      link.disconnect();
    }
    moves_before_ = moves_received(log_);
  }

  // Every answer of a good run, by key; `changes` replace or add some.
  std::map<std::string, std::string> answers(
      const std::map<std::string, std::string>& changes = {}) const {
    std::map<std::string, std::string> a = {
        {"robot.model", robot_.string()},
        {"robot.goal", "geometry"},
        {"controller.steps_per_mm", "80"},
        {"controller.steps_per_degree", "100"},
        {"controller.link", sim_->tcp()},
        {"controller.home", "no"},
        {"cameras.list", "cam0=aravis:SIM-CAM0 cam1=aravis:SIM-CAM1"},
        {"cameras.target", board_.string()},
        {"cameras.size", "640x480"},
        {"intrinsics.cam0", "cell"},
        {"intrinsics.cam1", "cell"},
        {"cell.file", (dir_ / "cell.yaml").string()},
        {"plan.count", "6"},
        {"plan.pool", "400"},
        {"plan.problem", "continue"},
        {"safety.speed", "0.2"},
        {"safety.acceleration", "4"},
        {"safety.confirm", "yes"},
        {"collection.continue", "yes"},
        {"identify.views", "quit"},
    };
    for (const auto& [k, v] : changes) a[k] = v;
    return a;
  }
  fs::path write_answers(const std::string& name, const std::map<std::string, std::string>& a) {
    fs::path p = dir_ / name;
    std::string text = "# answers by key\n";
    for (const auto& [k, v] : a) text += fmt::format("{}={}\n", k, v);
    write(p, text);
    return p;
  }
  int run_answers(const fs::path& folder, const fs::path& answers, std::string* output,
                  bool resume = false) const {
    std::vector<std::string> args = {"wizard"};
    if (resume) args.emplace_back("--resume");
    args.push_back(folder.string());
    args.emplace_back("--answers");
    args.push_back(answers.string());
    test::ChildProcess run(ROBOCAL_BINARY, args, (folder.string() + ".out"));
    const int code = run.wait(std::chrono::seconds(240));
    *output = run.output();
    return code;
  }

  fs::path dir_;
  fs::path board_;
  fs::path robot_;
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SimControllerTruth> truth_;
  std::unique_ptr<HeldOrMounted> seen_;
  std::vector<std::unique_ptr<SimulatedGigECamera>> cameras_;
  int moves_before_ = 0;
};

TEST_F(Wizard, AnswersFileDrivesTheFlowWithoutATerminal) {
  const fs::path folder = dir_ / "w1";
  std::string out;
  const int code = run_answers(folder, write_answers("a1.txt", answers()), &out);
  // The flow runs through the collection; identification then needs calibration views the
  // session does not have, which the step says (and stops, resumable).
  ASSERT_EQ(code, 1) << out;
  EXPECT_NE(out.find("check: ok - every camera sees the whole board"), std::string::npos) << out;
  EXPECT_NE(out.find("every planned motion passes the safety guard"), std::string::npos) << out;
  EXPECT_NE(out.find("calibration views"), std::string::npos) << out;
  const YAML::Node st = state_of(folder);
  EXPECT_EQ(st["current"].as<std::string>(), "identify");
  EXPECT_EQ(st["done"].size(), 8U);
  const int planned = std::stoi(st["values"]["plan.poses"].as<std::string>());
  EXPECT_GE(planned, 6);
  EXPECT_TRUE(fs::exists(folder / "plan.svg"));
  EXPECT_EQ(pose_folders(folder / "session").size(), static_cast<std::size_t>(planned));
  // The simulator's record: one move per planned pose, nothing else.
  EXPECT_EQ(moves_received(log_) - moves_before_, planned);
  // Each recorded pose is where the plan put it (the controller's settled readings).
  const auto plan = YAML::LoadFile((folder / "plan.yaml").string());
  std::size_t i = 0;
  for (const auto& p : plan["poses"]) {
    const YAML::Node y = YAML::LoadFile(
        (folder / "session" / "poses" / pose_folder_name(static_cast<int>(i++)) / "pose.yaml")
            .string());
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(y["actuators"][a].as<double>(), p["actuators"][a].as<double>(),
                  0.5 / 80.0 / 1000.0 + 1e-9);
  }
  // Resuming again stops at the same place and moves nothing.
  const int again = run_answers(folder, write_answers("a1.txt", answers()), &out, true);
  EXPECT_EQ(again, 1) << out;
  EXPECT_NE(out.find("done before"), std::string::npos) << out;
  EXPECT_EQ(moves_received(log_) - moves_before_, planned);

  // With the calibration views, the flow finishes: measure, identify, held-out validation,
  // export; still nothing moves.
  // The export step also writes the report page and rewrites a G-code program for this printer.
  render_calibration_views(dir_ / "views", vision::load_target_file(board_));
  write(dir_ / "part.gcode", "G90\nG1 X0 Y0 Z50 F3000\nG1 X20 Y0 Z50\nG1 X20 Y20 Z40\n");
  const int finish = run_answers(
      folder,
      write_answers("a1b.txt", answers({{"identify.views", (dir_ / "views").string()},
                                        {"validate.holdout_every", "3"},
                                        {"export.format", "marlin"},
                                        {"export.gcode", (dir_ / "part.gcode").string()}})),
      &out, true);
  EXPECT_EQ(finish, 0) << out;
  EXPECT_NE(out.find("All steps done"), std::string::npos) << out;
  EXPECT_TRUE(fs::exists(folder / "export" / "calibrated.marlin")) << out;
  EXPECT_TRUE(fs::exists(folder / "session" / "results" / "report.html")) << out;
  std::ifstream rewritten(folder / "export" / "part.compensated.gcode");
  ASSERT_TRUE(rewritten) << out;
  std::string text, line;
  int lines = 0;
  while (std::getline(rewritten, line)) {
    text += line + "\n";
    ++lines;
  }
  EXPECT_NE(text.find("robocal compensate"), std::string::npos) << text;
  EXPECT_GE(lines, 4) << text;
  // The held-out poses were predicted by a fit that did not see them, better than nominal; the
  // record is the session's (results/held_out.json), and its report page shows it.
  std::ifstream vjson(folder / "session" / "results" / "held_out.json");
  const auto v = nlohmann::json::parse(vjson);
  EXPECT_GE(v["calibrated"]["poses"].get<int>(), 1) << v.dump();
  EXPECT_LT(v["calibrated"]["rms_m"].get<double>(), v["nominal"]["rms_m"].get<double>())
      << v.dump();
  std::ifstream page_file(folder / "session" / "results" / "report.html");
  std::stringstream page_text;
  page_text << page_file.rdbuf();
  const std::string page = page_text.str();
  EXPECT_NE(page.find("held-out poses, measured by the cameras"), std::string::npos);
  EXPECT_EQ(page.find("no held-out validation"), std::string::npos);
  EXPECT_EQ(moves_received(log_) - moves_before_, planned);
}

// Types `line` once `prompt` shows; fails the test (with what the wizard printed) otherwise.
#define TYPE_AT(pty, prompt, line)                                                 \
  do {                                                                             \
    ASSERT_TRUE((pty).expect(prompt, 120s)) << "no prompt '" << (prompt) << "':\n" \
                                            << (pty).output();                     \
    (pty).type(std::string(line) + "\r");                                          \
  } while (false)

// The robot, controller and cameras steps as the operator of a good run answers them (defaults
// where there are any); the cameras' check passes.
void answer_robot_to_cameras(test::PtyProcess& w, const fs::path& robot, const std::string& link,
                             const fs::path& board) {
  TYPE_AT(w, "Robot (library name or robot file)", robot.string());
  TYPE_AT(w, "What to calibrate", "");  // the default: the robot's geometry
  TYPE_AT(w, "Steps per mm", "");       // a linear delta: no rotary axes, no steps per degree
  TYPE_AT(w, "Controller address", link);
  TYPE_AT(w, "Home the robot now?", "");
  TYPE_AT(w, "Cameras as NAME=SOURCE", "cam0=aravis:SIM-CAM0 cam1=aravis:SIM-CAM1");
  TYPE_AT(w, "Target file of the board", board.string());
  TYPE_AT(w, "Image size the cameras deliver", "640x480");
  ASSERT_TRUE(w.expect("check: ok - every camera sees the whole board", 60s)) << w.output();
}

// The cell step, which comes before the intrinsics (their default is the cell's camera file).
void answer_cell(test::PtyProcess& w, const fs::path& cell) {
  TYPE_AT(w, "Cell file", cell.string());
}

// The plan (8 poses from 400 candidates, taken even if not accepted) and safety steps, the
// axes limited to `speed`, and the confirmation that lets the robot move.
void answer_plan_to_safety(test::PtyProcess& w, const std::string& speed) {
  TYPE_AT(w, "How many poses", "8");
  TYPE_AT(w, "Candidate poses", "400");
  ASSERT_TRUE(w.expect("Preview:", 120s)) << w.output();
  if (w.output().find("the plan is NOT accepted") != std::string::npos)
    TYPE_AT(w, "Use it anyway", "continue");
  TYPE_AT(w, "Axis speed limit", speed);
  TYPE_AT(w, "Axis acceleration limit", "4");
  TYPE_AT(w, "may the robot move", "yes");
}

TEST_F(Wizard, KeystrokesOnATerminalCtrlCDuringCollectionAndResumeLoseNoPose) {
  const fs::path folder = dir_ / "w2";
  int planned = 0;
  int recorded_before = 0;
  {
    test::PtyProcess w(ROBOCAL_BINARY, {"wizard", folder.string()});
    // A robot the library does not have: the step says so and asks again.
    TYPE_AT(w, "Robot (library name or robot file)", "no_such_robot");
    ASSERT_TRUE(w.expect("neither a file nor a library robot", 30s)) << w.output();
    ASSERT_NO_FATAL_FAILURE(answer_robot_to_cameras(w, robot_, sim_->tcp(), board_));
    ASSERT_NO_FATAL_FAILURE(answer_cell(w, dir_ / "cell.yaml"));
    TYPE_AT(w, "Intrinsics of cam0", "");  // default: the cell's camera file
    TYPE_AT(w, "Intrinsics of cam1", "");
    // Slow: the Ctrl-C lands mid-plan.
    ASSERT_NO_FATAL_FAILURE(answer_plan_to_safety(w, "0.01"));
    const auto end = std::chrono::steady_clock::now() + 180s;
    while (!fs::exists(folder / "session" / "poses" / "pose_001") &&
           std::chrono::steady_clock::now() < end)
      (void)w.pump(20);
    w.type("\x03");  // Ctrl-C on the terminal
    EXPECT_EQ(w.wait(60s), 130) << w.output();
    EXPECT_NE(w.output().find("--resume"), std::string::npos) << w.output();
    EXPECT_GE(test::received(test::read_sim_log(log_), "M410"), 1) << w.output();
    planned = std::stoi(state_of(folder)["values"]["plan.poses"].as<std::string>());
    recorded_before = static_cast<int>(pose_folders(folder / "session").size());
    EXPECT_GE(recorded_before, 2);
    EXPECT_LT(recorded_before, planned);
    EXPECT_EQ(state_of(folder)["current"].as<std::string>(), "collection");
  }
  const int moves_at_stop = moves_received(log_);
  const auto written = fs::last_write_time(folder / "session" / "poses" / "pose_000" / "pose.yaml");
  {
    test::PtyProcess w(ROBOCAL_BINARY, {"wizard", "--resume", folder.string()});
    TYPE_AT(w, "Axis speed limit", "");  // the speed given before
    TYPE_AT(w, "Continue the interrupted collection", "yes");
    ASSERT_TRUE(w.expect("every planned pose is recorded", 240s)) << w.output();
    TYPE_AT(w, "Folder with the calibration views", "quit");
    EXPECT_EQ(w.wait(60s), 1) << w.output();  // identify: no calibration views (explained)
  }
  EXPECT_EQ(pose_folders(folder / "session").size(), static_cast<std::size_t>(planned));
  EXPECT_EQ(fs::last_write_time(folder / "session" / "poses" / "pose_000" / "pose.yaml"), written);
  // Only the missing poses were driven to (the one cut short by Ctrl-C, if any, among them).
  EXPECT_EQ(moves_received(log_) - moves_at_stop, planned - recorded_before);
}

// The intrinsics step's live views on a terminal: each Enter takes a view of the board the
// operator holds in front of cam0. A view without the board is not kept; views that all face the
// line of sight get the advice to tilt the board; tilted views over the whole image calibrate the
// camera, and
// its focal length agrees with the simulated camera's within the calibration's own uncertainty.
TEST_F(Wizard, LiveCalibrationViewsAreGuidedAndCalibrateTheCamera) {
  const fs::path folder = dir_ / "w4";
  const auto spec = camera_spec(0);
  const auto held = [&](const Eigen::Isometry3d& camera_T_board) {
    seen_->hold(spec.camera_T_world.inverse() * camera_T_board);
  };
  test::PtyProcess w(ROBOCAL_BINARY, {"wizard", folder.string()});
  ASSERT_NO_FATAL_FAILURE(answer_robot_to_cameras(w, robot_, sim_->tcp(), board_));
  ASSERT_NO_FATAL_FAILURE(answer_cell(w, dir_ / "cell.yaml"));
  TYPE_AT(w, "Intrinsics of cam0", "live");
  TYPE_AT(w, "Target file of the calibration board", board_.string());
  // The board held out of the camera's view: nothing kept.
  held(Eigen::Translation3d(0.0, 0.0, -1.0) * Eigen::Isometry3d::Identity());
  TYPE_AT(w, "cam0 view 1: Enter", "");
  ASSERT_TRUE(w.expect("no board in this view", 30s)) << w.output();
  // Four views square to the line of sight: the focal length is weakly determined.
  for (int k = 0; k < 4; ++k) {
    held(board_in_view(spec.model, 160.0 + 320.0 * (k % 2), 120.0 + 240.0 * (k >= 2 ? 1.0 : 0.0),
                       0.09, 0.0, 0.0));
    TYPE_AT(w, fmt::format("cam0 view {}: Enter", k + 1), "");
    ASSERT_TRUE(w.expect(fmt::format("view {} kept", k + 1), 30s)) << w.output();
  }
  ASSERT_TRUE(w.expect("only 0 views tilted", 30s)) << w.output();
  ASSERT_TRUE(w.expect("advice: add views with the board tilted", 30s)) << w.output();
  // Twelve tilted views over the image, at 7-11 cm, as the advice asks.
  for (int k = 0; k < 12; ++k) {
    held(board_in_view(spec.model, 110.0 + 140.0 * (k % 4), 100.0 + 140.0 * ((k / 4) % 3),
                       0.07 + 0.02 * (k % 3), (20.0 + 10.0 * (k % 3)) * kPi / 180.0,
                       (45.0 * k) * kPi / 180.0));
    TYPE_AT(w, fmt::format("cam0 view {}: Enter", k + 5), "");
    ASSERT_TRUE(w.expect(fmt::format("view {} kept", k + 5), 30s)) << w.output();
  }
  ASSERT_TRUE(w.expect("so far: focal length", 30s)) << w.output();
  TYPE_AT(w, "cam0 view 17: Enter", "done");
  ASSERT_TRUE(w.expect("cam0: calibrated from 16 views", 60s)) << w.output();
  ASSERT_TRUE(w.expect("Intrinsics of cam1", 60s)) << w.output();
  w.type("\x04");  // Ctrl-D at the prompt: the operator stops here
  (void)w.wait(30s);
  seen_->hold(std::nullopt);

  std::size_t kept = 0;
  for (const auto& e : fs::directory_iterator(folder / "calibration" / "intrinsics" / "cam0"))
    kept += e.path().extension() == ".png" ? 1 : 0;
  EXPECT_EQ(kept, 16u);
  // The last guidance calibrated these same 16 views: its focal length and sigma.
  const std::string out = w.output();
  const auto at = out.rfind("so far: focal length ");
  ASSERT_NE(at, std::string::npos) << out;
  double fx_so_far = 0.0;
  double sigma = 0.0;
  ASSERT_EQ(std::sscanf(out.c_str() + at, "so far: focal length %lf ± %lf px", &fx_so_far, &sigma),
            2)
      << out.substr(at, 80);
  const auto file = state_of(folder)["values"]["intrinsics.cam0"].as<std::string>();
  const vision::CameraModel calibrated = vision::load_camera_file(file);
  EXPECT_GT(sigma, 0.0);
  EXPECT_LT(std::abs(calibrated.params[0] - spec.model.params[0]), 4.0 * sigma)
      << "calibrated " << calibrated.params[0] << " true " << spec.model.params[0] << " sigma "
      << sigma;
  EXPECT_EQ(moves_received(log_), moves_before_);  // nothing moved
}

// The whole flow with calibration views taken only live, on a terminal: each camera's intrinsic
// views in the intrinsics step, the rig views (the board held where both cameras see it; a view
// only one camera sees is not kept) in the identify step, which puts them all into the session
// and identifies the robot from them.
TEST_F(Wizard, LiveViewsCarryTheFlowToTheIdentification) {
  const fs::path folder = dir_ / "w5";
  test::PtyProcess w(ROBOCAL_BINARY, {"wizard", folder.string()});
  ASSERT_NO_FATAL_FAILURE(answer_robot_to_cameras(w, robot_, sim_->tcp(), board_));
  ASSERT_NO_FATAL_FAILURE(answer_cell(w, dir_ / "cell.yaml"));
  for (int c = 0; c < 2; ++c) {
    const auto spec = camera_spec(c);
    TYPE_AT(w, fmt::format("Intrinsics of cam{}", c), "live");
    // One board for every camera: asked with the first camera only.
    if (c == 0) TYPE_AT(w, "Target file of the calibration board", "");  // the robot's board
    for (int k = 0; k < 16; ++k) {
      seen_->hold(spec.camera_T_world.inverse() *
                  board_in_view(spec.model, 110.0 + 140.0 * (k % 4), 100.0 + 140.0 * ((k / 4) % 3),
                                0.07 + 0.02 * (k % 3), (20.0 + 10.0 * (k % 3)) * kPi / 180.0,
                                (45.0 * k + 20.0 * c) * kPi / 180.0));
      TYPE_AT(w, fmt::format("cam{} view {}: Enter", c, k + 1), "");
      ASSERT_TRUE(w.expect(fmt::format("view {} kept", k + 1), 30s)) << w.output();
    }
    TYPE_AT(w, fmt::format("cam{} view 17: Enter", c), "done");
    ASSERT_TRUE(w.expect(fmt::format("cam{}: calibrated from 16 views", c), 60s)) << w.output();
  }
  seen_->hold(std::nullopt);  // the cameras see the board on the robot again
  ASSERT_NO_FATAL_FAILURE(answer_plan_to_safety(w, "0.2"));
  ASSERT_TRUE(w.expect("every planned pose is recorded", 240s)) << w.output();
  // The identify step has each camera's views from the intrinsics step; the rig views are taken
  // now, the board held 20-26 cm in front of the cameras.
  TYPE_AT(w, "Folder with the calibration views", "live");
  const auto spec0 = camera_spec(0);
  seen_->hold(spec0.camera_T_world.inverse() *
              board_in_view(spec0.model, 40.0, 240.0, 0.09, 0.0, 0.0));  // cam0 only
  TYPE_AT(w, "rig view 1: Enter", "");
  ASSERT_TRUE(w.expect("not kept (two or more cameras must see it)", 30s)) << w.output();
  for (int k = 0; k < 8; ++k) {
    seen_->hold(spec0.camera_T_world.inverse() *
                board_in_view(spec0.model, 300.0 + 20.0 * (k % 3), 220.0 + 20.0 * (k % 2),
                              0.2 + 0.02 * (k % 4), (15.0 + 5.0 * (k % 3)) * kPi / 180.0,
                              60.0 * k * kPi / 180.0));
    TYPE_AT(w, fmt::format("rig view {}: Enter", k + 1), "");
    ASSERT_TRUE(w.expect(fmt::format("rig view {} kept", k + 1), 30s)) << w.output();
  }
  seen_->hold(std::nullopt);
  TYPE_AT(w, "rig view 9: Enter", "done");
  ASSERT_TRUE(w.expect("check: ok - the geometry is identified", 240s)) << w.output();
  ASSERT_TRUE(w.expect("Hold out every K-th measured pose", 60s)) << w.output();
  w.type("\x04");  // the operator stops before the validation
  (void)w.wait(30s);

  const fs::path session = folder / "session";
  for (const std::string cam : {"cam0", "cam1"}) {
    std::size_t views = 0;
    for (const auto& e : fs::directory_iterator(session / "calibration" / "intrinsics" / cam))
      views += e.path().extension() == ".png" ? 1 : 0;
    EXPECT_EQ(views, 16u) << cam;
  }
  std::size_t rig_views = 0;
  for (const auto& e : fs::directory_iterator(session / "calibration" / "rig"))
    rig_views += fs::exists(e.path() / "cam0.png") && fs::exists(e.path() / "cam1.png") ? 1 : 0;
  EXPECT_EQ(rig_views, 8u);
  // The rig measured from the live views against the simulated cameras' true placement.
  const auto rig = nlohmann::json::parse(std::ifstream(session / "results" / "rig.json"));
  const Eigen::Vector3d true_baseline =
      (camera_spec(1).camera_T_world * spec0.camera_T_world.inverse()).translation();
  const double sigma = rig["cameras"][1]["baseline_sigma_m"].get<double>();
  EXPECT_GT(sigma, 0.0);
  EXPECT_LT(std::abs(rig["cameras"][1]["baseline_m"].get<double>() - true_baseline.norm()),
            4.0 * sigma)
      << rig.dump();
}

TEST_F(Wizard, BadInputAtAStepIsExplainedAndNothingMoves) {
  struct Case {
    std::string name;
    std::map<std::string, std::string> changes;
    int code;
    std::string step;  // where --resume would continue
    std::vector<std::string> says;
  };
  // A board the cameras do not see (another tag family: no tag of it is in the image).
  write(dir_ / "other_board.yaml",
        "type: apriltag_grid\nfamily: tag25h9\ncols: 3\nrows: 2\ntag_size: 0.012\n"
        "tag_spacing: 0.004\n");
  // A cell whose safe workspace lies beyond the robot's reach.
  write(dir_ / "far_cell.yaml",
        cell_yaml(board_, Eigen::Vector3d(0.5, 0.5, 0.5), Eigen::Vector3d(0.6, 0.6, 0.6)));
  const std::vector<Case> cases = {
      {"unknown_robot",
       {{"robot.model", "no_such_robot"}},
       5,
       "robot",
       {"neither a file nor a library robot", "linear_delta", "robot.model"}},
      {"no_controller",
       {{"controller.link", "tcp:127.0.0.1:9"}, {"controller.problem", "quit"}},
       1,
       "controller",
       {"no controller at tcp:127.0.0.1:9", "what to do: is the controller switched on",
        "What answers at 127.0.0.1:9: nothing answers on port 9 of 127.0.0.1"}},
      // A bare network address is probed first: nothing there is said in plain words.
      {"bare_address_probed",
       {{"controller.link", "127.0.0.1:9"}, {"controller.problem", "quit"}},
       1,
       "controller",
       {"Looking at 127.0.0.1:9",
        "nothing answers on port 9 of 127.0.0.1: is the robot on the "
        "network"}},
      {"target_not_in_view",
       {{"cameras.target", (dir_ / "other_board.yaml").string()}, {"cameras.problem", "quit"}},
       1,
       "cameras",
       {"PROBLEM", "a camera is not ready"}},
      {"infeasible_cell",
       {{"cell.file", (dir_ / "far_cell.yaml").string()}, {"plan.problem", "quit"}},
       1,
       "plan",
       {"no plan", "move the cameras"}},
  };
  for (const Case& c : cases) {
    const fs::path folder = dir_ / c.name;
    std::string out;
    EXPECT_EQ(run_answers(folder, write_answers(c.name + ".txt", answers(c.changes)), &out), c.code)
        << c.name << "\n"
        << out;
    for (const auto& s : c.says)
      EXPECT_NE(out.find(s), std::string::npos) << c.name << ": " << s << "\n" << out;
    EXPECT_NE(out.find("--resume"), std::string::npos) << c.name << "\n" << out;
    EXPECT_EQ(state_of(folder)["current"].as<std::string>(), c.step) << c.name;
    EXPECT_FALSE(fs::exists(folder / "session")) << c.name;
  }
  EXPECT_EQ(moves_received(log_), moves_before_);
}

}  // namespace
}  // namespace robocal::robotio
