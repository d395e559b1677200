// The Universal Robots link (robotio/ur_link.hpp) against `robocal sim-controller --protocol ur`
// running as its own process: RTDE, the secondary interface and the dashboard server over real
// loopback sockets. The simulator's JSONL log is the independent record of what the controller
// received and executed; expected joint counts are worked out here from the robot file's encoder
// scale and the simulator's --steps-per-degree, not taken from the link.
#include "robocal/calib/closure.hpp"
#include "robocal/calib/kinematics.hpp"
#include "robocal/calib/mechanism.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/motion_profile.hpp"
#include "robocal/robotio/ur_link.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <random>
#include <thread>

namespace robocal::test {
namespace {

using robotio::LinkError;
using robotio::MotionInterrupted;
using robotio::MotionRefused;
using robotio::MoveSpeed;
using robotio::SafetyGuard;
using robotio::SimControllerProcess;
using robotio::UrLink;

constexpr MoveSpeed kSpeed{0.8, 4.0};  // rad/s and rad/s^2 of the leading joint
constexpr double kStepsPerDegree = 10000.0;

calib::Mechanism ur5() {
  return calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/ur5.yaml");
}

robotio::SafetyLimits ur5_limits() {
  robotio::SafetyLimits l;
  l.workspace_min = Eigen::Vector3d::Constant(-1.2);
  l.workspace_max = Eigen::Vector3d::Constant(1.2);
  l.max_speed = 1.0;
  l.max_acceleration = 6.0;
  l.path_step = 5e-3;
  return l;
}

class UrLinkTest : public ScratchDirTest {
 protected:
  UrLinkTest() : ScratchDirTest("ur_link_") {}

  void start(std::vector<std::string> extra = {}) {
    log_ = file("sim.jsonl");
    std::vector<std::string> args = {"--robot",
                                     "ur5",
                                     "--protocol",
                                     "ur",
                                     "--log",
                                     log_,
                                     "--max-seconds",
                                     "600",
                                     "--steps-per-degree",
                                     std::to_string(kStepsPerDegree),
                                     "--slow-ms",
                                     "300"};
    args.insert(args.end(), extra.begin(), extra.end());
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, args);
    guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), ur5_limits());
    guard_->arm("test: simulated cell, nothing can be hurt");
  }
  robotio::UrLinkOptions options() const {
    robotio::UrLinkOptions o;
    o.address = sim_->ur();
    o.reply_timeout = std::chrono::milliseconds(500);
    o.package_timeout = std::chrono::milliseconds(800);
    o.reconnect_attempts = 4;
    return o;
  }
  std::unique_ptr<UrLink> link(bool unlock = false) {
    robotio::UrLinkOptions o = options();
    o.unlock_protective_stop = unlock;
    return std::make_unique<UrLink>(*guard_, o);
  }
  std::vector<nlohmann::json> log() const { return read_sim_log(log_); }
  // The log's `ev` events once at least one is there: a command the link sent just before it
  // threw reaches the simulator a moment later (2 s at most).
  std::vector<nlohmann::json> awaited(const std::string& ev) const {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    std::vector<nlohmann::json> found = events(log(), ev);
    while (found.empty() && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      found = events(log(), ev);
    }
    return found;
  }
  // Joint counts the simulator holds at `readings`: rad -> degrees -> steps.
  std::vector<long> counts_of(const Eigen::VectorXd& readings) const {
    const Eigen::VectorXd scale = calib::encoder_scales(model_, model_.nominal_parameters());
    std::vector<long> c;
    for (Eigen::Index i = 0; i < readings.size(); ++i)
      c.push_back(std::lround(readings[i] * scale[i] * 180.0 / std::numbers::pi * kStepsPerDegree));
    return c;
  }
  int motions_to(const std::vector<long>& counts) const {
    int n = 0;
    for (const auto& m : events(log(), "motion_start"))
      if (m["to"].get<std::vector<long>>() == counts) ++n;
    return n;
  }
  // Script lines the secondary interface received that start with `fn`.
  int scripts(const std::string& fn) const {
    int n = 0;
    for (const auto& rx : events(log(), "rx"))
      if (rx.value("ch", "") == "secondary" && rx.value("line", "").rfind(fn, 0) == 0) ++n;
    return n;
  }
  // Joint targets near the home pose (readings), inside the guard's box.
  std::vector<Eigen::VectorXd> targets(int count, unsigned seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> d(-0.3, 0.3);
    std::vector<Eigen::VectorXd> out;
    const Eigen::VectorXd home = model_.home_actuated();
    for (int k = 0; k < count; ++k) {
      Eigen::VectorXd t = home;
      for (Eigen::Index i = 0; i < t.size(); ++i) t[i] += d(rng);
      out.push_back(t);
    }
    return out;
  }
  void write_script(const std::string& text) { std::ofstream(file("faults.txt")) << text; }

  calib::Mechanism model_ = ur5();
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SafetyGuard> guard_;
};

