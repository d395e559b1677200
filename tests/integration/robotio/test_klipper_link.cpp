// A Klipper delta printer through Moonraker: the Klipper link drives `robocal sim-controller
// --firmware klipper --kinematics delta` (Klipper's delta kinematics behind Moonraker's JSON-RPC
// WebSocket) as its own process over real TCP. Ground truth is the simulator's log (the carriage
// step counts each motion ended on) checked against Klipper's model written out here: carriage
// coordinate c_i = z + sqrt(L^2 - |xy - T_i|^2), towers T_i at 210 + X, 330 + Y, 90 + Z degrees
// on radius R; the endstop coordinate E_i = position_endstop_i + sqrt(L^2 - R^2) with
// position_endstop_i = H + adjustment_i; steps counted from the endstop, count = lround(E_i * 80)
// + lround((c_i - E_i) * 80); and a reading r (the robot file's carriage reading, 0.45 m at the
// endstop) is lround(E_i * 80) + lround((r - 0.45) * 1000 * 80) steps.
#include "robocal/robotio/klipper_link.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/moonraker.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

namespace robocal::test {
namespace {

using robotio::KlipperLink;
using robotio::LinkError;
using robotio::SafetyGuard;
using robotio::SimControllerProcess;

constexpr robotio::MoveSpeed kSpeed{0.2, 4.0};
constexpr double kStepsPerMm = 80.0;
constexpr double kEndstopReading = 0.45;  // linear_delta.yaml: carriage limits [0, 0.45]
constexpr double kRod = 270.0, kRadius = 140.0, kHeight = 221.5;
constexpr std::array<double, 3> kTrim = {0.3, -0.2, 0.1};
constexpr std::array<double, 3> kAdjust = {-0.4, -0.1, 0.0};

// The printer's configuration (Klipper's terms: position_endstop = H + adjustment).
std::vector<std::string> klipper_args(std::vector<std::string> extra) {
  std::vector<std::string> a = {"--firmware",  "klipper",         "--kinematics", "delta",
                                "--no-pty",    "--delta-setting", "L=270",        "--delta-setting",
                                "R=140",       "--delta-setting", "H=221.5",      "--delta-setting",
                                "X=0.3",       "--delta-setting", "Y=-0.2",       "--delta-setting",
                                "Z=0.1",       "--delta-setting", "M666_X=-0.4",  "--delta-setting",
                                "M666_Y=-0.1", "--delta-setting", "M666_Z=0"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}

Eigen::Vector2d tower(int i) {
  const double a = (std::array<double, 3>{210.0, 330.0, 90.0}[static_cast<std::size_t>(i)] +
                    kTrim[static_cast<std::size_t>(i)]) *
                   std::numbers::pi / 180.0;
  return {kRadius * std::cos(a), kRadius * std::sin(a)};
}

double endstop(int i) {
  return kHeight + kAdjust[static_cast<std::size_t>(i)] +
         std::sqrt(kRod * kRod - kRadius * kRadius);
}

std::vector<long> expected_counts(const Eigen::VectorXd& readings) {
  std::vector<long> out;
  for (int i = 0; i < 3; ++i)
    out.push_back(std::lround(endstop(i) * kStepsPerMm) +
                  std::lround((readings[i] - kEndstopReading) * 1000.0 * kStepsPerMm));
  return out;
}

// Klipper's inverse kinematics of a G1 target, counted from the endstop.
std::vector<long> counts_of_cartesian(const Eigen::Vector3d& p) {
  std::vector<long> out;
  for (int i = 0; i < 3; ++i) {
    const double c = p.z() + std::sqrt(kRod * kRod - (p.head<2>() - tower(i)).squaredNorm());
    out.push_back(std::lround(endstop(i) * kStepsPerMm) +
                  std::lround((c - endstop(i)) * kStepsPerMm));
  }
  return out;
}

// The G-code lines of the scripts the simulated Moonraker received (its log's "rx" JSON-RPC
// requests), from the `first` received request on.
std::vector<std::string> script_lines(const std::vector<nlohmann::json>& log, std::size_t first) {
  std::vector<std::string> out;
  const auto rx = events(log, "rx");
  for (std::size_t k = first; k < rx.size(); ++k) {
    const auto request = nlohmann::json::parse(rx[k].value("line", ""), nullptr, false);
    if (!request.is_object() || request.value("method", "") != "printer.gcode.script") continue;
    const nlohmann::json params = request.value("params", nlohmann::json::object());
    std::stringstream ss(params.value("script", std::string()));
    std::string line;
    while (std::getline(ss, line)) out.push_back(line);
  }
  return out;
}

class KlipperLinkTest : public ScratchDirTest {
 protected:
  KlipperLinkTest() : ScratchDirTest("klipper_link_") {}

  void start(std::vector<std::string> extra) {
    log_ = file("sim.jsonl");
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY,
                                                  sim_args(log_, klipper_args(std::move(extra))));
    guard_ =
        std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_native_limits());
    guard_->arm("test: simulated cell, nothing can be hurt");
  }
  std::string address() const { return "moonraker:" + sim_->tcp().substr(4); }
  std::unique_ptr<KlipperLink> link(robotio::GeometryChoice choice) {
    robotio::GcodeLinkOptions o = link_options(model_, address());
    o.geometry = choice;
    o.identify_timeout = std::chrono::milliseconds(1500);
    return std::make_unique<KlipperLink>(*guard_, o);
  }
  std::vector<nlohmann::json> log() const { return read_sim_log(log_); }
  std::size_t motions() const { return events(log(), "motion_start").size(); }

