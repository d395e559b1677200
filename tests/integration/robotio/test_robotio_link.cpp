// The G-code link against the simulated controller running as its own process (the built
// `robocal sim-controller`), over a real loopback TCP socket and a real pseudo-terminal. The
// simulator's JSONL log is the independent record: what it received and what it executed.
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/stop_signals.hpp"
#include "robocal/robotio/task_space.hpp"
#include "robotio_sim.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <sys/wait.h>

#include <fstream>
#include <map>
#include <numbers>
#include <optional>
#include <ostream>
#include <thread>

namespace robocal::test {
namespace {

using robotio::GcodeLink;
using robotio::LinkError;
using robotio::MotionInterrupted;
using robotio::MotionRefused;
using robotio::MoveSpeed;
using robotio::SafetyGuard;
using robotio::SimControllerProcess;

constexpr MoveSpeed kSpeed{0.2, 4.0};

enum class Wire { kTcp, kPty };
// How GoogleTest shows the parameter (test listings, failures): "Tcp", not raw bytes.
void PrintTo(Wire wire, std::ostream* os) {
  *os << (wire == Wire::kTcp ? "Tcp" : "Pty");
}

class LinkTest : public ScratchDirTest {
 protected:
  LinkTest() : ScratchDirTest("robotio_link_") {}

  void start(const std::vector<std::string>& extra = {}) {
    log_ = file("sim.jsonl");
    sim_ = std::make_unique<SimControllerProcess>(ROBOCAL_BINARY, sim_args(log_, extra));
    guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
    guard_->arm("test: simulated cell, nothing can be hurt");
  }
  std::unique_ptr<GcodeLink> link(Wire wire) {
    return std::make_unique<GcodeLink>(
        *guard_, link_options(model_, wire == Wire::kTcp ? sim_->tcp() : sim_->pty()));
  }
  std::vector<nlohmann::json> log() const { return read_sim_log(log_); }

  // Motions the simulator started towards exactly these counts.
  int motions_to(const std::vector<long>& counts) const {
    int n = 0;
    for (const auto& m : events(log(), "motion_start"))
      if (m["to"].get<std::vector<long>>() == counts) ++n;
    return n;
  }

