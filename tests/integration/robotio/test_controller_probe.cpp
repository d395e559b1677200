// The wizard's controller probe (robotio/controller_probe.hpp) against `robocal sim-controller`
// processes of each protocol over loopback, a silent one and a closed port: each is named for
// what it is, with the link address to use, and nothing is moved or changed by the probing (the
// simulator's log).
#include "robocal/robotio/controller_probe.hpp"
#include "robocal/robotio/sim_process.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

namespace robocal::test {
namespace {

using robotio::ProbedController;
using robotio::ProbeResult;
using robotio::SimControllerProcess;

class ControllerProbe : public ScratchDirTest {
 protected:
  ControllerProbe() : ScratchDirTest("controller_probe_") {}

  void start(const std::string& robot, std::vector<std::string> extra) {
    log_ = file("sim.jsonl");
    std::vector<std::string> args = sim_args(log_, std::move(extra));
    args[1] = robot;
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, args);
  }
  // "HOST:PORT" of a "tcp:HOST:PORT" link address.
  static std::string host_port(const std::string& tcp) { return tcp.substr(4); }
  // The dashboard port of "ur:127.0.0.1:R:S:D".
  std::string dashboard() const { return sim_->ur().substr(sim_->ur().rfind(':') + 1); }
  void expect_nothing_moved() const {
    const std::vector<nlohmann::json> log = read_sim_log(log_);
    EXPECT_TRUE(events(log, "motion_start").empty()) << "the probe moved the robot";
    for (const auto& rx : events(log, "rx"))
      EXPECT_NE(rx.value("ch", ""), "secondary") << "the probe sent URScript: " << rx.dump();
  }

  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
};

TEST_F(ControllerProbe, UniversalRobotsDashboardIsNamedWithVersionRemoteControlAndModes) {
  start("ur5", {"--protocol", "ur"});
  const ProbeResult r = robotio::probe_controller("127.0.0.1:" + dashboard());
  EXPECT_EQ(r.kind, ProbedController::kUniversalRobots) << r.explanation;
  for (const char* words : {"a Universal Robots controller", "PolyScope 5.x", "5.11.0.108",
                            "remote control on", "robot mode RUNNING", "safety status NORMAL"})
    EXPECT_NE(r.explanation.find(words), std::string::npos) << words << " in: " << r.explanation;
  EXPECT_EQ(r.link, "ur:127.0.0.1:30004:30002:" + dashboard());
  EXPECT_EQ(r.said, "Connected: Universal Robots Dashboard Server");
  expect_nothing_moved();
}

TEST_F(ControllerProbe, UniversalRobotsWithRemoteControlOffSaysSo) {
  start("ur5", {"--protocol", "ur", "--ur-remote-off", "--ur-protective-stop"});
  const ProbeResult r = robotio::probe_controller("127.0.0.1:" + dashboard());
  EXPECT_EQ(r.kind, ProbedController::kUniversalRobots);
  EXPECT_NE(r.explanation.find("remote control OFF"), std::string::npos) << r.explanation;
  EXPECT_NE(r.explanation.find("safety status PROTECTIVE_STOP"), std::string::npos)
      << r.explanation;
  // Probing never unlocks a protective stop.
  EXPECT_TRUE(events(read_sim_log(log_), "unlock_protective_stop").empty());
}

TEST_F(ControllerProbe, OpenLinkControllerIsNamedFromItsHello) {
  start("gantry_tau", {"--protocol", "open"});
  const ProbeResult r = robotio::probe_controller(host_port(sim_->tcp()));
  EXPECT_EQ(r.kind, ProbedController::kOpenLink) << r.explanation;
  EXPECT_EQ(r.link, "open:" + host_port(sim_->tcp()));
  EXPECT_NE(r.explanation.find("an open link controller"), std::string::npos) << r.explanation;
  EXPECT_NE(r.explanation.find("protocol 1.0"), std::string::npos) << r.explanation;
  expect_nothing_moved();
}

TEST_F(ControllerProbe, GcodeBoardIsNamedFromItsM115) {
  start("linear_delta", {});
  const ProbeResult r = robotio::probe_controller(host_port(sim_->tcp()));
  EXPECT_EQ(r.kind, ProbedController::kGcode) << r.explanation << "\nsaid: " << r.said;
  EXPECT_EQ(r.link, sim_->tcp());
  EXPECT_NE(r.explanation.find("a G-code board, Marlin"), std::string::npos) << r.explanation;
  expect_nothing_moved();
}

// Moonraker answers no line protocol: found by its WebSocket upgrade and server.info.
TEST_F(ControllerProbe, KlipperPrinterBehindMoonrakerIsNamedFromServerInfo) {
  start("linear_delta", {"--firmware", "klipper", "--kinematics", "delta", "--no-pty"});
  const ProbeResult r = robotio::probe_controller(host_port(sim_->tcp()));
  EXPECT_EQ(r.kind, ProbedController::kKlipper) << r.explanation << "\nsaid: " << r.said;
  EXPECT_EQ(r.link, "moonraker:" + host_port(sim_->tcp()));
  EXPECT_NE(r.explanation.find("a Klipper printer through Moonraker"), std::string::npos)
      << r.explanation;
  EXPECT_NE(r.explanation.find("Klipper v0.12.0"), std::string::npos) << r.explanation;
  EXPECT_EQ(r.explanation.find("NOT ready"), std::string::npos) << r.explanation;
  expect_nothing_moved();
}

TEST_F(ControllerProbe, ControllerThatNeverAnswersIsCalledSilent) {
  start("linear_delta", {"--mute"});
  const ProbeResult r =
      robotio::probe_controller(host_port(sim_->tcp()), std::chrono::milliseconds(600));
  EXPECT_EQ(r.kind, ProbedController::kSilent) << r.explanation;
  EXPECT_TRUE(r.link.empty());
}

TEST(ControllerProbeAddress, ClosedPortSaysNothingAnswersThere) {
  const ProbeResult r = robotio::probe_controller("127.0.0.1:1");
  EXPECT_EQ(r.kind, ProbedController::kNothing);
  EXPECT_NE(r.explanation.find("nothing answers on port 1 of 127.0.0.1"), std::string::npos)
      << r.explanation;
  EXPECT_NE(r.explanation.find("is the robot on the network"), std::string::npos);
  EXPECT_TRUE(r.link.empty());
}

TEST(ControllerProbeAddress, OnlyBareHostsAndHostPortsAreProbed) {
  EXPECT_TRUE(robotio::is_probe_address("192.168.1.10"));
  EXPECT_TRUE(robotio::is_probe_address("robot.local:29999"));
  for (const char* link : {"/dev/ttyACM0", "tcp:127.0.0.1:5000", "ur:10.0.0.2", "open:h:7001",
                           "manual", "host:port", ""})
    EXPECT_FALSE(robotio::is_probe_address(link)) << link;
}

}  // namespace
}  // namespace robocal::test
