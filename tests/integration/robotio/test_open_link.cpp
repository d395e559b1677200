// The open link (robotio/OPEN_LINK.md) against `robocal sim-controller --protocol open` running
// as its own process, over a real loopback socket. The simulator's JSONL log is the independent
// record of what the controller received and executed; stand-in controllers answer garbage, an
// old version or the wrong actuators.
#include "open_link_support.hpp"
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/open_link.hpp"
#include "robocal/robotio/sim_controller.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <numbers>
#include <ostream>
#include <thread>

namespace robocal::test {
namespace {

using robotio::LinkError;
using robotio::MotionInterrupted;
using robotio::MotionRefused;
using robotio::MoveSpeed;
using robotio::OpenLink;
using robotio::SafetyGuard;
using robotio::SimControllerProcess;

constexpr MoveSpeed kSpeed{0.2, 4.0};

std::string open_address(const SimControllerProcess& sim) {
  return "open:" + sim.tcp().substr(4);  // "tcp:127.0.0.1:P" -> "open:127.0.0.1:P"
}

robotio::OpenLinkOptions open_options(const std::string& address) {
  robotio::OpenLinkOptions o;
  o.address = address;
  o.reply_timeout = std::chrono::milliseconds(500);
  o.reconnect_attempts = 3;
  return o;
}

class OpenLinkTest : public ScratchDirTest {
 protected:
  OpenLinkTest() : ScratchDirTest("open_link_") {}

  void start(std::vector<std::string> extra = {}, const std::string& robot = "linear_delta") {
    log_ = file("sim.jsonl");
    extra.insert(extra.begin(), {"--protocol", "open"});
    std::vector<std::string> args = sim_args(log_, extra);
    args[1] = robot;  // sim_args starts with --robot linear_delta
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, args);
    guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
    guard_->arm("test: simulated cell, nothing can be hurt");
  }
  std::unique_ptr<OpenLink> link() {
    return std::make_unique<OpenLink>(*guard_, open_options(open_address(*sim_)));
  }
  std::vector<nlohmann::json> log() const { return read_sim_log(log_); }
  // Motions the simulator started towards exactly these counts.
  int motions_to(const std::vector<long>& counts) const {
    int n = 0;
    for (const auto& m : events(log(), "motion_start"))
      if (m["to"].get<std::vector<long>>() == counts) ++n;
    return n;
  }
  // Requests the simulator received with this command.
  int requests(const std::string& cmd) const {
    int n = 0;
    for (const auto& rx : events(log(), "rx")) {
      const auto j = nlohmann::json::parse(rx.value("line", ""), nullptr, false);
      if (j.is_object() && j.value("cmd", "") == cmd) ++n;
    }
    return n;
  }
  // The counts of the last motion the simulator finished (its truth, not the link's report).
  std::vector<long> last_motion_end() const {
    const auto ends = events(log(), "motion_end");
    return ends.empty() ? std::vector<long>{} : ends.back()["counts"].get<std::vector<long>>();
  }
  void write_script(const std::string& text) { std::ofstream(file("faults.txt")) << text; }

  calib::Mechanism model_ = linear_delta();
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SafetyGuard> guard_;
};

TEST_F(OpenLinkTest, ConnectsHomesMovesAndReadsBackEveryTargetOnTheTruthLog) {
  start();
  auto l = link();
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_NE(fw.name.find("robocal simulated controller (linear_delta)"), std::string::npos);
  EXPECT_EQ(fw.version, "1.0");
  l->home();
  for (const Eigen::VectorXd& target : delta_targets(model_, 5, 3)) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const std::vector<long> expect = l->counts_for(target);
    EXPECT_EQ(r.readings.counts, expect);
    EXPECT_EQ(last_motion_end(), expect) << "the simulator's own record of where it stopped";
    for (int i = 0; i < 3; ++i)  // converted values within half a step (6.25 um) of the target
      EXPECT_NEAR(r.readings.values[i], target[i], 0.5 * 1.25e-5 + 1e-12);
    EXPECT_EQ(motions_to(expect), 1) << "each move executed exactly once";
  }
  EXPECT_EQ(requests("hello"), 1);
}

