// Capture against a simulated cell: rendered cameras served through Aravis' fake GigE cameras on
// 127.0.0.1 and 127.0.0.2 (run_in_netns.sh), a gantry whose true board pose is known.
#include "camera_cell.hpp"
#include "robocal/robotio/camera_recorded.hpp"
#include "robocal/robotio/capture.hpp"

#include "netns_skip.hpp"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;
using testing::CameraRig;
using testing::gantry_targets;
using testing::GantryCell;

fs::path fresh_dir(const std::string& name) {
  fs::path dir = fs::temp_directory_path() / ("robocal_capture_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

vision::TargetBoard board() {
  return vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml"));
}

std::set<std::string> pose_folders(const fs::path& session) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(session / "poses")) {
    names.insert(entry.path().filename().string());
  }
  return names;
}

// Every pose folder holds pose.yaml and both cameras' shots, and its readings are the target's.
void expect_complete_poses(const fs::path& session, const std::vector<Eigen::VectorXd>& targets,
                           int shots) {
  const std::set<std::string> names = pose_folders(session);
  ASSERT_EQ(names.size(), targets.size());
  for (std::size_t i = 0; i < targets.size(); ++i) {
    const fs::path dir = session / "poses" / pose_folder_name(static_cast<int>(i));
    ASSERT_TRUE(fs::is_regular_file(dir / "pose.yaml")) << dir;
    const YAML::Node pose = YAML::LoadFile((dir / "pose.yaml").string());
    ASSERT_EQ(pose["actuators"].size(), 3U);
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(pose["actuators"][a].as<double>(), targets[i][a]) << dir;
    }
    EXPECT_GE(pose["timestamp"].as<double>(), 0.0);
    EXPECT_EQ(pose["frames"].size(), static_cast<std::size_t>(2 * shots));
    for (int c = 0; c < 2; ++c) {
      for (int k = 0; k < shots; ++k) {
        const fs::path image = dir / ("cam" + std::to_string(c) + "_" + std::to_string(k) + ".png");
        EXPECT_TRUE(fs::is_regular_file(image)) << image;
      }
    }
  }
  EXPECT_FALSE(fs::exists(session / ".capture-staging"));
}

void write_session_yaml(const fs::path& session) {
  std::ofstream(session / "session.yaml") << "format: robocal-session-1\n"
                                             "cameras:\n"
                                             "  - {name: cam0, width: 640, height: 480}\n"
                                             "  - {name: cam1, width: 640, height: 480}\n"
                                             "folders: {poses: poses}\n";
}

TEST(Capture, EveryPoseRecordedWithFramesBitExactAndReplayableAsARecordedSession) {
  SKIP_WITHOUT_NETNS();
  constexpr int kPoses = 5;
  const fs::path session = fresh_dir("bit_exact");
  GantryCell cell;
  // Enough history for every frame rendered in this test.
  CameraRig rig(cell, std::size_t{4} * kPoses);
  const auto targets = gantry_targets(kPoses);
  CaptureOptions options;
  options.session_start_ns = host_time_ns();
  const CaptureResult result = capture_poses(session, targets, cell, rig.capture, board(), options);
  ASSERT_TRUE(result.complete) << result.stop_reason;
  EXPECT_EQ(result.recorded(), kPoses);
  expect_complete_poses(session, targets, 2);

  // Bit-exact: each recorded image is exactly one rendered frame, in order, and was rendered
  // with the board at that pose's true position (the truth channel, not the readings).
  for (int c = 0; c < 2; ++c) {
    const auto rendered = rig.simulated[static_cast<std::size_t>(c)]->rendered();
    ASSERT_EQ(rendered.size(), static_cast<std::size_t>(2 * kPoses)) << "no retakes expected";
    for (int i = 0; i < kPoses; ++i) {
      for (int k = 0; k < 2; ++k) {
        const RenderedFrame& truth = rendered[static_cast<std::size_t>(2 * i + k)];
        const fs::path file = session / "poses" / pose_folder_name(i) /
                              ("cam" + std::to_string(c) + "_" + std::to_string(k) + ".png");
        const cv::Mat image = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
        ASSERT_EQ(image.size(), truth.image.size()) << file;
        EXPECT_EQ(cv::norm(image, truth.image, cv::NORM_INF), 0.0) << file;
        EXPECT_LT((truth.world_T_board.translation() - cell.world_T_board().translation() -
                   (targets[static_cast<std::size_t>(i)] - targets.back()).head<3>())
                      .norm(),
                  1e-12);
      }
    }
    EXPECT_EQ(result.poses[0].corners.size(), 2U);
    EXPECT_EQ(result.poses[0].corners[static_cast<std::size_t>(c)], 48) << "all corners seen";
  }
  // Timestamps increase from pose to pose.
  double last = -1.0;
  for (int i = 0; i < kPoses; ++i) {
    const double t =
        YAML::LoadFile(
            (session / "poses" / pose_folder_name(i) / "pose.yaml").string())["timestamp"]
            .as<double>();
    EXPECT_GT(t, last);
    last = t;
  }

  // The same folder read back through the recorded-session camera: the same frames, in order.
  write_session_yaml(session);
  RecordedSessionCamera recorded(session, "cam1");
  recorded.start(TriggerMode::kSoftware);
  const auto rendered = rig.simulated[1]->rendered();
  std::int64_t last_stamp = -1;
  for (std::size_t f = 0; f < rendered.size(); ++f) {
    const Frame frame = recorded.grab(std::chrono::milliseconds(100));
    EXPECT_EQ(cv::norm(frame.image, rendered[f].image, cv::NORM_INF), 0.0) << "frame " << f;
    EXPECT_GT(frame.timestamp_ns, last_stamp);
    last_stamp = frame.timestamp_ns;
  }
  EXPECT_THROW((void)recorded.grab(std::chrono::milliseconds(100)), CameraError);
}

