// Plausibility gates end to end: mistakes a new user makes, on a small rendered
// session, each with its verdict and exit code. A board file 5 % off is refused at measure and
// again at identify (no calibrated file), unless the operator accepts it explicitly; readings
// in degrees exclude their pose naming the unit; one camera's images swapped between two poses
// exclude those two poses; the rest calibrates.
#include "session_test_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include <fcntl.h>
#include <grp.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using robocal::test::copy_recorded;
using robocal::test::load_json;
using robocal::test::read_file;
using robocal::test::run_cli;

fs::path gate_scratch(const std::string& name) {
  const auto dir = fs::temp_directory_path() / ("robocal_e2e_gates_" + name);
  fs::remove_all(dir);
  return dir;
}

nlohmann::json pose_entry(const fs::path& session, const std::string& name) {
  const auto measured = load_json(session / "results" / "measured_poses.json");
  for (const auto& p : measured["poses"])
    if (p["pose"] == name) return p;
  ADD_FAILURE() << name << " not in measured_poses.json";
  return {};
}

class Gates : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // One per process: ctest runs each test in its own process, possibly at the same time.
    recorded_ = gate_scratch("recorded_" + std::to_string(::getpid()));
    ASSERT_EQ(run_cli({"simulate", "--quick", "--poses", "16", "--seed", "7", "--out",
                       recorded_.string()}),
              0);
  }
  static void TearDownTestSuite() { fs::remove_all(recorded_); }
  static fs::path recorded_;
};
fs::path Gates::recorded_;

TEST_F(Gates, BoardFileFivePercentOffIsRefusedUnlessTheOperatorAcceptsIt) {
  const fs::path s = gate_scratch("board");
  copy_recorded(recorded_, s);
  const fs::path board = s / "targets" / "end_effector.yaml";
  std::string text = read_file(board);
  const auto at = text.find("tag_size: ");
  ASSERT_NE(at, std::string::npos);
  const auto end = text.find('\n', at);
  const double size = std::stod(text.substr(at + 10, end - at - 10));
  text.replace(at, end - at, "tag_size: " + std::to_string(0.95 * size));
  std::ofstream(board, std::ios::trunc) << text;

  testing::internal::CaptureStdout();
  EXPECT_EQ(run_cli({"measure", s.string()}), 1);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("NOT PLAUSIBLE"), std::string::npos) << out;
  EXPECT_NE(out.find("board's file"), std::string::npos) << out;
  const auto measure = load_json(s / "results" / "measure.json");
  EXPECT_EQ(measure["status"], "implausible");
  EXPECT_FALSE(measure["board_fit_gate"]["plausible"].get<bool>());
  EXPECT_GT(measure["board_fit_gate"]["median_chi2_dof"].get<double>(), 25.0);

  testing::internal::CaptureStdout();
  EXPECT_EQ(run_cli({"identify", s.string()}), 1);
  const std::string ident_out = testing::internal::GetCapturedStdout();
  EXPECT_NE(ident_out.find("implausible"), std::string::npos) << ident_out;
  EXPECT_FALSE(fs::exists(s / "results" / "calibrated_robot.yaml"));

  // Accepted at measure: identify's own gate still refuses the fit (residuals far beyond the
  // measurement noise), and writes no calibrated file.
  EXPECT_EQ(run_cli({"measure", s.string(), "--accept-implausible"}), 0);
  EXPECT_TRUE(
      load_json(s / "results" / "measure.json")["board_fit_gate"]["overridden"].get<bool>());
  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 1);
  const auto refused = load_json(s / "results" / "identification.json");
  EXPECT_EQ(refused["status"], "implausible");
  EXPECT_NE(refused["message"].get<std::string>().find("stated noise"), std::string::npos)
      << refused["message"];
  EXPECT_FALSE(fs::exists(s / "results" / "calibrated_robot.yaml"));
  // The operator accepts it explicitly: the file is written and the override recorded.
  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pose", "--accept-implausible"}), 0);
  EXPECT_TRUE(fs::exists(s / "results" / "calibrated_robot.yaml"));
  EXPECT_TRUE(
      load_json(s / "results" / "identification.json")["fit_gate"]["overridden"].get<bool>());
}

