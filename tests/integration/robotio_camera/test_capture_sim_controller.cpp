// Capture against the simulated controller as a separate process: `robocal sim-controller`
// holds a perturbed linear delta (the true robot) and serves Marlin over TCP; robocal drives it
// through the guarded G-code link; two simulated GigE Vision cameras (127.0.0.1, 127.0.0.2,
// run_in_netns.sh) render the board where the simulator's true-pose channel says it is.
#include "robocal/robotio/link_error.hpp"
#include "sim_camera_cell.hpp"

#include "netns_skip.hpp"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;
using testing::kSimCellSpeed;
using testing::sim_cell_mounting;
using testing::SimCell;

std::set<std::string> pose_folders(const fs::path& session) {
  std::set<std::string> names;
  if (fs::exists(session / "poses")) {
    for (const auto& entry : fs::directory_iterator(session / "poses")) {
      names.insert(entry.path().filename().string());
    }
  }
  return names;
}

TEST(CaptureSimController, PosesRecordedBitExactAtTheTruePoseAndALostCameraStopsTheController) {
  SKIP_WITHOUT_NETNS();
  constexpr int kPoses = 8;
  const fs::path dir = fs::temp_directory_path() / "robocal_capture_sim";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path session = dir / "session";
  SimCell cell(dir);
  const auto goals = testing::sim_cell_targets(cell.model, kPoses);
  const vision::TargetBoard board =
      vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml"));
  LinkCaptureRobot robot(*cell.link, kSimCellSpeed);
  CaptureOptions options;
  options.session_start_ns = host_time_ns();

  // Run 1: camera 1's cable is pulled while pose 2 is being written (the robot is on its way
  // to pose 3).
  int motions_before_stop = 0;
  {
    testing::CameraRig rig(*cell.truth, 64);
    bool pulled = false;
    options.on_file_written = [&](const fs::path& file) {
      if (!pulled && file.parent_path().filename() == "pose_002") {
        pulled = true;
        rig.simulated[1]->server().disconnect();
      }
    };
    const CaptureResult result = capture_poses(session, goals, robot, rig.capture, board, options);
    options.on_file_written = nullptr;
    EXPECT_FALSE(result.complete);
    ASSERT_TRUE(result.camera_error.has_value()) << result.stop_reason;
    EXPECT_EQ(*result.camera_error, CameraError::Kind::kDisconnected) << result.stop_reason;
    EXPECT_NE(result.stop_reason.find("cam1"), std::string::npos) << result.stop_reason;
    EXPECT_GE(result.recorded(), 3);
    EXPECT_LT(result.recorded(), kPoses);
    // The controller was told to stop (its own record), and the guard refuses motion until the
    // operator confirms again.
    const auto log = test::read_sim_log(cell.log);
    EXPECT_GE(test::received(log, "M410"), 1) << "no controlled stop reached the controller";
    EXPECT_TRUE(cell.guard->stop_requested());
    EXPECT_NE(cell.guard->stop_reason().find("cam1"), std::string::npos)
        << cell.guard->stop_reason();
    EXPECT_THROW(cell.link->move_actuators(goals[0], kSimCellSpeed), MotionRefused);
    motions_before_stop = static_cast<int>(test::events(log, "motion_start").size());

    // What was recorded is a prefix of the targets, frames bit-exact: each recorded image is
    // one rendered frame, in render order.
    std::set<std::string> expect;
    for (int i = 0; i < result.recorded(); ++i) {
      expect.insert(pose_folder_name(i));
    }
    EXPECT_EQ(pose_folders(session), expect);
    const auto rendered = rig.simulated[0]->rendered();
    ASSERT_GE(rendered.size(), static_cast<std::size_t>(2 * result.recorded()));
    for (int i = 0; i < result.recorded(); ++i) {
      for (int k = 0; k < 2; ++k) {
        const fs::path file =
            session / "poses" / pose_folder_name(i) / ("cam0_" + std::to_string(k) + ".png");
        const cv::Mat image = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
        const cv::Mat& truth = rendered[static_cast<std::size_t>(2 * i + k)].image;
        ASSERT_EQ(image.size(), truth.size()) << file;
        EXPECT_EQ(cv::norm(image, truth, cv::NORM_INF), 0.0) << file;
      }
    }
  }

  // Cable back in, the operator confirms, the same targets: the run resumes where it stopped.
  cell.guard->resume();
  cell.guard->arm("test: camera reconnected");
  const auto pose0_written = fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml");
  testing::CameraRig rig(*cell.truth, 64);
  const CaptureResult resumed = capture_poses(session, goals, robot, rig.capture, board, options);
  ASSERT_TRUE(resumed.complete) << resumed.stop_reason;
  EXPECT_EQ(resumed.already_recorded() + resumed.recorded(), kPoses);
  EXPECT_EQ(pose_folders(session).size(), static_cast<std::size_t>(kPoses));
  EXPECT_EQ(fs::last_write_time(session / "poses" / "pose_000" / "pose.yaml"), pose0_written)
      << "recorded data rewritten";
  // The resumed run moved only to the poses it recorded: no pose driven to twice after resume.
  const auto log = test::read_sim_log(cell.log);
  EXPECT_EQ(static_cast<int>(test::events(log, "motion_start").size()) - motions_before_stop,
            resumed.recorded());

  // Every pose: the controller's settled readings are the target (within half a step), and
  // the last frame shows the board exactly where the true robot stands now.
  for (int i = 0; i < kPoses; ++i) {
    const YAML::Node pose =
        YAML::LoadFile((session / "poses" / pose_folder_name(i) / "pose.yaml").string());
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(pose["actuators"][a].as<double>(), goals[static_cast<std::size_t>(i)][a],
                  0.5 / 80.0 / 1000.0 + 1e-12)
          << pose_folder_name(i);
    }
  }
  const RenderedFrame last = rig.simulated[0]->rendered().back();
  EXPECT_LT((last.world_T_board.translation() - cell.truth->world_T_board().translation()).norm(),
            1e-12);
  // The truth is not the nominal model: the board is where the perturbed robot put it, which
  // differs from the nominal forward kinematics of the same readings.
  const calib::ForwardResult nominal = calib::forward_kinematics(
      cell.model, cell.model.nominal_parameters(), goals.back(), cell.model.tool);
  const Eigen::Vector3d nominal_board =
      (sim_cell_mounting().world_T_base * nominal.pose * sim_cell_mounting().task_T_board)
          .translation();
  EXPECT_GT((last.world_T_board.translation() - nominal_board).norm(), 50e-6);
}

}  // namespace
}  // namespace robocal::robotio