// The targets the robot was moved to, by index (-1: none of them).
std::vector<int> targets_moved_to(const GantryCell& cell,
                                  const std::vector<Eigen::VectorXd>& targets) {
  std::vector<int> order;
  for (const Eigen::VectorXd& q : cell.moved_to()) {
    const auto it = std::find(targets.begin(), targets.end(), q);
    order.push_back(it == targets.end() ? -1 : static_cast<int>(it - targets.begin()));
  }
  return order;
}

// Captures `targets`; at the moves numbered in `swinging` (the first visits of those poses), the
// first shot series sees the board swing by 1.5-6 mm between shots.
CaptureResult capture_with_swings(const fs::path& session, GantryCell& cell,
                                  const std::vector<Eigen::VectorXd>& targets,
                                  const std::set<int>& swinging) {
  CameraRig rig(cell, 64);
  cell.before_move = [&cell, swinging](int move) {
    if (swinging.count(move) != 0) cell.wobble(4);
  };
  CaptureOptions options;
  options.session_start_ns = host_time_ns();
  return capture_poses(session, targets, cell, rig.capture, board(), options);
}

TEST(Capture, TargetMovingBetweenShotsIsRejectedAndRetaken) {
  SKIP_WITHOUT_NETNS();
  const fs::path session = fresh_dir("retake");
  GantryCell cell;
  const auto targets = gantry_targets(3);
  const CaptureResult result = capture_with_swings(session, cell, targets, {1});
  ASSERT_TRUE(result.complete) << result.stop_reason;
  EXPECT_EQ(result.poses[0].retakes, 0);
  EXPECT_GE(result.poses[1].retakes, 1);
  EXPECT_FALSE(result.poses[1].still_moving);
  EXPECT_EQ(result.poses[2].retakes, 0);
  // What was recorded for pose 1 is the still series: the last frames rendered at that pose.
  const YAML::Node pose =
      YAML::LoadFile((session / "poses" / pose_folder_name(1) / "pose.yaml").string());
  EXPECT_GE(pose["retakes"].as<int>(), 1);
  EXPECT_LT(pose["motion_chi2"].as<double>(), 30.0);
  expect_complete_poses(session, targets, 2);
  // The retake went back along the motion the robot made (pose 2 -> 1, the plan's 1 -> 2
  // reversed) as soon as the rejection was known.
  EXPECT_EQ(targets_moved_to(cell, targets), (std::vector<int>{0, 1, 2, 1}))
      << "pose 1 retaken from pose 2, then done";
}

// Two rejected poses in a row, the second rejected while the robot is on its way back: every
// retake still follows motions the robot made, and the plan goes on from where it left off.
TEST(Capture, RetakesFollowTheMotionsMadeAndThePlanGoesOn) {
  SKIP_WITHOUT_NETNS();
  const fs::path session = fresh_dir("retake_path");
  GantryCell cell;
  const auto targets = gantry_targets(5);
  const CaptureResult result = capture_with_swings(session, cell, targets, {1, 2});
  ASSERT_TRUE(result.complete) << result.stop_reason;
  expect_complete_poses(session, targets, 2);
  const std::vector<int> order = targets_moved_to(cell, targets);
  for (std::size_t k = 1; k < order.size(); ++k)
    EXPECT_LE(std::abs(order[k] - order[k - 1]), 1) << "motion " << k << " of " << order.size();
  EXPECT_GE(result.poses[1].retakes, 1);
  EXPECT_GE(result.poses[2].retakes, 1);
  EXPECT_EQ(order.back(), 4);
}