  calib::Mechanism model_ = linear_delta();
  std::string log_;
  std::unique_ptr<SimControllerProcess> sim_;
  std::unique_ptr<SafetyGuard> guard_;
};

class LinkWireTest : public LinkTest, public ::testing::WithParamInterface<Wire> {};

TEST_P(LinkWireTest, IdentifiesHomesMovesAndReadsBackEveryTarget) {
  start({"--firmware", GetParam() == Wire::kTcp ? "marlin" : "rrf"});
  auto l = link(GetParam());
  const robotio::FirmwareInfo fw = l->connect();
  EXPECT_EQ(fw.firmware, GetParam() == Wire::kTcp ? robotio::Firmware::kMarlin
                                                  : robotio::Firmware::kRepRapFirmware);
  l->home();
  for (const Eigen::VectorXd& target : delta_targets(model_, 5, 3)) {
    const robotio::MoveResult r = l->move_actuators(target, kSpeed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const std::vector<long> expect = l->counts_for(target);
    EXPECT_EQ(r.readings.counts, expect);
    for (int i = 0; i < 3; ++i)  // converted values within half a step (12.5 um) of the target
      EXPECT_NEAR(r.readings.values[i], target[i], 0.5 / 80.0 / 1000.0 + 1e-12);
    EXPECT_EQ(motions_to(expect), 1) << "each move executed exactly once";
  }
}

INSTANTIATE_TEST_SUITE_P(Wires, LinkWireTest, ::testing::Values(Wire::kTcp, Wire::kPty),
                         [](const ::testing::TestParamInfo<Wire>& p) {
                           return std::string(p.param == Wire::kTcp ? "Tcp" : "Pty");
                         });

// Task space through calib's IK; the simulator's true-pose channel is the ground truth.
TEST_F(LinkTest, TaskSpaceMoveReachesTheTargetOnTheTruePoseChannel) {
  start({"--noise", "0", "--backlash", "0"});
  auto l = link(Wire::kTcp);
  l->connect();
  calib::TaskTarget target;
  target.pose.translation() = Eigen::Vector3d(0.02, -0.03, 0.09);
  const robotio::MoveResult r =
      robotio::move_to_task_target(*l, model_, model_.nominal_parameters(), target, kSpeed);
  ASSERT_TRUE(r.confirmed) << r.reason;
  // Ask the pose channel (a plain TCP line protocol) where the effector really is.
  const std::string pose = sim_->pose();
  const int port = std::stoi(pose.substr(pose.rfind(':') + 1));
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ASSERT_EQ(::write(fd, "pose\n", 5), 5);
  std::string reply;
  char c = 0;
  while (::read(fd, &c, 1) == 1 && c != '\n') reply += c;
  ::close(fd);
  const auto j = nlohmann::json::parse(reply);
  ASSERT_TRUE(j.contains("position")) << reply;
  const Eigen::Vector3d p(j["position"][0], j["position"][1], j["position"][2]);
  // Nominal truth, no noise: only the 12.5 um step quantisation of each carriage separates the
  // effector from the target (a carriage step moves the effector by at most ~2 steps here).
  EXPECT_LT((p - target.pose.translation()).norm(), 50e-6) << reply;
  EXPECT_FALSE(j["moving"].get<bool>());
}

// Every fault kind, forced by a fault script on the first move's G1 (command index 6: M110,
// M115, M113, G90, M114 come first on Marlin) and on its M400 and M114.
struct FaultCase {
  std::string kind;
  Wire wire;
};
// How GoogleTest shows the parameter (test listings, failures): "stall over Pty", not raw bytes.
void PrintTo(const FaultCase& c, std::ostream* os) {
  *os << c.kind << " over " << (c.wire == Wire::kTcp ? "Tcp" : "Pty");
}

class FaultTest : public LinkTest, public ::testing::WithParamInterface<FaultCase> {};

TEST_P(FaultTest, EveryMoveEndsConfirmedOrFailsWithItsReasonAndNothingRunsTwice) {
  const std::string script = file("faults.txt");
  {
    std::ofstream s(script);
    // After connect: 1 M110, 2 M115, 3 M113, 4 G90, 5 M114; then per move M204 (first only),
    // G1, M400, M114.
    for (int index : {7, 12, 17, 21, 24}) s << index << " " << GetParam().kind << "\n";
  }
  start({"--fault-script", script, "--slow-ms", "200"});
  auto l = link(GetParam().wire);
  l->connect();
  int confirmed = 0, failed = 0;
  std::vector<std::vector<long>> targets;
  for (const Eigen::VectorXd& target : delta_targets(model_, 6, 11)) {
    targets.push_back(l->counts_for(target));
    try {
      const robotio::MoveResult r = l->move_actuators(target, kSpeed);
      if (r.confirmed) {
        ++confirmed;
      } else {
        ++failed;
        EXPECT_FALSE(r.reason.empty());
      }
    } catch (const LinkError& e) {
      ++failed;
      EXPECT_NE(std::string(e.what()).find(l->status().device), std::string::npos) << e.what();
      if (GetParam().kind == "stall") {
        EXPECT_NE(std::string(e.what()).find("did not settle"), std::string::npos) << e.what();
      }
    }
  }
  const auto sim_log = log();
  EXPECT_GE(events(sim_log, "fault").size(), 1u);
  for (const auto& counts : targets) EXPECT_LE(motions_to(counts), 1) << "a motion ran twice";
  if (GetParam().kind == "stall") {
    EXPECT_GE(failed, 1);
    EXPECT_GE(received(sim_log, "M410"), 1) << "a stalled move must be stopped";
  } else {
    EXPECT_EQ(failed, 0) << GetParam().kind << " must be recovered";
    EXPECT_EQ(confirmed, 6);
    for (const auto& counts : targets) EXPECT_EQ(motions_to(counts), 1) << "a motion was lost";
  }
  const robotio::LinkStatus st = l->status();
  if (GetParam().kind == "drop") {
    EXPECT_GE(st.reconnects, 1);
  }
  if (GetParam().kind == "resend" || GetParam().kind == "corrupt") {
    EXPECT_GE(st.resends, 1);
  }
  if (GetParam().kind == "lost_ok") {
    EXPECT_GE(st.timeouts, 1);
  }
  if (GetParam().kind == "busy") {
    EXPECT_GE(st.busy_lines, 2);
  }
  if (GetParam().kind == "garbage") {
    EXPECT_GE(st.garbage, 1);
  }
  if (GetParam().kind == "error") {
    EXPECT_GE(st.errors, 1);
  }
}

std::vector<FaultCase> all_fault_cases() {
  std::vector<FaultCase> out;
  for (const char* k : {"drop", "busy", "error", "stall", "corrupt", "lost_ok", "resend", "slow",
                        "garbage", "partial"})
    for (Wire w : {Wire::kTcp, Wire::kPty}) out.push_back({k, w});
  return out;
}

INSTANTIATE_TEST_SUITE_P(Kinds, FaultTest, ::testing::ValuesIn(all_fault_cases()),
                         [](const ::testing::TestParamInfo<FaultCase>& p) {
                           return p.param.kind + (p.param.wire == Wire::kTcp ? "_Tcp" : "_Pty");
                         });

// ---- safety: refused before anything is sent --------------------------------------------------

TEST_F(LinkTest, RefusedMovesSendNothing) {
  start();
  auto l = link(Wire::kTcp);
  l->connect();
  const int g1_before = received(log(), "G1");
  // Outside the workspace: the effector below the box (carriages low).
  calib::TaskTarget low;
  low.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.005);
  const calib::IkResult ik = calib::solve_ik(model_, model_.nominal_parameters(), low);
  ASSERT_TRUE(ik.ok());
  try {
    l->move_actuators(ik.actuator_readings, kSpeed);
    FAIL() << "a target outside the workspace was accepted";
  } catch (const MotionRefused& e) {
    EXPECT_NE(std::string(e.what()).find("outside the declared workspace"), std::string::npos)
        << e.what();
  }
  // Too fast.
  const std::vector<Eigen::VectorXd> targets = delta_targets(model_, 2, 5);
  EXPECT_THROW(l->move_actuators(targets[0], MoveSpeed{0.3, 4.0}), MotionRefused);
  EXPECT_THROW(l->move_actuators(targets[0], MoveSpeed{0.2, 50.0}), MotionRefused);
  // Through an obstacle: both ends are clear, the straight actuator path is not. The obstacle
  // is a ball around the path's midpoint (computed here from the nominal kinematics).
  const Eigen::VectorXd from = l->last_known();
  const Eigen::VectorXd mid = 0.5 * (from + targets[1]);
  const calib::ForwardResult fk =
      calib::forward_kinematics(model_, model_.nominal_parameters(), mid, model_.tool);
  ASSERT_TRUE(fk.closure.ok());
  const Eigen::Vector3d ball = fk.pose.translation();
  const double radius = 0.004;
  ASSERT_GT((calib::forward_kinematics(model_, model_.nominal_parameters(), targets[1], model_.tool)
                 .pose.translation() -
             ball)
                .norm(),
            radius);
  guard_->set_clearance_check([&](const robotio::PathSample& s) -> std::optional<std::string> {
    if ((s.tool_pose.translation() - ball).norm() < radius) return "inside the test ball";
    return std::nullopt;
  });
  try {
    l->move_actuators(targets[1], kSpeed);
    FAIL() << "a path through an obstacle was accepted";
  } catch (const MotionRefused& e) {
    EXPECT_NE(std::string(e.what()).find("inside the test ball"), std::string::npos) << e.what();
  }
  // Not armed.
  guard_->set_clearance_check(nullptr);
  guard_->disarm();
  EXPECT_THROW(l->move_actuators(targets[1], kSpeed), MotionRefused);
  // Dry run: all checks, nothing sent.
  guard_->set_dry_run(true);
  EXPECT_TRUE(l->move_actuators(targets[1], kSpeed).dry_run);
  EXPECT_EQ(received(log(), "G1"), g1_before) << "a refused or dry-run move reached the controller";
}

TEST_F(LinkTest, CtrlCDuringAMoveSendsTheStopAndTheSessionResumes) {
  start();
  auto l = link(Wire::kPty);
  l->connect();
  std::optional<robotio::StopSignals> signals(std::in_place, *guard_);
  const std::vector<Eigen::VectorXd> targets = delta_targets(model_, 2, 8);
  // A slow, long move inside the workspace (7 cm of carriage travel at 2 cm/s), so the signal
  // lands mid-motion.
  calib::TaskTarget low, high;
  low.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.04);
  high.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.11);
  const Eigen::VectorXd params = model_.nominal_parameters();
  ASSERT_TRUE(
      l->move_actuators(calib::solve_ik(model_, params, low).actuator_readings, kSpeed).confirmed);
  const Eigen::VectorXd far = calib::solve_ik(model_, params, high).actuator_readings;
  std::thread ctrl_c([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    ::kill(::getpid(), SIGINT);
  });
  EXPECT_THROW(l->move_actuators(far, MoveSpeed{0.02, 1.0}), MotionInterrupted);
  ctrl_c.join();
  signals.reset();
  const auto sim_log = log();
  EXPECT_GE(received(sim_log, "M410"), 1) << "the controller never received the stop";
  ASSERT_FALSE(events(sim_log, "stop").empty());
  const auto ended = events(sim_log, "motion_end");
  ASSERT_FALSE(ended.empty());
  EXPECT_TRUE(ended.back()["stopped"].get<bool>()) << "the move ran to its end";
  // Refused while the stop stands; resumable after the operator confirms again.
  EXPECT_THROW(l->move_actuators(targets[0], kSpeed), MotionRefused);
  guard_->resume();
  guard_->arm("operator confirmed after Ctrl-C");
  l->read_actuators();
  EXPECT_TRUE(l->move_actuators(targets[0], kSpeed).confirmed);
}