TEST_F(Gates, DegreesAndSwappedImagesExcludeTheirPosesAndTheRestCalibrates) {
  const fs::path s = gate_scratch("poses");
  copy_recorded(recorded_, s);
  // pose_002's readings in degrees.
  const fs::path pose = s / "poses" / "pose_002" / "pose.yaml";
  std::string text = read_file(pose);
  const auto open = text.find('[');
  const auto close = text.find(']');
  std::string values = text.substr(open + 1, close - open - 1);
  std::string degrees;
  for (std::size_t start = 0; start < values.size();) {
    const auto comma = values.find(',', start);
    const double rad = std::stod(values.substr(start, comma - start));
    degrees += (degrees.empty() ? "" : ", ") + std::to_string(rad * 180.0 / std::numbers::pi);
    start = comma == std::string::npos ? values.size() : comma + 1;
  }
  text.replace(open + 1, close - open - 1, degrees);
  std::ofstream(pose, std::ios::trunc) << text;
  // cam1's images of pose_006 and pose_009 swapped.
  const fs::path a = s / "poses" / "pose_006" / "cam1.png";
  const fs::path b = s / "poses" / "pose_009" / "cam1.png";
  fs::rename(a, s / "swap.png");
  fs::rename(b, a);
  fs::rename(s / "swap.png", b);

  EXPECT_EQ(run_cli({"measure", s.string()}), 0);
  const auto deg = pose_entry(s, "pose_002");
  EXPECT_FALSE(deg["used"].get<bool>());
  EXPECT_NE(deg["excluded"].get<std::string>().find("in degrees?"), std::string::npos) << deg;
  EXPECT_NE(deg["excluded"].get<std::string>().find("poses/pose_002/pose.yaml"), std::string::npos)
      << deg;
  for (const char* name : {"pose_006", "pose_009"}) {
    const auto swapped = pose_entry(s, name);
    EXPECT_FALSE(swapped["used"].get<bool>()) << name;
    EXPECT_NE(swapped["excluded"].get<std::string>().find("images disagree"), std::string::npos)
        << swapped;
  }
  int used = 0;
  const auto measured = load_json(s / "results" / "measured_poses.json");
  for (const auto& p : measured["poses"]) used += p["used"].get<bool>() ? 1 : 0;
  EXPECT_EQ(used, 13);
  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 0);
  EXPECT_TRUE(
      load_json(s / "results" / "identification.json")["fit_gate"]["plausible"].get<bool>());
  EXPECT_TRUE(fs::exists(s / "results" / "calibrated_robot.yaml"));
}

// Beside the pose route, the camera-in-the-loop route is a second opinion: corner pixels that
// no model explains (here 1 px of added jitter, 50x the detector's noise, in
// results/pixel_observations.json only) fail its gate, and the pose route's calibration stands
// with a warning; asked for alone, that route's verdict is the identification's.
TEST_F(Gates, AnImplausiblePixelRouteLeavesThePoseRouteStanding) {
  const fs::path s = gate_scratch("pixels");
  copy_recorded(recorded_, s);
  ASSERT_EQ(run_cli({"measure", s.string()}), 0);
  const fs::path pixels = s / "results" / "pixel_observations.json";
  auto doc = load_json(pixels);
  std::uint32_t state = 12345;
  const auto jitter = [&state] {
    state = state * 1664525U + 1013904223U;
    return 2.0 * (static_cast<double>(state >> 8) / 16777216.0) - 1.0;  // [-1, 1) px
  };
  for (auto& pose : doc["poses"])
    for (auto& camera : pose["observations"])
      for (auto& corner : camera["corners"]) {
        corner[1] = corner[1].get<double>() + jitter();
        corner[2] = corner[2].get<double>() + jitter();
      }
  std::ofstream(pixels, std::ios::trunc) << doc.dump();

  EXPECT_EQ(run_cli({"identify", s.string()}), 0);
  const auto both = load_json(s / "results" / "identification.json");
  EXPECT_EQ(both["status"], "ok");
  EXPECT_EQ(both["pixel_route"]["status"], "implausible");
  ASSERT_TRUE(both.contains("warnings"));
  EXPECT_NE(both["warnings"][0].get<std::string>().find("camera-in-the-loop route implausible"),
            std::string::npos)
      << both["warnings"];
  EXPECT_TRUE(fs::exists(s / "results" / "calibrated_robot.yaml"));
  EXPECT_FALSE(fs::exists(s / "results" / "calibrated_robot_pixels.yaml"));

  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pixel"}), 1);
  const auto alone = load_json(s / "results" / "identification.json");
  EXPECT_EQ(alone["status"], "implausible");
  EXPECT_FALSE(fs::exists(s / "results" / "calibrated_robot_pixels.yaml"));
}

}  // namespace

