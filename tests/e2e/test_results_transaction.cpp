// Results replaced whole or not at all (core/staging.hpp, session/results_transaction.hpp): on a
// processed session (simulate --quick, 12 poses, measure, identify, validate), every way a
// command can stop midway — Ctrl-C or SIGTERM at chosen moments, a truncated input file, a full
// disk (a small tmpfs, where the machine lets the test mount one), a folder given as a file —
// leaves the previous results byte for byte as they were and no temporary or staging file
// behind. A staging folder a SIGKILL left is removed by the next run. `plan` never replaces a
// file with a plan it rejects; an interrupted or failed `simulate` leaves no folder.
#include "child_process.hpp"
#include "session_test_support.hpp"
#include "test_paths.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/mount.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using robocal::test::ChildProcess;
using robocal::test::read_file;
using robocal::test::run_cli;

// The temporary folder shared by the test processes: TMPDIR as the program started, before each
// test points it at its own folder (tests/support/per_test_tmpdir.cpp).
const fs::path shared_tmp = fs::temp_directory_path();

// The processed session the tests start from, made once per build of this test binary and shared
// by its test processes (ctest runs each test as its own process): simulate + measure + identify
// + validate take about 35 s, a copy a fraction of a second. Those of earlier builds are removed.
fs::path processed_session() {
  const auto stamp = fs::last_write_time("/proc/self/exe").time_since_epoch().count();
  const std::string prefix = "robocal_tx_processed_";
  const fs::path dir = shared_tmp / (prefix + std::to_string(stamp));
  const std::string lock_path = (shared_tmp / (prefix + "lock")).string();
  const int lock = ::open(lock_path.c_str(), O_CREAT | O_RDWR, 0644);
  EXPECT_GE(lock, 0) << lock_path;
  ::flock(lock, LOCK_EX);
  if (!fs::exists(dir / "ready")) {
    for (const auto& e : fs::directory_iterator(shared_tmp))
      if (e.path().filename().string().rfind(prefix, 0) == 0 && e.is_directory())
        fs::remove_all(e.path());
    const fs::path s = dir / "s";
    EXPECT_EQ(run_cli({"simulate", "--quick", "--poses", "12", "--seed", "3", "--out", s.string()}),
              0);
    EXPECT_EQ(run_cli({"measure", s.string()}), 0);
    EXPECT_EQ(run_cli({"identify", s.string()}), 0);
    EXPECT_EQ(run_cli({"validate", s.string(), "--held-out", "50"}), 0);
    std::ofstream(dir / "ready") << "ok\n";
  }
  ::flock(lock, LOCK_UN);
  ::close(lock);
  return dir / "s";
}

// A copy of the processed session at `to`.
fs::path copy_of_processed(const fs::path& to) {
  fs::remove_all(to);
  fs::create_directories(to.parent_path());
  fs::copy(processed_session(), to, fs::copy_options::recursive);
  return to;
}

// results/ as bytes, by relative path: what "unchanged" is compared on.
std::map<std::string, std::string> results_bytes(const fs::path& session) {
  std::map<std::string, std::string> out;
  const fs::path results = session / "results";
  for (const auto& e : fs::recursive_directory_iterator(results))
    if (e.is_regular_file())
      out[fs::relative(e.path(), results).generic_string()] = read_file(e.path());
  return out;
}

// Temporary files and staging folders under `root` (a folder) and beside it (a staging folder or
// a temporary of `root` itself).
std::vector<std::string> leftovers(const fs::path& root) {
  std::vector<std::string> out;
  const auto check = [&out](const fs::path& p) {
    const std::string name = p.filename().string();
    if (name.find(".staging-") != std::string::npos || p.extension() == ".tmp")
      out.push_back(p.string());
  };
  if (fs::is_directory(root))
    for (const auto& e : fs::recursive_directory_iterator(root)) check(e.path());
  const std::string name = root.filename().string();
  for (const auto& e : fs::directory_iterator(root.parent_path())) {
    const std::string sibling = e.path().filename().string();
    if (sibling.rfind("." + name + ".staging-", 0) == 0 || sibling == name + ".tmp")
      check(e.path());
  }
  return out;
}

// `rel` inside the staging folder of `target` (a file of the new results not yet committed);
// empty while there is none.
fs::path staged(const fs::path& target, const std::string& rel) {
  const std::string prefix = "." + target.filename().string() + ".staging-";
  std::error_code ec;
  for (fs::directory_iterator it(target.parent_path(), ec), end; !ec && it != end;
       it.increment(ec)) {
    if (it->path().filename().string().rfind(prefix, 0) != 0) continue;
    fs::path p = it->path() / target.filename() / rel;
    if (fs::exists(p, ec)) return p;
  }
  return {};
}

