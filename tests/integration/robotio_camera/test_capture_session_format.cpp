// A captured session is read by the pipeline's own session reader (app/src/session/session.hpp, the
// one `measure`, `identify` and `batch` use): every pose loads with its readings, nothing flagged.
#include "camera_cell.hpp"
#include "netns_skip.hpp"
#include "robocal/robotio/capture.hpp"
#include "session/session.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;

TEST(CaptureSessionFormat, ThePipelinesSessionReaderLoadsEveryCapturedPose) {
  SKIP_WITHOUT_NETNS();
  const fs::path dir = fs::temp_directory_path() / "robocal_capture_session_format";
  fs::remove_all(dir);
  testing::GantryCell cell;
  testing::CameraRig rig(cell, 8);
  const auto targets = testing::gantry_targets(3);
  CaptureOptions options;
  options.session_start_ns = host_time_ns();
  const CaptureResult result = capture_poses(
      dir, targets, cell, rig.capture,
      vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml")), options);
  ASSERT_TRUE(result.complete) << result.stop_reason;

  app::Session session;
  session.dir = dir;
  session.actuators = 3;
  session.cameras = {{"cam0", 640, 480}, {"cam1", 640, 480}};
  const std::vector<app::PoseRecord> records = app::load_pose_records(session);
  ASSERT_EQ(records.size(), targets.size());
  for (std::size_t i = 0; i < records.size(); ++i) {
    EXPECT_EQ(records[i].name, pose_folder_name(static_cast<int>(i)));
    EXPECT_TRUE(records[i].problem.empty()) << records[i].problem;
    ASSERT_EQ(records[i].actuators.size(), 3);
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(records[i].actuators[a], targets[i][a]);
    }
    if (i > 0) {
      EXPECT_GT(records[i].timestamp, records[i - 1].timestamp);
    }
  }
}

}  // namespace
}  // namespace robocal::robotio
