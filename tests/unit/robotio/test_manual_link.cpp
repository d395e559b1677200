// The manual link (`--link manual`): targets shown to the operator, answers read from a pipe
// standing in for the terminal. A pose is confirmed only where the typed readings put the robot,
// and nothing is shown before the safety guard allowed it.
#include "robocal/calib/robot_file.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/manual_link.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <string>
#include <thread>

namespace robocal::robotio {
namespace {

constexpr MoveSpeed kSpeed{0.1, 1.0};

SafetyLimits limits() {
  SafetyLimits l;
  l.workspace_min = Eigen::Vector3d(-0.08, -0.08, 0.02);
  l.workspace_max = Eigen::Vector3d(0.08, 0.08, 0.16);
  l.max_speed = 0.25;
  l.max_acceleration = 5.0;
  l.path_step = 2e-3;
  return l;
}

class ManualLinkTest : public ::testing::Test {
 protected:
  ManualLinkTest()
      : model_(calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) +
                                      "/robots/linear_delta.yaml")),
        guard_(model_, model_.nominal_parameters(), limits()) {
    if (::pipe(pipe_) != 0) throw std::runtime_error("pipe");
    out_ = std::tmpfile();
    guard_.arm("test: nobody near the robot");
  }
  ~ManualLinkTest() override {
    ::close(pipe_[0]);
    if (pipe_[1] >= 0) ::close(pipe_[1]);
    std::fclose(out_);
  }
  void type(const std::string& text) {
    ASSERT_EQ(::write(pipe_[1], text.data(), text.size()), static_cast<ssize_t>(text.size()));
  }
  std::string shown() {
    std::fflush(out_);
    std::rewind(out_);
    std::string s;
    char buf[4096];
    std::size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, out_)) > 0) s.append(buf, n);
    return s;
  }
  std::unique_ptr<ManualLink> link() {
    ManualLinkOptions o;
    o.input_fd = pipe_[0];
    o.out = out_;
    return std::make_unique<ManualLink>(guard_, o);
  }
  // A reachable pose inside the box: all three carriages equal puts the effector on the axis.
  Eigen::VectorXd target() const { return Eigen::Vector3d(0.28, 0.281, 0.279); }
  static std::string typed(const Eigen::VectorXd& v) {
    return fmt::format("{:.6f}, {:.6f}, {:.6f}\n", v[0], v[1], v[2]);
  }

  calib::Mechanism model_;
  SafetyGuard guard_;
  int pipe_[2] = {-1, -1};
  std::FILE* out_ = nullptr;
};

TEST_F(ManualLinkTest, ShowsTheTargetAndConfirmsWhereTheTypedReadingsAre) {
  auto l = link();
  type("0.3 0.3 0.3\n");
  l->connect();
  EXPECT_EQ(l->last_known(), Eigen::Vector3d(0.3, 0.3, 0.3));
  type("done\n" + typed(target()));
  const MoveResult r = l->move_actuators(target(), kSpeed);
  EXPECT_TRUE(r.confirmed) << r.reason;
  EXPECT_TRUE(r.readings.values.isApprox(target(), 1e-9));
  const std::string out = shown();
  EXPECT_NE(out.find("carriage_a"), std::string::npos) << out;
  EXPECT_NE(out.find("0.281000 m"), std::string::npos) << out;
}

TEST_F(ManualLinkTest, TypedReadingsAwayFromTheTargetAreNotConfirmed) {
  auto l = link();
  type("0.3 0.3 0.3\n");
  l->connect();
  Eigen::VectorXd off = target();
  off[1] += 0.5e-3;  // half a millimetre: more than the 0.1 mm tolerance
  type("done\n" + typed(off));
  const MoveResult r = l->move_actuators(target(), kSpeed);
  EXPECT_FALSE(r.confirmed);
  EXPECT_NE(r.reason.find("away from the target"), std::string::npos) << r.reason;
  EXPECT_TRUE(l->last_known().isApprox(off, 1e-12)) << "the next path starts where it is";
}

TEST_F(ManualLinkTest, NothingIsShownBeforeTheGuardAllowsIt) {
  auto l = link();
  type("0.3 0.3 0.3\n");
  l->connect();
  guard_.disarm();
  EXPECT_THROW(l->move_actuators(target(), kSpeed), MotionRefused);
  Eigen::VectorXd outside = target();
  outside[0] = 0.0;  // far outside the workspace box
  guard_.arm("test");
  EXPECT_THROW(l->move_actuators(outside, kSpeed), MotionRefused);
  EXPECT_EQ(shown().find("Move the robot to"), std::string::npos) << shown();
}

TEST_F(ManualLinkTest, AnswersThatAreNotReadingsAreAskedAgainThenRefused) {
  auto l = link();
  type("zero\n0.3 0.3\n0.3 0.3 0.3\n");
  l->connect();
  EXPECT_EQ(l->last_known(), Eigen::Vector3d(0.3, 0.3, 0.3));
  type("a\nb\nc d e\n");
  try {
    l->read_actuators();
    FAIL() << "three bad answers must fail";
  } catch (const LinkError& e) {
    EXPECT_EQ(e.device(), "manual link (operator)");
    EXPECT_EQ(e.controller_said(), "c d e");
  }
}

TEST_F(ManualLinkTest, OperatorTypingStopInterruptsAndTheSessionResumes) {
  auto l = link();
  type("0.3 0.3 0.3\n");
  l->connect();
  type("stop\n0.29 0.29 0.29\n");
  EXPECT_THROW(l->move_actuators(target(), kSpeed), MotionInterrupted);
  EXPECT_TRUE(guard_.stop_requested());
  EXPECT_EQ(l->last_known(), Eigen::Vector3d(0.29, 0.29, 0.29)) << "read where the robot stopped";
  guard_.resume();
  guard_.arm("test: resumed");
  type("done\n" + typed(target()));
  EXPECT_TRUE(l->move_actuators(target(), kSpeed).confirmed);
}

TEST_F(ManualLinkTest, CtrlCWhileWaitingShowsTheStop) {
  auto l = link();
  type("0.3 0.3 0.3\n");
  l->connect();
  std::thread operator_side([this] {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    guard_.request_stop_from_signal();
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    type("0.295 0.295 0.295\n");  // asked where the robot stopped
  });
  EXPECT_THROW(l->move_actuators(target(), kSpeed), MotionInterrupted);
  operator_side.join();
  EXPECT_NE(shown().find("STOP: stop the robot now"), std::string::npos) << shown();
}

TEST_F(ManualLinkTest, ClosedInputIsALinkError) {
  auto l = link();
  ::close(pipe_[1]);
  pipe_[1] = -1;
  EXPECT_THROW(l->connect(), LinkError);
}

TEST(TypedReadings, SpacesOrCommasAndTheRightCount) {
  EXPECT_TRUE(parse_typed_readings("1, 2 ,3", 3).has_value());
  EXPECT_TRUE(parse_typed_readings("1\t2;3", 3).has_value());
  EXPECT_FALSE(parse_typed_readings("1 2", 3).has_value());
  EXPECT_FALSE(parse_typed_readings("1 2 3x", 3).has_value());
  EXPECT_FALSE(parse_typed_readings("", 3).has_value());
}

}  // namespace
}  // namespace robocal::robotio