// Waits (up to two minutes) until `ready` holds while `child` runs; false when the child ended
// first.
bool wait_until(ChildProcess& child, const std::function<bool()>& ready) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::minutes(2);
  while (std::chrono::steady_clock::now() < end) {
    if (ready()) return true;
    if (!child.running()) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

std::string signal_name(int sig) {
  return sig == SIGINT ? "SIGINT" : "SIGTERM";
}

// Runs `robocal <args>` on a copy of the processed session, sends `sig` once `moment` (a file
// of the staged results, "" = the staging folder itself) exists, and checks that the command
// ended by the signal with the previous results byte for byte and nothing left over.
void interrupt_at(const std::string& command, const std::string& moment, int sig) {
  SCOPED_TRACE(command + " interrupted by " + signal_name(sig) + " once the staging holds '" +
               moment + "'");
  const fs::path s = copy_of_processed(fs::temp_directory_path() / "s");
  const auto before = results_bytes(s);
  ChildProcess child(ROBOCAL_BINARY, {command, s.string()},
                     (fs::temp_directory_path() / "out.txt").string());
  ASSERT_TRUE(wait_until(child, [&] { return !staged(s / "results", moment).empty(); }))
      << "the command ended before the moment came:\n"
      << child.output();
  child.signal(sig);
  EXPECT_EQ(child.wait(std::chrono::seconds(60)), 128 + sig) << child.output();
  EXPECT_NE(child.output().find("interrupted"), std::string::npos) << child.output();
  EXPECT_EQ(results_bytes(s), before) << "the previous results changed";
  EXPECT_EQ(leftovers(s), std::vector<std::string>{});
}

TEST(ResultsTransaction, MeasureStoppedMidwayKeepsThePreviousResults) {
  // At the start (the previous results being copied, intrinsics calibrating) and after the new
  // cameras and rig are staged, while the board poses are measured: the moment the old
  // identification, calibrated files and validation.json used to be gone already.
  for (int sig : {SIGINT, SIGTERM}) {
    interrupt_at("measure", "", sig);
    interrupt_at("measure", "rig.json", sig);
  }
}

TEST(ResultsTransaction, IdentifyStoppedMidwayKeepsThePreviousResults) {
  // At the start, and once the new calibrated_robot.yaml is staged but identification.json is
  // not (the camera-in-the-loop route runs between them): the moment that used to leave a new
  // calibrated robot beside the old identification.
  for (int sig : {SIGINT, SIGTERM}) {
    interrupt_at("identify", "", sig);
    interrupt_at("identify", "calibrated_robot.yaml", sig);
  }
}

// Identify on a results/ input cut in half: exit 3 naming the file, and results/ as it was
// (the truncated file included): no calibrated robot file without its identification.json.
void truncated_input_fails_cleanly(const std::string& file) {
  SCOPED_TRACE(file);
  const fs::path s = copy_of_processed(fs::temp_directory_path() / "s");
  const fs::path input = s / "results" / file;
  const std::string text = read_file(input);
  std::ofstream(input, std::ios::binary | std::ios::trunc) << text.substr(0, text.size() / 2);
  const auto before = results_bytes(s);
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"identify", s.string()}), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find(file), std::string::npos) << err;
  EXPECT_EQ(results_bytes(s), before) << "the previous results changed";
  EXPECT_EQ(leftovers(s), std::vector<std::string>{});
}

TEST(ResultsTransaction, IdentifyOnATruncatedRigFileChangesNothing) {
  truncated_input_fails_cleanly("rig.json");
}

TEST(ResultsTransaction, IdentifyOnTruncatedPixelObservationsChangesNothing) {
  truncated_input_fails_cleanly("pixel_observations.json");
}

// A staging folder that a SIGKILL left (no handler runs) is not results: results/ is unchanged,
// and the next run removes the folder.
TEST(ResultsTransaction, AStagingFolderAKilledRunLeftIsRemovedByTheNextRun) {
  const fs::path s = copy_of_processed(fs::temp_directory_path() / "s");
  const auto before = results_bytes(s);
  {
    ChildProcess child(ROBOCAL_BINARY, {"identify", s.string()},
                       (fs::temp_directory_path() / "out.txt").string());
    ASSERT_TRUE(wait_until(child, [&] {
      return !staged(s / "results", "calibrated_robot.yaml").empty();
    })) << child.output();
    child.signal(SIGKILL);
    EXPECT_EQ(child.wait(std::chrono::seconds(60)), 128 + SIGKILL);
  }
  EXPECT_EQ(results_bytes(s), before);
  ASSERT_EQ(leftovers(s).size(), 1U) << "the killed run's staging folder";
  EXPECT_EQ(run_cli({"validate", s.string(), "--held-out", "50"}), 0);
  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 0);
  EXPECT_EQ(leftovers(s), std::vector<std::string>{});
  EXPECT_FALSE(fs::exists(s / "results" / "validation.json"))
      << "validation.json judged the previous identification";
}

