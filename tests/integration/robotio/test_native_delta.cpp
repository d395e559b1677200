// Firmware-native delta mode: the G-code link drives `robocal sim-controller --kinematics delta`
// (Marlin and RepRapFirmware in their own delta kinematics, their M665/M666 geometry differing
// from the true robot's) as its own process over real TCP and a real pty. Ground truth is the
// simulator's log (the carriage step counts each motion ended on) checked against the firmware
// model's closed form written out here: carriage coordinate c_i = z + sqrt(L_i^2 - |xy - T_i|^2),
// towers T_i at 210 + X, 330 + Y, 90 + Z degrees on radius R; step count lround(c_i * 80); at the
// endstop (reading 0.45 m, the robot file's upper carriage limit) c_i = H + sqrt(L_i^2 - R^2) +
// |M666_i| (Marlin) or + M666_i (RepRapFirmware), and a reading r is lround(c_endstop * 80) +
// lround((r - 0.45) * 1000 * 80) steps.
#include "robocal/calib/kinematics.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <ostream>
#include <sstream>

namespace robocal::test {
namespace {

using robotio::GcodeLink;
using robotio::LinkError;
using robotio::SafetyGuard;
using robotio::SimControllerProcess;

constexpr robotio::MoveSpeed kSpeed{0.2, 4.0};

std::vector<std::string> concat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}
constexpr double kStepsPerMm = 80.0;
constexpr double kEndstopReading = 0.45;  // linear_delta.yaml: carriage limits [0, 0.45]

// The firmware's geometry the simulator is given (mm, degrees): the robot file's drawing (rods
// 270, radius 140) with trims inside the file's tolerances, as a printer after its own delta
// calibration, and a homed height of its own.
struct Firmware {
  const char* name;
  bool marlin;
};
// How GoogleTest shows the parameter: its name, not raw bytes.
void PrintTo(const Firmware& f, std::ostream* os) {
  *os << f.name;
}
constexpr double kRod = 270.0, kRadius = 140.0, kHeight = 221.5;
constexpr std::array<double, 3> kTrim = {0.3, -0.2, 0.1};
constexpr std::array<double, 3> kM666 = {-0.4, -0.1, 0.0};

std::vector<std::string> firmware_settings() {
  return {"--delta-setting", "L=270",       "--delta-setting", "R=140",
          "--delta-setting", "H=221.5",     "--delta-setting", "X=0.3",
          "--delta-setting", "Y=-0.2",      "--delta-setting", "Z=0.1",
          "--delta-setting", "M666_X=-0.4", "--delta-setting", "M666_Y=-0.1",
          "--delta-setting", "M666_Z=0"};
}

Eigen::Vector2d tower(int i) {
  const double a = (std::array<double, 3>{210.0, 330.0, 90.0}[static_cast<std::size_t>(i)] +
                    kTrim[static_cast<std::size_t>(i)]) *
                   std::numbers::pi / 180.0;
  return {kRadius * std::cos(a), kRadius * std::sin(a)};
}

// Step counts the firmware holds at carriage readings (closed form above).
std::vector<long> expected_counts(const Eigen::VectorXd& readings, bool marlin) {
  std::vector<long> out;
  for (int i = 0; i < 3; ++i) {
    const double adj = kM666[static_cast<std::size_t>(i)];
    const double endstop =
        kHeight + std::sqrt(kRod * kRod - kRadius * kRadius) + (marlin ? std::abs(adj) : adj);
    // The reading at the endstop is tied to the whole step counted there.
    out.push_back(std::lround(endstop * kStepsPerMm) +
                  std::lround((readings[i] - kEndstopReading) * 1000.0 * kStepsPerMm));
  }
  return out;
}

// The firmware's inverse kinematics of a G1 target, rounded to steps.
std::vector<long> counts_of_cartesian(const Eigen::Vector3d& p) {
  std::vector<long> out;
  for (int i = 0; i < 3; ++i) {
    const double c = p.z() + std::sqrt(kRod * kRod - (p.head<2>() - tower(i)).squaredNorm());
    out.push_back(std::lround(c * kStepsPerMm));
  }
  return out;
}

class NativeDeltaTest : public ScratchDirTest, public ::testing::WithParamInterface<Firmware> {
 protected:
  NativeDeltaTest() : ScratchDirTest("native_delta_") {}

