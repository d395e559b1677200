// A captured session is read by the pipeline's own session reader (app/src/session/session.hpp, the
// one `measure`, `identify` and `batch` use): every pose loads with its readings, nothing flagged.
#include "camera_cell.hpp"
#include "netns_skip.hpp"
#include "robocal/robotio/capture.hpp"
#include "robocal/vision/detection_record.hpp"
#include "robocal/vision/image_detection.hpp"
#include "session/session.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;

// Three poses of the gantry captured into a fresh temporary folder `name`.
struct CapturedSession {
  fs::path dir;
  std::vector<Eigen::VectorXd> targets = testing::gantry_targets(3);
  vision::TargetBoard board =
      vision::load_target_file(testing::testdata("vision/apriltag_4x3.yaml"));
  CaptureResult result;
  explicit CapturedSession(const std::string& name) : dir(fs::temp_directory_path() / name) {
    fs::remove_all(dir);
    testing::GantryCell cell;
    testing::CameraRig rig(cell, 8);
    CaptureOptions options;
    options.session_start_ns = host_time_ns();
    result = capture_poses(dir, targets, cell, rig.capture, board, options);
  }
};

TEST(CaptureSessionFormat, ThePipelinesSessionReaderLoadsEveryCapturedPose) {
  SKIP_WITHOUT_NETNS();
  const CapturedSession captured("robocal_capture_session_format");
  ASSERT_TRUE(captured.result.complete) << captured.result.stop_reason;
  const fs::path& dir = captured.dir;
  const auto& targets = captured.targets;

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

// The detections the settled-frame test made are recorded in each pose folder, and each equals
// what measure's own detection of the written image gives (the first frame detected in full, the
// second refined from it), so measure can take them instead of detecting again.
TEST(CaptureSessionFormat, RecordedDetectionsEqualDetectingTheWrittenImagesAgain) {
  SKIP_WITHOUT_NETNS();
  const CapturedSession captured("robocal_capture_detection_record");
  ASSERT_TRUE(captured.result.complete) << captured.result.stop_reason;
  const fs::path& dir = captured.dir;
  const auto& targets = captured.targets;
  const vision::TargetBoard& board = captured.board;

  const std::string signature =
      vision::detection_signature(board, vision::detector_options_for(board));
  int compared = 0;
  for (std::size_t i = 0; i < targets.size(); ++i) {
    const fs::path pose = dir / "poses" / pose_folder_name(static_cast<int>(i));
    const vision::DetectionRecord record =
        vision::read_detection_record(pose / vision::kDetectionRecordFile, signature);
    for (const std::string camera : {"cam0", "cam1"}) {
      const std::vector<vision::DetectionRequest> series = {{pose / (camera + "_0.png"), 0, 0, ""},
                                                            {pose / (camera + "_1.png"), 0, 0, ""}};
      const auto fresh = vision::detect_in_image_series({series}, board, 1)[0];
      for (std::size_t shot = 0; shot < series.size(); ++shot) {
        const std::string file = series[shot].image.filename().string();
        // The first shot of every camera is recorded; the second where the first saw the board.
        if (shot == 0 || fresh[0].problem.empty()) {
          ASSERT_EQ(record.count(file), 1u) << pose << "/" << file;
        }
        if (record.count(file) == 0) continue;
        const vision::TargetDetection& recorded = record.at(file).detection;
        const vision::TargetDetection& again = fresh[shot].detection;
        EXPECT_EQ(recorded.status, again.status) << file;
        EXPECT_EQ(recorded.corner_ids, again.corner_ids) << file;
        EXPECT_EQ(recorded.pixels, again.pixels) << file;  // bit for bit
        ASSERT_EQ(recorded.corner_groups.size(), again.corner_groups.size()) << file;
        for (std::size_t g = 0; g < again.corner_groups.size(); ++g) {
          EXPECT_EQ(recorded.corner_groups[g].covariance, again.corner_groups[g].covariance);
        }
        compared += recorded.pixels.empty() ? 0 : 1;
      }
    }
  }
  EXPECT_GE(compared, 6);  // the board seen by both cameras at every pose, twice
}

}  // namespace
}  // namespace robocal::robotio