TEST_F(OpenLinkTest, MoveTakesTheTimeOfItsSpeedOnTheSimulator) {
  start();
  auto l = link();
  l->connect();
  const auto targets = delta_targets(model_, 1, 11);
  const Eigen::VectorXd from = l->read_actuators().values;
  const robotio::MoveResult r = l->move_actuators(targets[0], kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  const auto starts = events(log(), "motion_start");
  ASSERT_EQ(starts.size(), 1u);
  // The simulator ran the move for the trapezoid of the joint length at kSpeed; the link waited
  // for it rather than reading a moving robot.
  const double joint_length = (targets[0] - from).norm();
  EXPECT_NEAR(starts[0]["duration_s"].get<double>(),
              robotio::trapezoid_seconds(joint_length, kSpeed.speed, kSpeed.acceleration), 1e-3);
  EXPECT_GE(r.seconds, starts[0]["duration_s"].get<double>());
}

TEST_F(OpenLinkTest, StopRequestDuringAMoveSendsTheStopAndTheSessionResumes) {
  start();
  auto l = link();
  l->connect();
  const auto targets = delta_targets(model_, 2, 5);
  Eigen::VectorXd far = targets[0];
  std::thread stopper([this] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    guard_->request_stop("test: operator pressed Ctrl-C");
  });
  EXPECT_THROW(l->move_actuators(far, MoveSpeed{0.02, 1.0}), MotionInterrupted);
  stopper.join();
  const auto stops = events(log(), "stop");
  ASSERT_EQ(stops.size(), 1u);
  EXPECT_EQ(stops[0]["cmd"], "stop controlled");
  const auto ends = events(log(), "motion_end");
  ASSERT_EQ(ends.size(), 1u);
  EXPECT_TRUE(ends[0]["stopped"].get<bool>()) << "the motion ended by the stop, not at its target";
  // Refused until the operator confirms again; nothing reaches the controller meanwhile.
  const int moves_before = requests("move");
  EXPECT_THROW(l->move_actuators(targets[1], kSpeed), MotionRefused);
  EXPECT_EQ(requests("move"), moves_before);
  guard_->resume();
  guard_->arm("test: resumed");
  const robotio::MoveResult r = l->move_actuators(targets[1], kSpeed);
  EXPECT_TRUE(r.confirmed) << r.reason;
}