namespace {

// The results folder cannot be written (here: a file stands where the folder should be; tests
// run as root, for whom permission bits do not stop a write): an input error naming the path,
// exit 3, not an internal error; the recorded data is untouched.
TEST_F(Gates, AResultsFolderThatCannotBeWrittenIsNamedWithExit3) {
  const fs::path s = gate_scratch("unwritable");
  copy_recorded(recorded_, s);
  std::ofstream(s / "results") << "not a folder\n";
  const auto before = robocal::test::recorded_fingerprint(s);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"measure", s.string()}), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("results"), std::string::npos) << err;
  EXPECT_EQ(err.find("internal error"), std::string::npos) << err;
  EXPECT_EQ(robocal::test::recorded_fingerprint(s), before);
}

// Runs `robocal args` in a child process whose output goes to `out`, as the unprivileged user
// nobody (uid and gid 65534) when the test runs as root: permission bits do not stop root, so a
// folder without read permission is only a folder without read permission for another user.
// Returns the exit code (-1 if the child did not exit, 99 if it could not drop root).
int run_cli_unprivileged(const std::vector<std::string>& args, const fs::path& out) {
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0 || ::dup2(fd, STDOUT_FILENO) < 0 || ::dup2(fd, STDERR_FILENO) < 0) ::_exit(98);
    if (::geteuid() == 0 &&
        (::setgroups(0, nullptr) != 0 || ::setgid(65534) != 0 || ::setuid(65534) != 0))
      ::_exit(99);
    const int code = run_cli(args);
    std::fflush(stdout);
    std::fflush(stderr);
    ::_exit(code);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Every folder and file under `dir` readable and writable by everyone (the unprivileged child
// writes results/ there).
void open_to_everyone(const fs::path& dir) {
  fs::permissions(dir, fs::perms::all, fs::perm_options::add);
  for (const auto& e : fs::recursive_directory_iterator(dir))
    fs::permissions(e.path(),
                    e.is_directory() ? fs::perms::all
                                     : fs::perms::owner_read | fs::perms::owner_write |
                                           fs::perms::group_read | fs::perms::group_write |
                                           fs::perms::others_read | fs::perms::others_write,
                    fs::perm_options::add);
}

// A pose folder this user may not read: the pose is left out with that cause named,
// not as "pose.yaml: missing", which sends the operator looking for a lost file.
TEST_F(Gates, APoseFolderWithoutReadPermissionIsNamedWithTheCause) {
  const fs::path s = gate_scratch("unreadable");
  copy_recorded(recorded_, s);
  open_to_everyone(s);
  for (fs::path p = s.parent_path(); p != p.root_path(); p = p.parent_path())
    ASSERT_TRUE((fs::status(p).permissions() & fs::perms::others_exec) != fs::perms::none)
        << p << " cannot be entered by another user: the test cannot run here";
  const fs::path pose = s / "poses" / "pose_003";
  fs::permissions(pose, fs::perms::none);
  const fs::path out = s.parent_path() / "robocal_e2e_gates_unreadable.out";
  const int code = run_cli_unprivileged({"measure", s.string()}, out);
  fs::permissions(pose, fs::perms::owner_all, fs::perm_options::add);
  const std::string text = read_file(out);
  EXPECT_EQ(code, 0) << text;  // the other poses are measured
  EXPECT_NE(
      text.find("pose_003 not used: " + (pose / "pose.yaml").string() + ": permission denied"),
      std::string::npos)
      << text;
  EXPECT_EQ(text.find("pose.yaml: missing"), std::string::npos) << text;
  fs::remove(out);
}

// A symbolic link loop inside a session folder is the session's problem, named with the link and
// the cause: exit 3 from measure, the session's error in batch's summary, never an internal error.
TEST_F(Gates, ASymbolicLinkLoopInASessionIsNamedNotAnInternalError) {
  const fs::path s = gate_scratch("link_loop");
  copy_recorded(recorded_, s);
  fs::create_symlink("loop_b", s / "poses" / "loop_a");
  fs::create_symlink("loop_a", s / "poses" / "loop_b");
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"measure", s.string()}), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("loop_"), std::string::npos) << err;
  EXPECT_NE(err.find("a symbolic link loop"), std::string::npos) << err;
  const fs::path summary = gate_scratch("link_loop_batch.json");
  testing::internal::CaptureStdout();
  EXPECT_EQ(run_cli({"batch", s.string(), "--json", summary.string()}), 1);
  const std::string out = testing::internal::GetCapturedStdout();
  const std::string json = read_file(summary);
  EXPECT_NE(json.find("a symbolic link loop"), std::string::npos) << json << out;
  EXPECT_EQ(json.find("internal error"), std::string::npos) << json;
  EXPECT_EQ(out.find("internal error"), std::string::npos) << out;
  fs::remove(summary);
}