TEST_F(UrLinkTest, ConnectsMovesSettlesAndReadsBackEveryTargetOnTheTruthLog) {
  start();
  auto l = link();
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_EQ(fw.version, "5.11.0.108");
  EXPECT_NE(fw.name.find("URControl"), std::string::npos) << fw.name;
  for (const Eigen::VectorXd& target : targets(4, 3)) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const std::vector<long> expect = counts_of(target);
    const auto ends = events(log(), "motion_end");
    ASSERT_FALSE(ends.empty());
    EXPECT_EQ(ends.back()["counts"].get<std::vector<long>>(), expect)
        << "the simulator's own record of where the arm stopped";
    EXPECT_EQ(motions_to(expect), 1) << "each move executed exactly once";
    // Read back within half a simulated encoder step (1e-4 degree) of the target.
    const double half_step = 0.5 * std::numbers::pi / 180.0 / kStepsPerDegree;
    for (Eigen::Index i = 0; i < 6; ++i)
      EXPECT_NEAR(r.readings.values[i], target[i], half_step + 1e-12);
  }
  EXPECT_EQ(scripts("movej(["), 4);
  // The RTDE session as the guide orders it: version, controller version, recipe, start.
  std::string order;
  for (const auto& rx : events(log(), "rx"))
    if (rx.value("ch", "") == "rtde" && order.size() < 4) order += rx.value("type", "?");
  EXPECT_EQ(order, "VvOS");
}

int body_index(const calib::Mechanism& m, const std::string& name) {
  for (std::size_t i = 0; i < m.bodies.size(); ++i)
    if (m.bodies[i].name == name) return static_cast<int>(i);
  ADD_FAILURE() << "no body " << name;
  return -1;
}

// The flange pose the link reads (actual_TCP_pose times the inverse of tcp_offset) is the true
// robot's: worked out here from the perturbation file given to the simulator and the UR5's
// forward kinematics to wrist3 (the flange; `tool` is fixed on it) in the base frame. The
// simulator's TCP is off the flange in all six values, so a link that took the TCP for the
// flange, or turned a rotation vector the wrong way, would miss by centimetres.
TEST_F(UrLinkTest, FlangePoseIsTheTrueRobotsFromTheTcpPoseAndTheTcpOffset) {
  const std::vector<std::string> perturbation = {"wrist1.d=0.11215", "wrist2.d=0.09165",
                                                 "wrist3.d=0.0853"};
  {
    std::ofstream out(file("truth.txt"));
    for (const std::string& line : perturbation) out << line << "\n";
  }
  start(
      {"--perturbation", file("truth.txt"), "--ur-tcp-offset", "0.012,-0.034,0.156,0.3,-0.2,0.5"});
  Eigen::VectorXd truth = model_.nominal_parameters();
  for (const std::string& line : perturbation) calib::apply_parameter_override(model_, truth, line);
  const int flange = body_index(model_, "wrist3"), base = body_index(model_, "base");
  auto l = link();
  (void)l->connect();
  constexpr double kTolerance = 1e-9;  // m and rad: doubles over RTDE, one rotation-vector trip
  for (const Eigen::VectorXd& target : targets(3, 11)) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    ASSERT_TRUE(r.readings.base_T_flange.has_value());
    const calib::ForwardResult fk =
        calib::forward_kinematics(model_, truth, r.readings.values, flange);
    ASSERT_TRUE(fk.closure.ok());
    const Eigen::Isometry3d expect =
        calib::frame_pose(model_, truth, fk.state, base).inverse() * fk.pose;
    const Eigen::Isometry3d& got = *r.readings.base_T_flange;
    EXPECT_LT((got.translation() - expect.translation()).norm(), kTolerance);
    EXPECT_LT(Eigen::AngleAxisd(got.linear().transpose() * expect.linear()).angle(), kTolerance);
    // The nominal model misses the perturbed flange: the pose is the controller's, not robocal's.
    const calib::ForwardResult nominal =
        calib::forward_kinematics(model_, model_.nominal_parameters(), r.readings.values, flange);
    EXPECT_GT((nominal.pose.translation() - fk.pose.translation()).norm(), 1e-3);
  }
}