  calib::Mechanism model_ = linear_delta();
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SafetyGuard> guard_;
};

TEST_F(KlipperLinkTest, EveryMoveEndsOnTheRequestedStepCountsInTheTruthLog) {
  start({"--seed", "3"});
  auto l = link(robotio::GeometryChoice::kAsk);
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_EQ(fw.firmware, robotio::Firmware::kKlipper);
  EXPECT_NE(fw.name.find("Klipper"), std::string::npos) << fw.name;
  EXPECT_TRUE(l->geometry_disagreements().empty());
  l->home();
  // Homed: Klipper leaves every carriage on its endstop.
  EXPECT_EQ(events(log(), "motion_end").back()["counts"].get<std::vector<long>>(),
            expected_counts(Eigen::Vector3d::Constant(kEndstopReading)));
  for (const Eigen::VectorXd& target : delta_targets(model_, 6, 5)) {
    const std::size_t before = events(log(), "rx").size();
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const std::vector<long> expect = expected_counts(target);
    EXPECT_EQ(events(log(), "motion_end").back()["counts"].get<std::vector<long>>(), expect);
    EXPECT_EQ(r.readings.counts, expect);
    for (int i = 0; i < 3; ++i)  // half a step at 80 steps/mm
      EXPECT_NEAR(r.readings.values[i], target[i], 0.5 / kStepsPerMm / 1000.0 + 1e-12);
    // What was sent is Cartesian: Klipper's own inverse kinematics of the move's last G1 lands
    // on the requested counts.
    std::string last_g1;
    for (const std::string& line : script_lines(log(), before))
      if (line.rfind("G1 ", 0) == 0) last_g1 = line;
    ASSERT_FALSE(last_g1.empty());
    EXPECT_EQ(counts_of_cartesian(g1_xyz(last_g1)), expect) << last_g1;
  }
}

TEST_F(KlipperLinkTest, AGeometryThatDisagreesIsNamedAndNothingMovesUntilTheOperatorChooses) {
  start({"--delta-setting", "L=272"});
  try {
    link(robotio::GeometryChoice::kAsk)->connect();
    FAIL() << "connected despite a 2 mm rod difference";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("Moonraker at " + sim_->tcp().substr(4)), std::string::npos) << what;
    EXPECT_NE(what.find("tower A diagonal rod: the firmware says 272.00 mm, the robot file "
                        "270.00 mm"),
              std::string::npos)
        << what;
  }
  EXPECT_EQ(motions(), 0U);
  auto chosen = link(robotio::GeometryChoice::kRobotFile);
  chosen->connect();
  EXPECT_EQ(chosen->geometry_disagreements().size(), 3U);
}

TEST_F(KlipperLinkTest, NoMoveBeforeKlipperHasHomed) {
  start({});
  auto l = link(robotio::GeometryChoice::kAsk);
  l->connect();
  EXPECT_EQ(l->read_actuators().values.size(), 0) << "a position before homing is unknown";
  EXPECT_THROW(l->move_actuators(delta_targets(model_, 1, 4).front(), kSpeed),
               robotio::MotionRefused);
  EXPECT_TRUE(script_lines(log(), 0).empty());
  EXPECT_EQ(motions(), 0U);
}