// Camera files of another resolution than the rig views' images: the rig's refusal names the
// images' size and the camera file's, not only "sees the board in none of the views".
TEST_F(Gates, ARigCameraFileOfAnotherResolutionIsNamed) {
  const fs::path views = recorded_ / "calibration" / "rig";
  std::vector<std::string> args = {
      "rig",          "--target", (recorded_ / "targets" / "calibration.yaml").string(), "--views",
      views.string(), "--out",    gate_scratch("rig_resolution.json").string()};
  const std::string small = std::string(ROBOCAL_TESTDATA_DIR) + "/vision/camera_640x480.yaml";
  fs::path first_view;
  for (const auto& e : fs::directory_iterator(views))
    if (e.is_directory() && (first_view.empty() || e.path() < first_view)) first_view = e.path();
  for (const auto& e : fs::directory_iterator(first_view))
    if (e.path().extension() == ".png") {
      args.emplace_back("--camera");
      args.push_back(e.path().stem().string() + "=" + small);
    }
  ASSERT_GE(args.size(), 10U);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli(args), 1);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("sees the board"), std::string::npos) << err;
  EXPECT_NE(err.find("but camera '"), std::string::npos) << err;
  EXPECT_NE(err.find("for 640x480"), std::string::npos) << err;
}

// A board file with a column too many: every pose's fit is bad (and most ambiguous); the refusal
// blames the board's file, not each pose's images as swapped.
TEST_F(Gates, ABoardFileWithTheWrongColumnCountBlamesTheBoardFile) {
  const fs::path s = gate_scratch("columns");
  copy_recorded(recorded_, s);
  const fs::path board = s / "targets" / "end_effector.yaml";
  std::string text = read_file(board);
  const auto at = text.find("cols: ");
  ASSERT_NE(at, std::string::npos);
  const auto end = text.find('\n', at);
  const int cols = std::stoi(text.substr(at + 6, end - at - 6));
  text.replace(at, end - at, "cols: " + std::to_string(cols + 1));
  std::ofstream(board, std::ios::trunc) << text;
  testing::internal::CaptureStdout();
  EXPECT_EQ(run_cli({"measure", s.string()}), 1);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("NOT PLAUSIBLE"), std::string::npos) << out;
  EXPECT_NE(out.find("board's file does not match the printed board (its cols or rows"),
            std::string::npos)
      << out;
}

}  // namespace