TEST_F(LinkTest, LostCameraDuringAMoveStopsTheRobot) {
  start();
  auto l = link(Wire::kTcp);
  l->connect();
  calib::TaskTarget high;
  high.pose.translation() = Eigen::Vector3d(0.0, 0.0, 0.12);
  const Eigen::VectorXd far =
      calib::solve_ik(model_, model_.nominal_parameters(), high).actuator_readings;
  std::thread camera([this] {
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    guard_->camera_lost("cam1");
  });
  try {
    l->move_actuators(far, MoveSpeed{0.02, 1.0});
    ADD_FAILURE() << "the move finished although the camera was lost";
  } catch (const MotionInterrupted& e) {
    EXPECT_NE(std::string(e.what()).find("camera cam1 lost"), std::string::npos) << e.what();
  }
  camera.join();
  EXPECT_GE(received(log(), "M410"), 1);
  EXPECT_TRUE(events(log(), "motion_end").back()["stopped"].get<bool>());
}

TEST_F(LinkTest, EmergencyStopHaltsTheController) {
  start();
  auto l = link(Wire::kTcp);
  l->connect();
  l->stop(GcodeLink::StopKind::kEmergency);
  try {
    l->read_actuators();
    FAIL() << "a halted controller answered";
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("halted"), std::string::npos) << e.what();
  }
  EXPECT_EQ(received(log(), "M112"), 1);
  ASSERT_FALSE(events(log(), "stop").empty());
  EXPECT_EQ(events(log(), "stop").back()["cmd"], "M112");
}