TEST_F(KlipperLinkTest, KlippyInShutdownIsNamedWithKlippersWordsAndNothingMoves) {
  start({});
  auto l = link(robotio::GeometryChoice::kAsk);
  l->connect();
  l->home();
  const std::size_t homed = motions();
  // Someone presses the emergency stop in the printer's web page.
  robotio::MoonrakerClient other("127.0.0.1",
                                 std::stoi(sim_->tcp().substr(sim_->tcp().rfind(':') + 1)));
  other.open(robotio::Clock::now() + std::chrono::seconds(2));
  other.call("printer.emergency_stop", nullptr, robotio::Clock::now() + std::chrono::seconds(2));
  other.close();
  try {
    l->move_actuators(delta_targets(model_, 1, 4).front(), kSpeed);
    FAIL() << "a move sent to a Klipper in shutdown was reported";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("Shutdown due to webhooks request"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(motions(), homed);
  // A new connection is refused with Klipper's state and message.
  try {
    link(robotio::GeometryChoice::kAsk)->connect();
    FAIL() << "connected to a Klipper in shutdown";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("state 'shutdown'"), std::string::npos) << what;
    EXPECT_NE(what.find("Shutdown due to webhooks request"), std::string::npos) << what;
    EXPECT_NE(what.find("FIRMWARE_RESTART"), std::string::npos) << what;
  }
  EXPECT_EQ(motions(), homed);
}

TEST_F(KlipperLinkTest, MoonrakerNotAnsweringIsNamedAndNothingMoves) {
  start({"--mute"});
  try {
    link(robotio::GeometryChoice::kAsk)->connect();
    FAIL() << "connected to a Moonraker that never answers";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(sim_->tcp().substr(4)), std::string::npos) << what;
    EXPECT_NE(what.find("no answer to server.info"), std::string::npos) << what;
  }
  EXPECT_EQ(motions(), 0U);
}

TEST_F(KlipperLinkTest, AnErrorAnswerStopsTheMoveWithKlippersWords) {
  // Scripts: 1 homing, 2 and 3 GET_POSITION (the count at the endstop, the homed position),
  // 4 the move.
  const std::string faults = file("faults.txt");
  std::ofstream(faults) << "4 error\n";
  start({"--fault-script", faults});
  auto l = link(robotio::GeometryChoice::kAsk);
  l->connect();
  l->home();
  const std::size_t homed = motions();
  try {
    l->move_actuators(delta_targets(model_, 1, 4).front(), kSpeed);
    FAIL() << "a refused script reported as a move";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("command rejected (injected fault)"), std::string::npos) << what;
    EXPECT_NE(what.find("Moonraker at"), std::string::npos) << what;
  }
  EXPECT_EQ(motions(), homed);
}

TEST_F(KlipperLinkTest, ALostConnectionIsRecoveredWithoutLosingOrRepeatingTheMove) {
  // Scripts 4 (the first move) and 7 are dropped, before or after they ran (the fault seed
  // decides): the move itself, then a move or the position read after one.
  const std::string faults = file("faults.txt");
  std::ofstream(faults) << "4 drop\n7 drop\n";
  start({"--fault-script", faults, "--fault-seed", "4"});
  auto l = link(robotio::GeometryChoice::kAsk);
  l->connect();
  l->home();
  const std::size_t homed = motions();
  const auto targets = delta_targets(model_, 3, 6);
  for (const Eigen::VectorXd& target : targets) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    EXPECT_EQ(events(log(), "motion_end").back()["counts"].get<std::vector<long>>(),
              expected_counts(target));
  }
  EXPECT_EQ(events(log(), "drop").size(), 2U);
  EXPECT_GE(l->status().reconnects, 2);
  // Every move's segments ran once: the motions in the log are the G1 lines Klipper ran, and
  // none of them twice in a row to the same counts.
  const auto ends = events(log(), "motion_end");
  for (std::size_t k = homed + 1; k < ends.size(); ++k)
    EXPECT_NE(ends[k]["counts"], ends[k - 1]["counts"]) << "a segment repeated at motion " << k;
}

}  // namespace
}  // namespace robocal::test