TEST_F(OpenLinkTest, EmergencyStopHaltsTheControllerAndLaterMovesAreRefusedByIt) {
  start();
  auto l = link();
  l->connect();
  l->stop(robotio::RobotLink::StopKind::kEmergency);
  EXPECT_EQ(l->status().state, robotio::LinkState::kFault);
  const auto stops = events(log(), "stop");
  ASSERT_EQ(stops.size(), 1u);
  EXPECT_EQ(stops[0]["cmd"], "stop emergency");
  try {
    l->move_actuators(delta_targets(model_, 1, 6)[0], kSpeed);
    FAIL() << "a halted controller must not move";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("error 202: halted by an emergency stop"),
              std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

TEST_F(OpenLinkTest, ReconnectsAndFindsTheRobotWhereItWas) {
  start();
  auto l = link();
  l->connect();
  const auto targets = delta_targets(model_, 2, 9);
  ASSERT_TRUE(l->move_actuators(targets[0], kSpeed).confirmed);
  const std::vector<long> before = l->read_actuators().counts;
  l->disconnect();
  l->reconnect();
  EXPECT_EQ(l->read_actuators().counts, before);
  EXPECT_TRUE(l->move_actuators(targets[1], kSpeed).confirmed);
  EXPECT_EQ(requests("hello"), 2);
  EXPECT_EQ(l->status().reconnects, 1);
}

TEST_F(OpenLinkTest, NothingMovesUnconfirmed) {
  start();
  guard_->disarm();
  auto l = link();
  l->connect();
  const auto targets = delta_targets(model_, 1, 4);
  EXPECT_THROW(l->move_actuators(targets[0], kSpeed), MotionRefused);
  EXPECT_THROW(l->home(), MotionRefused);
  EXPECT_EQ(requests("move"), 0);
  EXPECT_EQ(requests("home"), 0);
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

// Every fault kind of the open protocol, forced by a fault script on one request of the first
// move: requests 1 and 2 are the connection's hello and read, then move (3), wait_settled (4)
// and read (5).
struct FaultCase {
  std::string kind;
  int request;
};
void PrintTo(const FaultCase& c, std::ostream* os) {
  *os << c.kind << " on request " << c.request;
}

class OpenLinkFaultTest : public OpenLinkTest, public ::testing::WithParamInterface<FaultCase> {};

TEST_P(OpenLinkFaultTest, EndsConfirmedAtTheTargetOrFailedWithItsReason) {
  const FaultCase c = GetParam();
  write_script(std::to_string(c.request) + " " + c.kind + "\n");
  start({"--fault-script", file("faults.txt"), "--slow-ms", "300"});
  auto l = link();
  l->connect();
  const Eigen::VectorXd target = delta_targets(model_, 1, 21)[0];
  const std::vector<long> expect = l->counts_for(target);
  if (c.kind == "stall" && c.request == 3) {
    try {
      l->move_actuators(target, kSpeed);
      FAIL() << "a stalled move must not be confirmed";
    } catch (const LinkError& e) {
      EXPECT_NE(std::string(e.what()).find("did not settle"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("open link 127.0.0.1:"), std::string::npos);
    }
    const auto stops = events(log(), "stop");
    ASSERT_EQ(stops.size(), 1u) << "the stalled move is stopped";
    EXPECT_NE(last_motion_end(), expect);
    return;
  }
  const robotio::MoveResult r = l->move_actuators(target, kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  EXPECT_EQ(r.readings.counts, expect);
  EXPECT_EQ(last_motion_end(), expect);
  EXPECT_EQ(motions_to(expect), 1) << "neither lost nor executed twice";
  const auto faults = events(log(), "fault");
  ASSERT_EQ(faults.size(), 1u) << "the fault happened";
  EXPECT_EQ(faults[0]["kind"], c.kind);
  if (c.kind == "drop") {
    EXPECT_GE(l->status().reconnects, 1);
  }
  if (c.kind == "garbage") {
    EXPECT_GE(l->status().garbage, 1);
  }
  if (c.kind == "lost_ok") {
    EXPECT_GE(l->status().resends, 1);
  }
}

std::vector<FaultCase> fault_cases() {
  std::vector<FaultCase> out;
  for (const char* kind : {"drop", "busy", "error", "stall", "lost_ok", "slow", "garbage"})
    for (int request : {3, 4, 5}) {
      if (std::string(kind) == "stall" && request != 3) continue;  // only moves stall
      out.push_back({kind, request});
    }
  return out;
}

INSTANTIATE_TEST_SUITE_P(Kinds, OpenLinkFaultTest, ::testing::ValuesIn(fault_cases()),
                         [](const ::testing::TestParamInfo<FaultCase>& p) {
                           return p.param.kind + "_on_request_" + std::to_string(p.param.request);
                         });

// Random faults of every kind the protocol has, over many moves: each move ends confirmed at
// its target (the simulator's own record agrees) or failed with a reason, and no target is
// driven to twice.
class OpenLinkSoakTest : public OpenLinkTest, public ::testing::WithParamInterface<int> {};

TEST_P(OpenLinkSoakTest, EveryMoveConfirmedOnceOrFailedWithItsReason) {
  start({"--faults", "all=0.04", "--fault-seed", std::to_string(GetParam()), "--slow-ms", "200"});
  auto l = link();
  l->connect();
  int confirmed = 0;
  for (const Eigen::VectorXd& target : delta_targets(model_, 12, 40 + GetParam())) {
    const std::vector<long> expect = l->counts_for(target);
    try {
      const robotio::MoveResult r = l->move_actuators(target, kSpeed);
      ASSERT_TRUE(r.confirmed) << r.reason;
      EXPECT_EQ(last_motion_end(), expect);
      EXPECT_EQ(motions_to(expect), 1) << "neither lost nor executed twice";
      ++confirmed;
    } catch (const LinkError& e) {
      // Only a stalled move may fail: the controller's stop is in its log.
      EXPECT_NE(std::string(e.what()).find("did not settle"), std::string::npos) << e.what();
      EXPECT_FALSE(events(log(), "stop").empty());
      EXPECT_LE(motions_to(expect), 1);
    }
  }
  EXPECT_GE(confirmed, 8);
  EXPECT_FALSE(events(log(), "fault").empty()) << "the soak injected faults";
}

INSTANTIATE_TEST_SUITE_P(Seeds, OpenLinkSoakTest, ::testing::Values(1, 2, 3));

TEST_F(OpenLinkTest, RefusedEveryTimeFailsWithTheControllersWordsAndNothingMoves) {
  write_script("3 error\n4 error\n5 error\n6 error\n");
  start({"--fault-script", file("faults.txt")});
  auto l = link();
  l->connect();
  try {
    l->move_actuators(delta_targets(model_, 1, 2)[0], kSpeed);
    FAIL() << "a move refused four times must fail";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'move' refused 4 times: error 200"), std::string::npos) << what;
    EXPECT_NE(what.find("injected fault"), std::string::npos) << what;
  }
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

// ---- bad controllers ---------------------------------------------------------------------------

TEST_F(OpenLinkTest, GarbageAnsweringControllerIsRefusedNamingDeviceAndWhatItSaid) {
  guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
  FakeController fake([](const std::string&) { return std::string("\x01\x02garbage \x7f"); });
  OpenLink l(*guard_, open_options(fake.address()));
  try {
    l.connect();
    FAIL() << "a controller answering garbage must be refused";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("open link 127.0.0.1:"), std::string::npos) << what;
    EXPECT_NE(what.find("no reply to 'hello'"), std::string::npos) << what;
    EXPECT_NE(what.find("not JSON"), std::string::npos) << what;
    EXPECT_NE(e.controller_said().find("garbage"), std::string::npos) << what;
  }
  for (const std::string& line : fake.received())
    EXPECT_EQ(line.find("\"move\""), std::string::npos) << "nothing but hello was sent";
}

TEST_F(OpenLinkTest, MuteControllerIsRefusedAfterItsAttempts) {
  start({"--mute"});
  auto l = link();
  try {
    l->connect();
    FAIL() << "a controller that never answers must be refused";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("open link 127.0.0.1:"), std::string::npos) << what;
    EXPECT_NE(what.find("no reply to 'hello' after 4 attempts"), std::string::npos) << what;
  }
  EXPECT_EQ(requests("hello"), 4) << "the same request, repeated after each silence";
  EXPECT_EQ(requests("move"), 0);
}

TEST_F(OpenLinkTest, SimulatorOfAnOlderVersionRefusesTheClientAndTheLinkSaysSo) {
  start({"--open-version", "0.9"});
  auto l = link();
  try {
    l->connect();
    FAIL() << "version 0.9 must not be accepted";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("refuses robocal-open-link 1.0"), std::string::npos) << what;
    EXPECT_NE(what.find("speaks robocal-open-link 0.9"), std::string::npos) << what;
  }
  EXPECT_EQ(requests("move"), 0);
}

TEST_F(OpenLinkTest, WrongActuatorCountIsRefusedNamingBoth) {
  start({}, "ur5");  // a 6-axis controller for a 3-actuator robot file
  auto l = link();
  try {
    l->connect();
    FAIL() << "a controller with 6 actuators must not drive a 3-actuator robot";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("reports 6 actuators"), std::string::npos) << what;
    EXPECT_NE(what.find("'linear_delta' has 3"), std::string::npos) << what;
    EXPECT_NE(what.find("robocal simulated controller (ur5)"), std::string::npos) << what;
  }
  EXPECT_EQ(requests("move"), 0);
}

TEST_F(OpenLinkTest, ControllerOfAnOlderVersionIsRefusedWithBothVersions) {
  guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
  FakeController fake([](const std::string& line) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    nlohmann::json actuators = nlohmann::json::array();
    for (int i = 0; i < 3; ++i)
      actuators.push_back({{"name", "c" + std::to_string(i)}, {"unit", "m"}, {"resolution", 1e-5}});
    return nlohmann::json{{"id", j.value("id", 0)},          {"ok", true},
                          {"protocol", "robocal-open-link"}, {"version", {0, 9}},
                          {"controller", "old lab adapter"}, {"actuators", actuators}}
        .dump();
  });
  OpenLink l(*guard_, open_options(fake.address()));
  try {
    l.connect();
    FAIL() << "an older controller must be refused";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'old lab adapter' speaks robocal-open-link 0.9, older than this "
                        "robocal's 1.0: update the controller's adapter"),
              std::string::npos)
        << what;
  }
}

}  // namespace
}  // namespace robocal::test

