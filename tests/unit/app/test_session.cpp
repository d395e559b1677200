// Session folder files (app/SESSION.md): session.yaml round trip and errors with file:line,
// pose readings (NaN, wrong count, malformed), atomic writes that never overwrite recorded data.
#include "cli/cli_common.hpp"
#include "session/session.hpp"

#include "robocal/core/files.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

namespace robocal::app {
namespace {

namespace fs = std::filesystem;

Session example() {
  Session s;
  s.software = "robocal test";
  s.created = "2026-01-01T00:00:00Z";
  s.source = "simulated";
  s.seed = 42;
  s.robot_name = "rotary_delta";
  s.measured_frame = "tool";
  s.actuators = 3;
  s.cameras = {{"cam0", 640, 480}, {"cam1", 800, 600}};
  return s;
}

std::string error_of(const std::string& text) {
  try {
    parse_session_yaml(text, "s/session.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

fs::path scratch(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("robocal_unit_session_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(SessionFile, RoundTrips) {
  const Session s = example();
  const Session r = parse_session_yaml(session_to_yaml(s), "x");
  EXPECT_EQ(r.robot_name, "rotary_delta");
  EXPECT_EQ(r.measured_frame, "tool");
  EXPECT_EQ(r.actuators, 3);
  EXPECT_EQ(r.seed, 42U);
  ASSERT_EQ(r.cameras.size(), 2U);
  EXPECT_EQ(r.cameras[1].name, "cam1");
  EXPECT_EQ(r.cameras[1].width, 800);
  EXPECT_EQ(r.cameras[1].height, 600);
  EXPECT_EQ(r.poses, "poses");
  EXPECT_EQ(r.rig_views, "calibration/rig");
}

TEST(SessionFile, ErrorsNameFileAndLine) {
  std::string text = session_to_yaml(example());
  // Which line holds "actuators:" (1-based)?
  int line = 1;
  for (std::size_t i = 0; i < text.find("actuators:"); ++i) line += text[i] == '\n' ? 1 : 0;
  std::string broken = text;
  broken.replace(broken.find("actuators: 3"), 12, "actuators: three");
  const std::string e1 = error_of(broken);
  EXPECT_NE(e1.find("s/session.yaml:" + std::to_string(line)), std::string::npos) << e1;
  EXPECT_NE(e1.find("actuators"), std::string::npos) << e1;

  broken = text;
  broken.replace(broken.find("actuators: 3"), 12, "actuators: [3");  // not YAML
  EXPECT_NE(error_of(broken).find("s/session.yaml:"), std::string::npos) << error_of(broken);

  broken = text;
  broken.replace(broken.find("robocal-session-1"), 17, "something-else");
  EXPECT_NE(error_of(broken).find("format"), std::string::npos);

  broken = text;
  broken.replace(broken.find("width: 800"), 10, "width: -5");
  EXPECT_NE(error_of(broken).find("cam1"), std::string::npos) << error_of(broken);

  EXPECT_NE(error_of("- just\n- a list\n").find("mapping"), std::string::npos);
  const std::string no_robot = error_of("format: robocal-session-1\n");
  EXPECT_NE(no_robot.find("s/session.yaml:1: 'robot' must be a mapping"), std::string::npos)
      << no_robot;
}

TEST(SessionFile, NotASessionIsSaidClearly) {
  const auto dir = scratch("empty");
  EXPECT_FALSE(is_session(dir));
  try {
    load_session(dir);
    FAIL() << "expected an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("session.yaml"), std::string::npos);
  }
}

TEST(PoseRecords, BadReadingsGiveAProblemNotAnException) {
  const auto dir = scratch("poses");
  Session s = example();
  s.dir = dir;
  const auto write = [&](const std::string& pose, const std::string& text) {
    fs::create_directories(dir / "poses" / pose);
    std::ofstream(dir / "poses" / pose / "pose.yaml") << text;
  };
  write("pose_000", "actuators: [0.1, 0.2, 0.3]\ntimestamp: 4.5\n");
  write("pose_001", "actuators: [0.1, .nan, 0.3]\n");
  write("pose_002", "actuators: [0.1, 0.2]\n");
  write("pose_003", "actuators: [0.1, x, 0.3]\n");
  fs::create_directories(dir / "poses" / "pose_004");  // no pose.yaml
  write("pose_005", "actuators: [0.1, 0.2\n");         // not YAML
  const auto records = load_pose_records(s);
  ASSERT_EQ(records.size(), 6U);
  EXPECT_TRUE(records[0].problem.empty()) << records[0].problem;
  EXPECT_DOUBLE_EQ(records[0].actuators[2], 0.3);
  EXPECT_DOUBLE_EQ(records[0].timestamp, 4.5);
  EXPECT_NE(records[1].problem.find("actuators[1] is nan"), std::string::npos)
      << records[1].problem;
  EXPECT_NE(records[1].problem.find("pose_001/pose.yaml:1"), std::string::npos)
      << records[1].problem;
  EXPECT_NE(records[2].problem.find("2 actuator readings"), std::string::npos)
      << records[2].problem;
  EXPECT_NE(records[3].problem.find("actuators[1] is not a number"), std::string::npos)
      << records[3].problem;
  EXPECT_NE(records[4].problem.find("missing"), std::string::npos) << records[4].problem;
  EXPECT_NE(records[5].problem.find("not valid YAML"), std::string::npos) << records[5].problem;

  PoseRecord r;
  r.name = "p";
  r.actuators = Eigen::Vector3d(0.1, 1.0 / 3.0, -2e-7);
  r.timestamp = 2;
  write("pose_006", pose_record_yaml(r));
  const auto again = load_pose_records(s);
  EXPECT_EQ(again[6].actuators, r.actuators) << "readings round-trip exactly";
}

// A pose folder copied under another name (same readings, same time) is not used twice: it
// carries a problem naming the original, so measure excludes it with that reason.
TEST(PoseRecords, CopiedPoseFolderIsRefusedNamingTheOriginal) {
  const auto dir = scratch("poses_dup");
  Session s = example();
  s.dir = dir;
  const auto write = [&](const std::string& pose, const std::string& text) {
    fs::create_directories(dir / "poses" / pose);
    std::ofstream(dir / "poses" / pose / "pose.yaml") << text;
  };
  write("pose_003", "actuators: [0.1, 0.2, 0.3]\ntimestamp: 12.25\n");
  write("pose_003_dup", "actuators: [0.1, 0.2, 0.3]\ntimestamp: 12.25\n");
  write("pose_004", "actuators: [0.1, 0.2, 0.3]\ntimestamp: 13.5\n");  // a repeat: later
  write("pose_005", "actuators: [0.4, 0.2, 0.3]\n");
  write("pose_006", "actuators: [0.4, 0.2, 0.3]\n");  // no time: a deliberate repeat, kept
  const auto records = load_pose_records(s);
  ASSERT_EQ(records.size(), 5U);
  EXPECT_TRUE(records[0].problem.empty()) << records[0].problem;
  EXPECT_NE(records[1].problem.find("a copy of pose_003"), std::string::npos) << records[1].problem;
  EXPECT_TRUE(records[2].problem.empty()) << records[2].problem;
  EXPECT_TRUE(records[3].problem.empty()) << records[3].problem;
  EXPECT_TRUE(records[4].problem.empty()) << records[4].problem;
}

TEST(AtomicWrite, RecordedFilesAreNeverOverwritten) {
  const auto dir = scratch("atomic");
  const auto f = dir / "sub" / "a.txt";
  using robocal::core::Overwrite;
  using robocal::core::read_text_file;
  using robocal::core::write_file_atomic;
  write_file_atomic(f, "first", Overwrite::kRefuse);
  EXPECT_EQ(read_text_file(f), "first");
  EXPECT_THROW(write_file_atomic(f, "second", Overwrite::kRefuse), InputError);
  EXPECT_EQ(read_text_file(f), "first");
  write_file_atomic(f, "third", Overwrite::kReplace);  // results may be replaced
  EXPECT_EQ(read_text_file(f), "third");
  EXPECT_FALSE(fs::exists(dir / "sub" / "a.txt.tmp"));
}

}  // namespace
}  // namespace robocal::app