// RepRapFirmware has no quick stop: the controlled stop is M112 then M999, and the link is
// usable again afterwards.
TEST_F(LinkTest, RrfControlledStopRestartsTheFirmware) {
  start({"--firmware", "rrf"});
  auto l = link(Wire::kPty);
  l->connect();
  l->stop(GcodeLink::StopKind::kControlled);
  EXPECT_EQ(received(log(), "M112"), 1);
  EXPECT_EQ(received(log(), "M999"), 1);
  EXPECT_EQ(received(log(), "M410"), 0);
  const std::vector<Eigen::VectorXd> targets = delta_targets(model_, 1, 2);
  EXPECT_TRUE(l->move_actuators(targets[0], kSpeed).confirmed);
}

// ---- bad input ------------------------------------------------------------------------------

TEST_F(LinkTest, SerialDeviceThatDoesNotExistIsNamed) {
  guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
  GcodeLink l(*guard_, link_options(model_, "/dev/ttyACM-robocal-none"));
  try {
    l.connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/ttyACM-robocal-none"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("No such file"), std::string::npos) << e.what();
  }
}

TEST_F(LinkTest, ControllerThatNeverAnswersFailsAfterRetriesNamingTheDevice) {
  start({"--mute"});
  auto l = link(Wire::kTcp);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    l->connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find(sim_->tcp().substr(4)), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("failed 4 times"), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(10));
  EXPECT_GE(received(log(), "M110"), 4) << "the link should retry";
}