  void start(std::vector<std::string> extra) {
    log_ = file("sim.jsonl");
    extra.insert(extra.end(), {"--firmware", GetParam().marlin ? "marlin" : "rrf"});
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, sim_args(log_, extra));
    guard_ =
        std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_native_limits());
    guard_->arm("test: simulated cell, nothing can be hurt");
  }
  std::unique_ptr<GcodeLink> link(bool pty, robotio::GeometryChoice choice) {
    robotio::GcodeLinkOptions o = link_options(model_, pty ? sim_->pty() : sim_->tcp());
    o.mode = robotio::GcodeMode::kNativeDelta;
    o.geometry = choice;
    return std::make_unique<GcodeLink>(*guard_, o);
  }
  std::vector<nlohmann::json> log() const { return read_sim_log(log_); }
  int moves_received() const { return received(log(), "G1") + received(log(), "G28"); }

  calib::Mechanism model_ = linear_delta();
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SafetyGuard> guard_;
};

// Marlin on TCP, RRF on the pty: both wires, both dialects.
TEST_P(NativeDeltaTest, EveryMoveEndsOnTheRequestedStepCountsInTheTruthLog) {
  start(concat({"--kinematics", "delta", "--seed", "3"}, firmware_settings()));
  auto l = link(!GetParam().marlin, robotio::GeometryChoice::kAsk);
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_EQ(fw.firmware,
            GetParam().marlin ? robotio::Firmware::kMarlin : robotio::Firmware::kRepRapFirmware);
  EXPECT_TRUE(l->geometry_disagreements().empty());
  l->home();
  // Homed: Marlin backs each carriage |M666| off its endstop, RRF stays on it.
  Eigen::VectorXd homed(3);
  for (int i = 0; i < 3; ++i)
    homed[i] = kEndstopReading -
               (GetParam().marlin ? std::abs(kM666[static_cast<std::size_t>(i)]) / 1000.0 : 0.0);
  EXPECT_EQ(events(log(), "motion_end").back()["counts"].get<std::vector<long>>(),
            expected_counts(homed, GetParam().marlin));
  for (const Eigen::VectorXd& target : delta_targets(model_, 6, 5)) {
    const std::size_t before = events(log(), "rx").size();
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const std::vector<long> expect = expected_counts(target, GetParam().marlin);
    // The truth log: where the steppers stopped.
    EXPECT_EQ(events(log(), "motion_end").back()["counts"].get<std::vector<long>>(), expect);
    EXPECT_EQ(r.readings.counts, expect);
    for (int i = 0; i < 3; ++i)  // half a step at 80 steps/mm
      EXPECT_NEAR(r.readings.values[i], target[i], 0.5 / kStepsPerMm / 1000.0 + 1e-12);
    // What was sent is Cartesian: the firmware's own inverse kinematics of the last G1 of this
    // move lands on the requested counts.
    const auto rx = events(log(), "rx");
    std::string last_g1;
    for (std::size_t k = before; k < rx.size(); ++k)
      if (rx[k]["line"].get<std::string>().find(" G1 ") != std::string::npos)
        last_g1 = rx[k]["line"];
    ASSERT_FALSE(last_g1.empty());
    EXPECT_EQ(counts_of_cartesian(g1_xyz(last_g1)), expect) << last_g1;
  }
}

TEST_P(NativeDeltaTest, AGeometryThatDisagreesIsNamedAndNothingMovesUntilTheOperatorChooses) {
  std::vector<std::string> settings = firmware_settings();
  settings.insert(settings.end(), {"--delta-setting", "L=272"});
  start(concat({"--kinematics", "delta"}, settings));
  auto asked = link(false, robotio::GeometryChoice::kAsk);
  try {
    asked->connect();
    FAIL() << "connected despite a 2 mm rod difference";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(sim_->tcp().substr(4)), std::string::npos) << what;  // the device
    EXPECT_NE(what.find("tower A diagonal rod: the firmware says 272.00 mm, the robot file "
                        "270.00 mm"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("choose which to trust"), std::string::npos) << what;
    EXPECT_EQ(what.find("delta radius"), std::string::npos) << "the radius agrees: " << what;
  }
  EXPECT_EQ(moves_received(), 0);
  EXPECT_TRUE(events(log(), "motion_start").empty());

  // The operator chose: the moves land exactly, computed with the firmware's own rods.
  auto chosen = link(false, robotio::GeometryChoice::kRobotFile);
  chosen->connect();
  ASSERT_EQ(chosen->geometry_disagreements().size(), 3U);
  const Eigen::VectorXd target = delta_targets(model_, 1, 9).front();
  const robotio::MoveResult r = chosen->move_actuators(target, kSpeed);
  EXPECT_TRUE(r.confirmed) << r.reason;
  const double endstop = kHeight + std::sqrt(272.0 * 272.0 - kRadius * kRadius);
  const double adj = kM666[0];
  EXPECT_EQ(events(log(), "motion_end").back()["counts"][0].get<long>(),
            std::lround((endstop + (GetParam().marlin ? std::abs(adj) : adj)) * kStepsPerMm) +
                std::lround((target[0] - kEndstopReading) * 1000.0 * kStepsPerMm));
}