TEST_F(UrLinkTest, ControllerWithoutTcpOffsetConnectsAndReportsNoFlangePose) {
  start({"--ur-unknown-output", "tcp_offset"});
  auto l = link();
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_NE(fw.raw.find("no tcp_offset"), std::string::npos) << fw.raw;
  const robotio::MoveResult r = l->move_actuators(targets(1, 5).front(), kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  EXPECT_FALSE(r.readings.base_T_flange.has_value());
  std::string order;
  for (const auto& rx : events(log(), "rx"))
    if (rx.value("ch", "") == "rtde" && order.size() < 5) order += rx.value("type", "?");
  EXPECT_EQ(order, "VvOOS") << "the recipe set up again without tcp_offset";
}

TEST_F(UrLinkTest, MovejTakesTheLeadingJointsTrapezoid) {
  start();
  auto l = link();
  l->connect();
  const Eigen::VectorXd from = l->read_actuators().values;
  const Eigen::VectorXd to = targets(1, 11)[0];
  const robotio::MoveResult r = l->move_actuators(to, kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  const auto starts = events(log(), "motion_start");
  ASSERT_EQ(starts.size(), 1u);
  const double lead = (to - from).cwiseAbs().maxCoeff();  // ur5 readings are radians
  EXPECT_NEAR(starts[0]["duration_s"].get<double>(),
              robotio::trapezoid_seconds(lead, kSpeed.speed, kSpeed.acceleration), 2e-3);
  EXPECT_GE(r.seconds, starts[0]["duration_s"].get<double>());
}

TEST_F(UrLinkTest, CtrlCDuringAMoveReachesTheControllerAsStopj) {
  start();
  auto l = link();
  l->connect();
  Eigen::VectorXd far = model_.home_actuated();
  far[0] += 1.0;
  std::thread stopper([this] {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    guard_->request_stop("test: operator pressed Ctrl-C");
  });
  EXPECT_THROW(l->move_actuators(far, MoveSpeed{0.2, 1.0}), MotionInterrupted);
  stopper.join();
  const auto stops = awaited("stop");
  ASSERT_EQ(stops.size(), 1u);
  EXPECT_EQ(stops[0]["cmd"], "stopj");
  const auto ends = events(log(), "motion_end");
  ASSERT_EQ(ends.size(), 1u);
  EXPECT_TRUE(ends[0]["stopped"].get<bool>());
  const int moves_before = scripts("movej");
  EXPECT_THROW(l->move_actuators(targets(1, 2)[0], kSpeed), MotionRefused);
  EXPECT_EQ(scripts("movej"), moves_before) << "nothing moves until the operator confirms again";
}

TEST_F(UrLinkTest, ReconnectsAndFindsTheArmWhereItWas) {
  start();
  auto l = link();
  l->connect();
  const auto t = targets(2, 9);
  ASSERT_TRUE(l->move_actuators(t[0], kSpeed).confirmed);
  const Eigen::VectorXd before = l->read_actuators().values;
  l->disconnect();
  l->reconnect();
  EXPECT_LT((l->read_actuators().values - before).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_TRUE(l->move_actuators(t[1], kSpeed).confirmed);
  EXPECT_EQ(l->status().reconnects, 1);
}

// Each fault kind on the first movej: the move ends confirmed at its target, exactly once.
class UrFaultTest : public UrLinkTest, public ::testing::WithParamInterface<const char*> {};

TEST_P(UrFaultTest, MoveEndsConfirmedAtItsTargetExecutedOnce) {
  write_script(std::string("1 ") + GetParam() + "\n");
  start({"--fault-script", file("faults.txt"), "--ur-unlock-delay", "0.3"});
  auto l = link(/*unlock=*/true);
  l->connect();
  const Eigen::VectorXd target = targets(1, 21)[0];
  const robotio::MoveResult r = l->move_actuators(target, kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  const auto faults = events(log(), "fault");
  ASSERT_EQ(faults.size(), 1u);
  EXPECT_EQ(faults[0]["kind"], GetParam());
  const auto ends = events(log(), "motion_end");
  ASSERT_FALSE(ends.empty());
  EXPECT_EQ(ends.back()["counts"].get<std::vector<long>>(), counts_of(target));
  EXPECT_EQ(motions_to(counts_of(target)), std::string(GetParam()) == "pstop" ? 2 : 1)
      << "a protective stop halts the first motion; the unlocked link sends it once more";
}

INSTANTIATE_TEST_SUITE_P(EveryRecoverableKind, UrFaultTest,
                         ::testing::Values("drop", "error", "slow", "missing", "pstop"));

TEST_F(UrLinkTest, StalledMoveIsStoppedAndReportedWithWhereTheJointsStopped) {
  write_script("1 stall\n");
  start({"--fault-script", file("faults.txt")});
  auto l = link();
  l->connect();
  try {
    l->move_actuators(targets(1, 5)[0], kSpeed);
    FAIL() << "a stalled move must not be confirmed";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("did not settle in time (stalled?): sent stopj"),
              std::string::npos)
        << e.what();
  }
  const auto stops = awaited("stop");
  ASSERT_FALSE(stops.empty());
  EXPECT_EQ(stops.back()["cmd"], "stopj");
}

// A script the controller refuses every time: the failure carries the controller's own words,
// read off the secondary interface (a runtime exception robot message), not only robocal's
// "did not take the movej".
TEST_F(UrLinkTest, ScriptTheControllerRefusesFailsWithTheControllersMessage) {
  write_script("1 error\n2 error\n3 error\n");
  start({"--fault-script", file("faults.txt")});
  auto l = link();
  l->connect();
  try {
    l->move_actuators(targets(1, 5)[0], kSpeed);
    FAIL() << "a refused movej must not be confirmed";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("did not take the movej after 3 sends"), std::string::npos) << what;
    EXPECT_NE(what.find("the controller said: runtime exception at line 1, column 1: \"movej "
                        "refused (injected fault)\""),
              std::string::npos)
        << what;
  }
  EXPECT_EQ(events(log(), "motion_start").size(), 0U);
}

TEST_F(UrLinkTest, ProtectiveStopDuringAMoveFailsItWithTheSafetyStatus) {
  write_script("1 pstop\n");
  start({"--fault-script", file("faults.txt")});
  auto l = link();  // the operator did not allow unlocking
  l->connect();
  try {
    l->move_actuators(targets(1, 5)[0], kSpeed);
    FAIL() << "a protective stop must end the move";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("safety status PROTECTIVE_STOP (3)"), std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(events(log(), "unlock_protective_stop").empty()) << "never unlocked unasked";
}

TEST_F(UrLinkTest, ArmInProtectiveStopIsRefusedAtConnectNamingWhatTheDashboardSaid) {
  start({"--ur-protective-stop"});
  auto l = link();
  try {
    l->connect();
    FAIL() << "a protective stop must be refused";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("UR 127.0.0.1"), std::string::npos) << what;
    EXPECT_NE(what.find("protective stop"), std::string::npos) << what;
    EXPECT_EQ(e.controller_said(), "Safetystatus: PROTECTIVE_STOP");
  }
  EXPECT_EQ(scripts("movej"), 0);
  EXPECT_TRUE(events(log(), "unlock_protective_stop").empty());
}

TEST_F(UrLinkTest, ProtectiveStopIsUnlockedOnlyWhenTheOperatorAllowedIt) {
  start({"--ur-protective-stop", "--ur-unlock-delay", "0.5"});
  auto l = link(/*unlock=*/true);
  l->connect();
  EXPECT_TRUE(events(log(), "unlock_protective_stop").empty()) << "connecting never unlocks";
  guard_->disarm();
  EXPECT_THROW(l->move_actuators(targets(1, 4)[0], kSpeed), MotionRefused);
  EXPECT_TRUE(events(log(), "unlock_protective_stop").empty()) << "nor does a refused move";
  guard_->arm("test: the operator confirmed");
  // Refused for the first 0.5 s with the controller's own words, then released.
  EXPECT_TRUE(l->move_actuators(targets(1, 4)[0], kSpeed).confirmed);
  EXPECT_EQ(events(log(), "unlock_protective_stop").size(), 1u);
}

TEST_F(UrLinkTest, RemoteControlOffIsRefusedAndNothingIsSent) {
  start({"--ur-remote-off"});
  auto l = link();
  try {
    l->connect();
    FAIL() << "local control must be refused";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("remote control is off"), std::string::npos) << e.what();
    EXPECT_EQ(e.controller_said(), "false");
  }
  EXPECT_EQ(scripts("movej"), 0);
}

TEST_F(UrLinkTest, SpeedSliderBelowFullIsRefusedBeforeTheMovej) {
  start({"--ur-speed-slider", "0.5"});
  auto l = link();
  l->connect();
  try {
    l->move_actuators(targets(1, 4)[0], kSpeed);
    FAIL() << "a slider at 50 % must be refused";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("speed slider is at 50 %"), std::string::npos) << e.what();
  }
  EXPECT_EQ(scripts("movej"), 0);
  EXPECT_TRUE(events(log(), "motion_start").empty());
}