TEST(Capture, CameraLostMidSessionStopsTheRobotAndTheResumedRunCompletesWithoutDuplicates) {
  SKIP_WITHOUT_NETNS();
  const fs::path session = fresh_dir("resume");
  const auto targets = gantry_targets(6);
  GantryCell cell;
  CaptureOptions options;
  options.session_start_ns = host_time_ns();
  {
    CameraRig rig(cell, 8);
    cell.before_move = [&](int move) {
      if (move == 3) {
        rig.simulated[1]->server().disconnect();  // cam1's cable pulled during the move to pose 3
      }
    };
    const CaptureResult result =
        capture_poses(session, targets, cell, rig.capture, board(), options);
    EXPECT_FALSE(result.complete);
    ASSERT_TRUE(result.camera_error.has_value());
    EXPECT_EQ(*result.camera_error, CameraError::Kind::kDisconnected) << result.stop_reason;
    EXPECT_NE(result.stop_reason.find("pose pose_003: cam1: "), std::string::npos)
        << result.stop_reason;
    EXPECT_NE(result.stop_reason.find("robot stopped"), std::string::npos) << result.stop_reason;
    EXPECT_EQ(cell.stops(), 1);
    EXPECT_EQ(result.recorded(), 3);
    EXPECT_EQ(pose_folders(session), (std::set<std::string>{"pose_000", "pose_001", "pose_002"}));
    cell.before_move = nullptr;
  }
  // Cable back in: the same cameras again, the same targets; the run resumes at pose 3.
  const auto pose0_before = fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml");
  CameraRig rig(cell, 8);
  const CaptureResult resumed =
      capture_poses(session, targets, cell, rig.capture, board(), options);
  ASSERT_TRUE(resumed.complete) << resumed.stop_reason;
  EXPECT_EQ(resumed.already_recorded(), 3);
  EXPECT_EQ(resumed.recorded(), 3);
  expect_complete_poses(session, targets, 2);
  EXPECT_EQ(fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml"), pose0_before)
      << "recorded data rewritten";
}

// Atomic pose writing: a capture process killed while writing pose 2 (after its first image)
// leaves poses 0 and 1 whole and no pose_002; a new run completes pose 2.
TEST(Capture, ProcessKilledMidPoseLeavesNoHalfWrittenPoseAndARerunCompletesIt) {
  SKIP_WITHOUT_NETNS();
  const fs::path session = fs::temp_directory_path() / "robocal_capture_killed";
  const auto targets = gantry_targets(4);
  if (const char* child = std::getenv("ROBOCAL_CAPTURE_KILL_CHILD"); child != nullptr) {
    // The child: capture until the first file of pose_002 is on disk, then die at once.
    GantryCell cell;
    CameraRig rig(cell, 8);
    CaptureOptions options;
    options.on_file_written = [](const fs::path& file) {
      if (file.parent_path().filename() == "pose_002") {
        _exit(9);
      }
    };
    (void)capture_poses(session, targets, cell, rig.capture, board(), options);
    _exit(0);  // not reached when the kill happened
  }
  fs::remove_all(session);
  fs::create_directories(session);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    setenv("ROBOCAL_CAPTURE_KILL_CHILD", "1", 1);
    const std::string filter =
        "--gtest_filter=Capture.ProcessKilledMidPoseLeavesNoHalfWrittenPoseAndARerunCompletesIt";
    execl("/proc/self/exe", "/proc/self/exe", filter.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 9) << "the child did not die mid-pose";
  EXPECT_EQ(pose_folders(session), (std::set<std::string>{"pose_000", "pose_001"}));
  EXPECT_TRUE(fs::exists(session / ".capture-staging" / "pose_002"));  // the half-written one
  GantryCell cell;
  CameraRig rig(cell, 8);
  const CaptureResult rerun = capture_poses(session, targets, cell, rig.capture, board(), {});
  ASSERT_TRUE(rerun.complete) << rerun.stop_reason;
  EXPECT_EQ(rerun.already_recorded(), 2);
  EXPECT_EQ(rerun.recorded(), 2);
  expect_complete_poses(session, targets, 2);
}

TEST(Capture, FrameOfTheWrongSizeStopsWithAnErrorNamingTheCamera) {
  SKIP_WITHOUT_NETNS();
  const fs::path session = fresh_dir("wrong_size");
  GantryCell cell;
  CameraRig rig(cell, 8);
  // The session says cam1 is 800x600; the camera delivers 640x480.
  rig.capture[1].model.width = 800;
  rig.capture[1].model.height = 600;
  const CaptureResult result =
      capture_poses(session, gantry_targets(2), cell, rig.capture, board(), {});
  EXPECT_FALSE(result.complete);
  EXPECT_NE(
      result.stop_reason.find("cam1: frame of the wrong size: 640x480, the camera is 800x600"),
      std::string::npos)
      << result.stop_reason;
  EXPECT_EQ(cell.stops(), 1);
  EXPECT_TRUE(pose_folders(session).empty());
}

}  // namespace
}  // namespace robocal::robotio
