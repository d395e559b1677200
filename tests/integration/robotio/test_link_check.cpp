// `robocal link-check` as an adapter author runs it: against the simulated open link controller
// (every requirement passes), against the Python reference adapter (the same), and without the
// operator's confirmation (nothing moves). The simulator's log says whether anything moved.
#include "child_process.hpp"
#include "open_link_support.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>

namespace robocal::test {
namespace {

using robotio::SimControllerProcess;

class LinkCheckTest : public ScratchDirTest {
 protected:
  LinkCheckTest() : ScratchDirTest("link_check_") {}

  void start_sim() {
    log_ = file("sim.jsonl");
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY,
                                                  sim_args(log_, {"--protocol", "open"}));
    address_ = "open:" + sim_->tcp().substr(4);
  }
  struct Run {
    int status = -1;
    std::string output;
  };
  // `robocal link-check ADDRESS ... EXTRA` with nothing on its standard input.
  Run link_check(const std::string& address, const std::string& extra) const {
    std::vector<std::string> args = {"link-check", address,          "--speed",
                                     "0.2",        "--acceleration", "4"};
    std::stringstream words(extra);
    for (std::string w; words >> w;) args.push_back(w);
    ChildProcess run(ROBOCAL_BINARY, args, file("link_check.out"));
    Run r;
    r.status = run.wait(std::chrono::seconds(60));
    r.output = run.output();
    return r;
  }
  // Lines that begin with the verdict and two spaces. Scanned by hand: std::regex trips GCC 12's
  // maybe-uninitialized warning in the sanitizer build.
  static int count(const std::string& output, const std::string& verdict) {
    const std::string head = verdict + "  ";
    int n = 0;
    for (std::size_t at = 0; at < output.size();) {
      if (output.compare(at, head.size(), head) == 0) ++n;
      const std::size_t eol = output.find('\n', at);
      if (eol == std::string::npos) break;
      at = eol + 1;
    }
    return n;
  }

  std::string log_, address_;
  std::unique_ptr<SimControllerProcess> sim_;
};

constexpr const char* kBox = "--lower 0.05,0.05,0.05 --upper 0.3,0.3,0.3";

TEST_F(LinkCheckTest, SimulatedControllerPassesEveryRequirement) {
  start_sim();
  const Run r = link_check(address_, std::string(kBox) + " --yes");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(count(r.output, "FAIL"), 0) << r.output;
  EXPECT_EQ(count(r.output, "SKIP"), 0) << r.output;
  EXPECT_EQ(count(r.output, "PASS"), 13) << r.output;
  // The motion checks really moved the robot, inside the box: the simulator's record.
  const auto starts = events(read_sim_log(log_), "motion_start");
  ASSERT_EQ(starts.size(), 2u);
  for (const auto& m : starts)
    for (const double v : m["target_readings"].get<std::vector<double>>()) {
      EXPECT_GE(v, 0.05);
      EXPECT_LE(v, 0.3);
    }
  EXPECT_EQ(events(read_sim_log(log_), "stop").size(), 1u) << "the stop check stopped a move";
}

TEST_F(LinkCheckTest, WithoutConfirmationNothingMoves) {
  start_sim();
  const Run r = link_check(address_, kBox);  // standard input: nothing typed
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(count(r.output, "SKIP"), 2) << r.output;
  EXPECT_NE(r.output.find("the operator did not confirm motion"), std::string::npos) << r.output;
  EXPECT_TRUE(events(read_sim_log(log_), "motion_start").empty());
}

TEST_F(LinkCheckTest, RobotOutsideTheGivenLimitsIsNotMoved) {
  start_sim();  // the simulated robot starts at 0.3 m on every carriage
  const Run r = link_check(address_, "--lower 0.05,0.05,0.05 --upper 0.2,0.2,0.2 --yes");
  EXPECT_EQ(count(r.output, "SKIP"), 2) << r.output;
  EXPECT_NE(r.output.find("outside the limits given"), std::string::npos) << r.output;
  EXPECT_TRUE(events(read_sim_log(log_), "motion_start").empty());
}

TEST_F(LinkCheckTest, GarbageControllerFailsTheFramingCheck) {
  FakeController fake([](const std::string&) { return std::string("\x01 not json"); });
  const Run r = link_check(fake.address(), "--reply-timeout 0.3");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("FAIL  framing"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not JSON"), std::string::npos) << r.output;
}

TEST_F(LinkCheckTest, PythonReferenceAdapterPassesEveryRequirement) {
  const std::string python = "/usr/bin/python3";
  if (!std::filesystem::exists(python)) GTEST_SKIP() << python << " is not installed";
  ChildProcess adapter(python,
                       {std::string(ROBOCAL_SOURCE_DIR) + "/robotio/adapters/open_link_adapter.py",
                        "--port", "0", "--max-seconds", "300"},
                       file("adapter.out"));
  // The adapter announces its port on its first line.
  std::string announced;
  for (int i = 0; i < 400 && announced.find('\n') == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    announced = adapter.output();
  }
  ASSERT_EQ(announced.rfind("listening 127.0.0.1:", 0), 0u) << announced;
  const std::string address =
      "open:" + announced.substr(10, announced.find('\n') - 10);  // after "listening "
  const Run r = link_check(address, std::string(kBox) + " --yes");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(count(r.output, "FAIL"), 0) << r.output;
  EXPECT_EQ(count(r.output, "PASS"), 13) << r.output;
}

}  // namespace
}  // namespace robocal::test