// A small tmpfs mounted at `dir`, unmounted when the test ends; skips the test (with the reason)
// where the machine does not allow the mount.
class Tmpfs {
 public:
  Tmpfs(fs::path dir, const std::string& size) : dir_(std::move(dir)) {
    fs::create_directories(dir_);
    const std::string options = "size=" + size;
    if (::mount("tmpfs", dir_.c_str(), "tmpfs", 0, options.c_str()) == 0)
      mounted_ = true;
    else
      why_ = std::strerror(errno);
  }
  ~Tmpfs() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  Tmpfs(const Tmpfs&) = delete;
  Tmpfs& operator=(const Tmpfs&) = delete;
  Tmpfs(Tmpfs&&) = delete;
  Tmpfs& operator=(Tmpfs&&) = delete;
  [[nodiscard]] bool mounted() const { return mounted_; }
  [[nodiscard]] const std::string& why() const { return why_; }

  // Fills the file system until `free_bytes` are left.
  void leave_free(std::uintmax_t free_bytes) const {
    struct statvfs st {};
    ASSERT_EQ(::statvfs(dir_.c_str(), &st), 0);
    const std::uintmax_t available = static_cast<std::uintmax_t>(st.f_bavail) * st.f_frsize;
    ASSERT_GT(available, free_bytes);
    std::ofstream filler(dir_ / "filler", std::ios::binary);
    const std::string chunk(1 << 16, '\0');
    for (std::uintmax_t left = available - free_bytes; left > 0;) {
      const std::uintmax_t n = std::min<std::uintmax_t>(left, chunk.size());
      filler.write(chunk.data(), static_cast<std::streamsize>(n));
      left -= n;
    }
    filler.flush();
  }

 private:
  fs::path dir_;
  bool mounted_ = false;
  std::string why_;
};

// The space files take on the tmpfs (whole pages), but those named in `but`.
std::uintmax_t folder_bytes(const fs::path& dir, const std::vector<std::string>& but = {}) {
  std::uintmax_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() &&
        std::find(but.begin(), but.end(), e.path().filename().string()) == but.end())
      n += (e.file_size() + 4095) / 4096 * 4096;
  return n;
}

// A full disk while the new results are written: measure's board poses (2.9 MB of corner pixels)
// do not fit after its cameras and rig did; identify's calibrated robot file fits, its
// identification.json does not (the staged copy of the results it keeps fits just before).
TEST(ResultsTransaction, AFullDiskChangesNothing) {
  const Tmpfs disk(fs::temp_directory_path() / "disk", "64m");
  if (!disk.mounted())
    GTEST_SKIP() << "a tmpfs cannot be mounted here (" << disk.why()
                 << "): the full disk is not simulated";
  const fs::path s = copy_of_processed(fs::temp_directory_path() / "disk" / "s");
  const auto before = results_bytes(s);

  disk.leave_free(std::uintmax_t{512} << 10);
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"measure", s.string()}), 3);
  testing::internal::GetCapturedStdout();
  std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("pixel_observations.json"), std::string::npos) << err;
  EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
  EXPECT_EQ(results_bytes(s), before) << "measure changed the previous results";
  EXPECT_EQ(leftovers(s), std::vector<std::string>{});

  fs::remove(fs::temp_directory_path() / "disk" / "filler");
  const std::uintmax_t kept =
      folder_bytes(s / "results", {"identification.json", "calibrated_robot.yaml",
                                   "calibrated_robot_pixels.yaml", "validation.json"});
  disk.leave_free(kept + (std::uintmax_t{64} << 10));
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"identify", s.string(), "--route", "pose"}), 3);
  testing::internal::GetCapturedStdout();
  err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("identification.json"), std::string::npos) << err;
  EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
  EXPECT_EQ(results_bytes(s), before) << "identify changed the previous results";
  EXPECT_EQ(leftovers(s), std::vector<std::string>{});
}

// simulate on a disk too small for its images, and simulate interrupted while it renders: no
// session folder (not even a partial one), no staging folder, no temporary file.
TEST(ResultsTransaction, AnUnfinishedSimulateLeavesNothing) {
  const fs::path out = fs::temp_directory_path() / "sim" / "s";
  fs::create_directories(out.parent_path());
  for (int sig : {SIGINT, SIGTERM}) {
    SCOPED_TRACE(signal_name(sig));
    ChildProcess child(ROBOCAL_BINARY,
                       {"simulate", "--quick", "--poses", "12", "--out", out.string()},
                       (fs::temp_directory_path() / "out.txt").string());
    ASSERT_TRUE(wait_until(child, [&] { return !staged(out, "calibration").empty(); }))
        << child.output();
    child.signal(sig);
    EXPECT_EQ(child.wait(std::chrono::seconds(60)), 128 + sig) << child.output();
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(fs::is_empty(out.parent_path())) << leftovers(out).size();
  }

  const Tmpfs disk(fs::temp_directory_path() / "disk", "8m");
  if (!disk.mounted())
    GTEST_SKIP() << "a tmpfs cannot be mounted here (" << disk.why()
                 << "): the full disk is not simulated";
  const fs::path full = fs::temp_directory_path() / "disk" / "s";
  testing::internal::CaptureStderr();
  EXPECT_EQ(run_cli({"simulate", "--quick", "--poses", "12", "--out", full.string()}), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("No space left on device"), std::string::npos) << err;
  EXPECT_TRUE(fs::is_empty(full.parent_path()))
      << fs::directory_iterator(full.parent_path())->path();
}