TEST_F(LinkTest, UnknownFirmwareBannerIsRefusedWithWhatItSaid) {
  start({"--firmware-name", "Grbl 1.1h ['$' for help]"});
  auto l = link(Wire::kPty);
  try {
    l->connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown firmware"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("Grbl 1.1h"), std::string::npos) << e.what();
  }
}

TEST_F(LinkTest, PartialPositionReportsAreRetriedThenReported) {
  start({"--faults", "partial=1"});
  auto l = link(Wire::kTcp);
  try {
    l->connect();  // reads the position once connected
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("no readable M114"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("controller said"), std::string::npos) << e.what();
  }
  EXPECT_EQ(received(log(), "M114"), 4);
}

TEST_F(LinkTest, WrongChecksumsOnEveryLineFailWithTheResendRequest) {
  start({"--faults", "corrupt=1"});
  auto l = link(Wire::kPty);
  try {
    l->connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("'M115' failed 4 times"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("Resend: 1"), std::string::npos) << e.what();
  }
  EXPECT_GE(events(log(), "fault").size(), 4u);
}

TEST_F(LinkTest, GarbageAndUnsolicitedLinesAreSkipped) {
  start({"--faults", "garbage=1", "--temperature-interval", "0.05"});
  auto l = link(Wire::kPty);
  l->connect();
  const std::vector<Eigen::VectorXd> targets = delta_targets(model_, 2, 21);
  for (const auto& t : targets) EXPECT_TRUE(l->move_actuators(t, kSpeed).confirmed);
  EXPECT_GE(l->status().garbage, 5);
  EXPECT_GE(l->status().unsolicited, 1);
}

TEST_F(LinkTest, ReconnectsAfterTheControllerDropsTheConnection) {
  const std::string script = file("faults.txt");
  std::ofstream(script) << "7 drop\n9 drop\n";
  start({"--fault-script", script});
  auto l = link(Wire::kPty);
  l->connect();
  const std::vector<Eigen::VectorXd> targets = delta_targets(model_, 3, 4);
  for (const auto& t : targets) {
    const robotio::MoveResult r = l->move_actuators(t, kSpeed);
    EXPECT_TRUE(r.confirmed) << r.reason;
    EXPECT_EQ(motions_to(l->counts_for(t)), 1);
  }
  EXPECT_GE(l->status().reconnects, 1);
  EXPECT_GE(events(log(), "disconnect").size(), 1u);
}

TEST_F(LinkTest, ConnectionRefusedNamesTheAddress) {
  guard_ = std::make_unique<SafetyGuard>(model_, model_.nominal_parameters(), delta_limits());
  // A port nobody listens on: bind one, close it, connect to it.
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  const int port = ntohs(addr.sin_port);
  ::close(fd);
  GcodeLink l(*guard_, link_options(model_, "tcp:127.0.0.1:" + std::to_string(port)));
  try {
    l.connect();
    FAIL();
  } catch (const LinkError& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(port)), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("refused"), std::string::npos) << e.what();
  }
}

// Axes in different units move at the joint speed asked. The modular arm's firmware axes are
// degrees (two revolute joints) and millimetres (the prismatic one): a feed taken from one axis'
// units alone made a long joint move take several times what the link waited for ("did not
// settle"). The wire robot's branch is read in encoder counts: its G-code axes are the joints'
// degrees. Each move's duration as the simulator planned it is checked against the trapezoid
// over the joint-value change, written here.
double joint_trapezoid(double length, double v, double a) {
  return length >= v * v / a ? length / v + v / a : 2.0 * std::sqrt(length / a);
}

class MixedAxesTest : public ScratchDirTest, public ::testing::WithParamInterface<std::string> {
 protected:
  MixedAxesTest() : ScratchDirTest("robotio_axes_") {}
};