namespace {

// Validation cannot flatter by drawing fewer configurations: for several sessions seeds (the
// seed of validation's draws), the configurations drawn equal the count requested, and the
// figures cover all of them except the ones a model could not answer (counted).
TEST_F(Gates, HeldOutCountEqualsTheRequestedCountForEverySeed) {
  const fs::path s = gate_scratch("held_out");
  copy_recorded(recorded_, s);
  ASSERT_EQ(run_cli({"measure", s.string()}), 0);
  ASSERT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 0);
  for (const int seed : {11, 23, 57, 101}) {
    std::string text = read_file(s / "session.yaml");
    const auto at = text.find("\nseed: ");
    ASSERT_NE(at, std::string::npos);
    const auto end = text.find('\n', at + 1);
    text.replace(at + 1, end - at - 1, "seed: " + std::to_string(seed));
    std::ofstream(s / "session.yaml", std::ios::trunc) << text;
    const int requested = 60 + seed;
    ASSERT_EQ(run_cli({"validate", s.string(), "--held-out", std::to_string(requested)}), 0);
    const auto v = load_json(s / "results" / "validation.json");
    EXPECT_EQ(v["held_out_drawn"].get<int>(), requested) << "seed " << seed;
    // Every drawn configuration is in the figures or is a counted failure of some model.
    int unanswered = 0;
    for (const auto& [model, n] : v["unanswered"].items()) unanswered += n.get<int>();
    EXPECT_GE(v["held_out_poses"].get<int>(), requested - unanswered) << "seed " << seed;
    EXPECT_LE(v["held_out_poses"].get<int>(), requested);
  }
}

}  // namespace

namespace {

// Validation certifies the calibrated robot file the user takes away: one that does not read as a
// robot file, or whose values are not the identified ones (edited by hand, copied from another
// run), is refused with exit 3 naming the file (and the parameter), not validated.
TEST_F(Gates, ValidateRefusesACalibratedFileThatIsNotTheIdentifiedModel) {
  const fs::path s = gate_scratch("calibrated_file");
  copy_recorded(recorded_, s);
  ASSERT_EQ(run_cli({"measure", s.string()}), 0);
  ASSERT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 0);
  const fs::path file = s / "results" / "calibrated_robot.yaml";
  const std::string good = read_file(file);
  ASSERT_EQ(run_cli({"validate", s.string(), "--held-out", "20"}), 0);

  std::ofstream(file, std::ios::trunc) << "robot: [\n";
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"validate", s.string(), "--held-out", "20"}), 3);
  std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("calibrated_robot.yaml: cannot be read as a robot file"), std::string::npos)
      << err;

  // The first parameter value written as a number (`params: {a1: 0.00547...`), changed by 1 mm or
  // 1 mrad in the text.
  std::size_t at = 0;
  for (std::size_t key = good.find("params: {"); key != std::string::npos;
       key = good.find("params: {", key + 1)) {
    const std::size_t value = good.find(": ", key + 9);
    if (value != std::string::npos &&
        std::string("-0123456789").find(good[value + 2]) != std::string::npos) {
      at = value + 2;
      break;
    }
  }
  ASSERT_GT(at, 0u) << "no numeric parameter value in " << file;
  std::size_t end = at;
  while (end < good.size() && std::string("+-0123456789.e").find(good[end]) != std::string::npos)
    ++end;
  std::string edited = good;
  edited.replace(at, end - at, std::to_string(std::stod(good.substr(at, end - at)) + 1e-3));
  std::ofstream(file, std::ios::trunc) << edited;
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"validate", s.string(), "--held-out", "20"}), 3);
  err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("in the file but"), std::string::npos) << err;
  EXPECT_EQ(err.find("internal error"), std::string::npos) << err;
}

}  // namespace