namespace robocal::test {
namespace {

// The flange_pose capability (OPEN_LINK.md, `read`): every read carries the controller's base ->
// flange pose. The simulator's truth is the nominal robot here (no --seed), so the pose must be
// the robot file's at the link's readings, to the simulated actuators' noise and backlash
// (2 + 5 um per actuator).
TEST_F(OpenLinkTest, ReadsCarryTheControllersFlangePoseWhenItHasTheCapability) {
  start();
  auto l = link();
  l->connect();
  EXPECT_TRUE(l->reports_flange_pose());
  l->home();
  const robotio::FlangeFrames frames = robotio::flange_frames(model_);
  const Eigen::VectorXd nominal = model_.nominal_parameters();
  for (const Eigen::VectorXd& target : delta_targets(model_, 3, 7)) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    ASSERT_TRUE(r.readings.base_T_flange.has_value());
    const auto fk = calib::forward_kinematics(model_, nominal, r.readings.values, frames.flange);
    ASSERT_TRUE(fk.closure.ok());
    const Eigen::Isometry3d base = frames.base >= 0
                                       ? calib::frame_pose(model_, nominal, fk.state, frames.base)
                                       : Eigen::Isometry3d::Identity();
    const Eigen::Isometry3d expected = base.inverse() * fk.pose;
    const Eigen::Isometry3d& got = *r.readings.base_T_flange;
    EXPECT_LT((got.translation() - expected.translation()).norm(), 20e-6);
    EXPECT_LT(Eigen::AngleAxisd(got.linear() * expected.linear().transpose()).angle(), 1e-4);
  }
}

TEST_F(OpenLinkTest, AControllerWithoutTheFlangePoseCapabilityReportsNone) {
  start({"--no-flange-pose"});
  auto l = link();
  l->connect();
  EXPECT_FALSE(l->reports_flange_pose());
  EXPECT_FALSE(l->read_actuators().base_T_flange.has_value());
}

// A reply's flange pose that is not one is named, field and all; a unit quaternion in x y z w
// order is read as such.
TEST(OpenLinkFlangePose, MalformedPosesAreNamedAndAGoodOneIsRead) {
  std::string problem;
  const auto good = robotio::parse_open_flange_pose(
      nlohmann::json::parse(
          R"({"flange_pose":{"position":[0.4,-0.1,0.3],"quaternion_xyzw":[0,0,0.7071068,0.7071068]}})"),
      problem);
  ASSERT_TRUE(good.has_value()) << problem;
  EXPECT_NEAR(good->translation().x(), 0.4, 1e-12);
  EXPECT_NEAR(Eigen::AngleAxisd(good->linear()).angle(), std::numbers::pi / 2, 1e-6);
  EXPECT_NEAR(Eigen::AngleAxisd(good->linear()).axis().z(), 1.0, 1e-6);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {R"({"position":[1,2,3]})", "no \"flange_pose\""},
      {R"({"flange_pose":{"position":[1,2],"quaternion_xyzw":[0,0,0,1]}})", "\"position\""},
      {R"({"flange_pose":{"position":[1,2,3],"quaternion_xyzw":[90,0,45,1]}})", "has length"},
      {R"({"flange_pose":{"position":[1,2,3]}})", "\"quaternion_xyzw\""},
  };
  for (const auto& [reply, says] : bad) {
    EXPECT_FALSE(robotio::parse_open_flange_pose(nlohmann::json::parse(reply), problem)) << reply;
    EXPECT_NE(problem.find(says), std::string::npos) << problem;
  }
}

}  // namespace
}  // namespace robocal::test