TEST_P(NativeDeltaTest, APrinterThatIsNotADeltaIsRefusedNamingTheDevice) {
  start({"--kinematics", "axes"});
  auto l = link(!GetParam().marlin, robotio::GeometryChoice::kAsk);
  try {
    l->connect();
    FAIL() << "a Cartesian firmware accepted for native delta mode";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("not a delta"), std::string::npos) << what;
    EXPECT_NE(what.find(GetParam().marlin ? sim_->tcp().substr(4) : sim_->pty()), std::string::npos)
        << what;
    if (!GetParam().marlin) {  // RRF says why in its own words
      EXPECT_NE(what.find("do not apply to Cartesian kinematics"), std::string::npos) << what;
    }
  }
  EXPECT_EQ(moves_received(), 0);
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

TEST_P(NativeDeltaTest, AnErrorReplyStopsTheMoveWithWhatTheFirmwareSaidAndNothingMoves) {
  // Connect takes the numbered commands up to M114 (Marlin: M110 M115 M113 G90 M503 M114; RRF
  // one fewer M113, one more query): from the 7th on every command is refused.
  const std::string script = file("faults.txt");
  std::ofstream(script) << "7 error\n8 error\n9 error\n10 error\n11 error\n12 error\n";
  start(concat({"--kinematics", "delta", "--fault-script", script}, firmware_settings()));
  auto l = link(false, robotio::GeometryChoice::kAsk);
  l->connect();
  try {
    l->move_actuators(delta_targets(model_, 1, 4).front(), kSpeed);
    FAIL() << "a refused command reported as a move";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("command rejected (injected fault)"), std::string::npos) << what;
    EXPECT_NE(what.find(sim_->tcp().substr(4)), std::string::npos) << what;
  }
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

// A pose the robot file reaches with rod A rising from its carriage to the effector has no
// Cartesian command in the firmware's kinematics (every carriage above the nozzle): refused
// before anything is sent.
TEST_P(NativeDeltaTest, APoseTheFirmwareCannotCommandIsRefusedBeforeAnythingIsSent) {
  start(concat({"--kinematics", "delta"}, firmware_settings()));
  robotio::SafetyLimits wide = delta_native_limits();
  wide.workspace_min = Eigen::Vector3d(-0.2, -0.2, 0.0);
  wide.workspace_max = Eigen::Vector3d(0.2, 0.2, 0.225);
  guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), wide);
  guard_->arm("test: simulated cell, nothing can be hurt");
  auto l = link(false, robotio::GeometryChoice::kAsk);
  l->connect();
  // Carriage A 0.148 m, B 0.441 m, C 0.347 m: the nominal robot assembles there with the
  // effector joint of rod A about 30 mm above carriage A (a live-demo plan's pose).
  Eigen::VectorXd rim(3);
  rim << 0.147848771, 0.441185325, 0.347218821;
  const auto fk = calib::forward_kinematics(model_, model_.nominal_parameters(), rim, model_.tool);
  ASSERT_TRUE(fk.closure.ok());
  const std::size_t g1_before = static_cast<std::size_t>(received(log(), "G1"));
  try {
    l->move_actuators(rim, kSpeed);
    FAIL() << "a pose with a carriage below the nozzle was sent";
  } catch (const robotio::MotionRefused& e) {
    EXPECT_NE(std::string(e.what()).find("cannot command"), std::string::npos) << e.what();
  }
  EXPECT_EQ(static_cast<std::size_t>(received(log(), "G1")), g1_before);
}

INSTANTIATE_TEST_SUITE_P(Firmwares, NativeDeltaTest,
                         ::testing::Values(Firmware{"Marlin", true}, Firmware{"Rrf", false}),
                         [](const ::testing::TestParamInfo<Firmware>& p) {
                           return std::string(p.param.name);
                         });

}  // namespace
}  // namespace robocal::test