TEST_F(UrLinkTest, RecipeFieldTheControllerDoesNotKnowIsRefusedByName) {
  start({"--ur-unknown-output", "target_speed_fraction"});
  auto l = link();
  try {
    l->connect();
    FAIL() << "a recipe with a NOT_FOUND field must be refused";
  } catch (const LinkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("does not know the output 'target_speed_fraction' (NOT_FOUND)"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("URControl 5.11.0.108"), std::string::npos) << what;
  }
  EXPECT_EQ(scripts("movej"), 0);
  // The simulator answered the recipe and was never asked to stream.
  int starts = 0;
  for (const auto& rx : events(log(), "rx"))
    if (rx.value("ch", "") == "rtde" && rx.value("type", "") == "S") ++starts;
  EXPECT_EQ(starts, 0);
}

TEST_F(UrLinkTest, NothingMovesUnconfirmed) {
  start();
  guard_->disarm();
  auto l = link();
  l->connect();
  EXPECT_THROW(l->move_actuators(targets(1, 4)[0], kSpeed), MotionRefused);
  EXPECT_EQ(scripts("movej"), 0);
}

TEST_F(UrLinkTest, DeadAddressFailsNamingTheDevice) {
  start();
  robotio::UrLinkOptions o = options();
  o.address = "ur:127.0.0.1:1:2:3";  // nothing listens on these ports
  o.reconnect_attempts = 1;
  UrLink l(*guard_, o);
  try {
    l.connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("UR 127.0.0.1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace robocal::test
