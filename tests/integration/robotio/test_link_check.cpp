// `robocal link-check` as an adapter author runs it: against the simulated open link controller
// (every requirement passes), against the Python reference adapter (the same), and without the
// operator's confirmation (nothing moves). The simulator's log says whether anything moved.
#include "open_link_support.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <regex>

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
  CommandResult link_check(const std::string& address, const std::string& extra) const {
    return run_command(std::string(ROBOCAL_BINARY) + " link-check " + address +
                       " --speed 0.2 --acceleration 4 " + extra);
  }
  int count(const std::string& output, const std::string& verdict) const {
    const std::regex line("(^|\n)" + verdict + "  ");
    return static_cast<int>(
        std::distance(std::sregex_iterator(output.begin(), output.end(), line), {}));
  }

  std::string log_, address_;
  std::unique_ptr<SimControllerProcess> sim_;
};

constexpr const char* kBox = "--lower 0.05,0.05,0.05 --upper 0.3,0.3,0.3";

TEST_F(LinkCheckTest, SimulatedControllerPassesEveryRequirement) {
  start_sim();
  const CommandResult r = link_check(address_, std::string(kBox) + " --yes");
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
  const CommandResult r = link_check(address_, kBox);  // standard input: nothing typed
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(count(r.output, "SKIP"), 2) << r.output;
  EXPECT_NE(r.output.find("the operator did not confirm motion"), std::string::npos) << r.output;
  EXPECT_TRUE(events(read_sim_log(log_), "motion_start").empty());
}

TEST_F(LinkCheckTest, RobotOutsideTheGivenLimitsIsNotMoved) {
  start_sim();  // the simulated robot starts at 0.3 m on every carriage
  const CommandResult r = link_check(address_, "--lower 0.05,0.05,0.05 --upper 0.2,0.2,0.2 --yes");
  EXPECT_EQ(count(r.output, "SKIP"), 2) << r.output;
  EXPECT_NE(r.output.find("outside the limits given"), std::string::npos) << r.output;
  EXPECT_TRUE(events(read_sim_log(log_), "motion_start").empty());
}

TEST_F(LinkCheckTest, GarbageControllerFailsTheFramingCheck) {
  FakeController fake([](const std::string&) { return std::string("\x01 not json"); });
  const CommandResult r = link_check(fake.address(), "--reply-timeout 0.3");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("FAIL  framing"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("not JSON"), std::string::npos) << r.output;
}

TEST_F(LinkCheckTest, PythonReferenceAdapterPassesEveryRequirement) {
  if (std::system("python3 -c 'import selectors' >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3 is not installed";
  ChildProcess adapter({"python3",
                        std::string(ROBOCAL_SOURCE_DIR) + "/robotio/adapters/open_link_adapter.py",
                        "--port", "0", "--exit-with-parent", "--max-seconds", "300"});
  const std::string announced = adapter.line(std::chrono::seconds(20));
  ASSERT_EQ(announced.rfind("listening 127.0.0.1:", 0), 0u) << announced;
  const std::string address = "open:" + announced.substr(std::string("listening ").size());
  const CommandResult r = link_check(address, std::string(kBox) + " --yes");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(count(r.output, "FAIL"), 0) << r.output;
  EXPECT_EQ(count(r.output, "PASS"), 13) << r.output;
}

}  // namespace
}  // namespace robocal::test