// A plan the planner rejects (here: no plan meets a condition number of 1) is not written: the
// existing plan and preview stay byte for byte.
TEST(ResultsTransaction, PlanNeverReplacesAFileWithARejectedPlan) {
  const fs::path dir = fs::temp_directory_path();
  const fs::path plan = dir / "plan.yaml", svg = dir / "plan.svg";
  std::ofstream(plan) << "the plan the operator had\n";
  std::ofstream(svg) << "<svg/>\n";
  testing::internal::CaptureStdout();
  EXPECT_EQ(run_cli({"plan", "--cell",
                     std::string(ROBOCAL_TESTDATA_DIR) + "/cells/delta_two_cameras.yaml", "--count",
                     "5", "--pool", "300", "--no-order", "--max-condition", "1", "--out",
                     plan.string(), "--svg", svg.string()}),
            1);
  const std::string out = testing::internal::GetCapturedStdout();
  EXPECT_NE(out.find("NOT accepted"), std::string::npos) << out;
  EXPECT_NE(out.find("no plan written"), std::string::npos) << out;
  EXPECT_EQ(read_file(plan), "the plan the operator had\n");
  EXPECT_EQ(read_file(svg), "<svg/>\n");
  EXPECT_EQ(leftovers(plan), std::vector<std::string>{});
  EXPECT_EQ(leftovers(svg), std::vector<std::string>{});
}

// intrinsics with -o naming a folder: exit 3 naming it, no "<folder>.tmp", and neither the
// report nor the SVG replaced (they go with the camera file or not at all).
TEST(ResultsTransaction, IntrinsicsOntoAFolderWritesNothing) {
  const fs::path s = copy_of_processed(fs::temp_directory_path() / "s");
  const fs::path dir = fs::temp_directory_path() / "out";
  fs::create_directories(dir / "emptyd");
  std::ofstream(dir / "report.json") << "{\"previous\": true}\n";
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int code = run_cli({"intrinsics", "--images", (s / "calibration/intrinsics/cam0").string(),
                            "--target", (s / "targets/calibration.yaml").string(), "-o",
                            (dir / "emptyd").string(), "--report", (dir / "report.json").string(),
                            "--svg", (dir / "coverage.svg").string()});
  testing::internal::GetCapturedStdout();
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(code, 3);
  EXPECT_NE(err.find("emptyd: is a folder"), std::string::npos) << err;
  EXPECT_EQ(read_file(dir / "report.json"), "{\"previous\": true}\n");
  EXPECT_FALSE(fs::exists(dir / "coverage.svg"));
  EXPECT_TRUE(fs::is_empty(dir / "emptyd"));
  EXPECT_EQ(leftovers(dir), std::vector<std::string>{});
}

// identify on a measurements file with --out-robot and --json naming a folder: exit 3 naming it,
// and the calibrated robot file as it was (it goes with its report or not at all).
TEST(ResultsTransaction, IdentifyFileModeWritesTheRobotWithItsReportOrNeither) {
  const fs::path dir = fs::temp_directory_path();
  const std::string robot = std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml";
  const fs::path m = dir / "m.yaml", calibrated = dir / "calibrated.yaml";
  testing::internal::CaptureStdout();
  ASSERT_EQ(run_cli({"identify", "--robot", robot, "--simulate", m.string()}), 0);
  testing::internal::GetCapturedStdout();
  std::ofstream(calibrated) << "the calibrated robot the operator had\n";
  fs::create_directories(dir / "report");
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  const int code =
      run_cli({"identify", "--robot", robot, "--measurements", m.string(), "--out-robot",
               calibrated.string(), "--json", (dir / "report").string()});
  testing::internal::GetCapturedStdout();
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(code, 3);
  EXPECT_NE(err.find("report: is a folder"), std::string::npos) << err;
  EXPECT_EQ(read_file(calibrated), "the calibrated robot the operator had\n");
  EXPECT_TRUE(fs::is_empty(dir / "report"));
  EXPECT_EQ(leftovers(calibrated), std::vector<std::string>{});
}

}  // namespace