TEST_P(MixedAxesTest, MovesTakeTheTimeOfTheJointSpeedAsked) {
  const calib::Mechanism model =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + GetParam() + ".yaml");
  const Eigen::VectorXd p = model.nominal_parameters();
  const std::string log = file("sim.jsonl");
  SimControllerProcess sim(ROBOCAL_BINARY, {"--robot", GetParam(), "--log", log, "--noise", "0",
                                            "--backlash", "0", "--max-seconds", "300"});
  robotio::SafetyLimits limits;
  limits.max_speed = 4.0;
  limits.max_acceleration = 40.0;
  SafetyGuard guard(model, p, limits);
  guard.arm("test: simulated cell, nothing can be hurt");
  GcodeLink l(guard, link_options(model, sim.tcp()));
  l.connect();
  l.home();
  const auto n = static_cast<Eigen::Index>(model.actuated.size());
  Eigen::VectorXd q = model.home_actuated();
  const Eigen::VectorXd home_q = q;
  // Every actuator a tenth of its way towards its upper limit, then back half of that.
  Eigen::VectorXd far = q;
  for (Eigen::Index i = 0; i < n; ++i)
    far[i] += 0.1 * (model.bodies[model.actuated[static_cast<std::size_t>(i)]].limits.upper - q[i]);
  const MoveSpeed speed{0.5, 2.0};
  for (const Eigen::VectorXd& target_q : {far, Eigen::VectorXd(0.5 * (far + home_q))}) {
    const Eigen::VectorXd from_q = q;
    const robotio::MoveResult r =
        l.move_actuators(calib::readings_from_joint_values(model, p, target_q), speed);
    ASSERT_TRUE(r.confirmed) << r.reason;
    const auto starts = events(read_sim_log(log), "motion_start");
    ASSERT_FALSE(starts.empty());
    const double planned = starts.back()["duration_s"].get<double>();
    EXPECT_NEAR(planned,
                joint_trapezoid((target_q - from_q).norm(), speed.speed, speed.acceleration), 0.02)
        << "move to " << target_q.transpose();
    // The G-code target is the joint's millimetres or degrees.
    const auto gcode = starts.back()["target"].get<std::vector<double>>();
    for (Eigen::Index i = 0; i < n; ++i) {
      const bool prismatic = model.bodies[model.actuated[static_cast<std::size_t>(i)]].joint ==
                             calib::JointType::kPrismatic;
      EXPECT_NEAR(gcode[static_cast<std::size_t>(i)],
                  target_q[i] * (prismatic ? 1000.0 : 180.0 / std::numbers::pi), 0.02)
          << "axis " << i;
    }
    q = target_q;
  }
}

INSTANTIATE_TEST_SUITE_P(Robots, MixedAxesTest,
                         ::testing::Values("modular_arm", "wire_robot_branch"));

// A simulator outlives nothing: when the process that started it ends without stopping it (a
// crash, SIGKILL; here _exit, which runs no destructor), it exits instead of serving on until
// --max-seconds.
class SimProcessTest : public ScratchDirTest {
 protected:
  SimProcessTest() : ScratchDirTest("robotio_simproc_") {}
};

TEST_F(SimProcessTest, ExitsWhenTheProcessThatStartedItEnds) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const std::string log = file("sim.jsonl");
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fds[0]);
    pid_t sim_pid = -1;
    try {
      // Never destroyed: the child ends as a crash would.
      const auto* sim = new SimControllerProcess(ROBOCAL_BINARY, sim_args(log, {}));
      sim_pid = sim->pid();
    } catch (...) {
    }
    (void)!::write(fds[1], &sim_pid, sizeof sim_pid);
    ::_exit(0);
  }
  ::close(fds[1]);
  pid_t sim_pid = -1;
  ASSERT_EQ(::read(fds[0], &sim_pid, sizeof sim_pid), static_cast<ssize_t>(sizeof sim_pid));
  ::close(fds[0]);
  ::waitpid(child, nullptr, 0);
  ASSERT_GT(sim_pid, 0) << "the simulator did not start";
  auto running = [&] {
    std::ifstream stat("/proc/" + std::to_string(sim_pid) + "/stat");
    std::string line;
    std::getline(stat, line);
    return !line.empty() && line.find(") Z") == std::string::npos;  // a zombie has exited
  };
  for (int i = 0; i < 500 && running(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const bool still = running();
  if (still) ::kill(sim_pid, SIGKILL);
  EXPECT_FALSE(still) << "the simulator kept serving after its parent ended";
  bool logged = false;
  for (const auto& e : events(read_sim_log(log), "exit"))
    logged = e.contains("parent_gone") && e.at("parent_gone").get<bool>();
  EXPECT_TRUE(logged);
}

}  // namespace
}  // namespace robocal::test
