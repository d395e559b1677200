// The guard's clearance check wired to the planner's FCL cell model: a straight actuator path
// whose two ends are clear but whose middle sweeps the effector through an obstacle is refused
// naming the obstacle; the same path without the obstacle passes.
#include "live/cell_clearance.hpp"

#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/robot_file.hpp"
#include "robocal/planner/cell.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

namespace robocal::app {
namespace {

class CellClearance : public ::robocal::test::ScratchDirTest {
 protected:
  CellClearance() : ScratchDirTest("cell_clearance_") {}

  // A linear-delta cell; `obstacle` is one line of the obstacles list (or empty).
  planner::Cell cell(const std::string& obstacle) {
    const std::string data = ROBOCAL_TESTDATA_DIR;
    const std::string path = file("cell.yaml");
    std::ofstream(path)
        << "cell: clearance_test\nunits: m\nrobot: " << data
        << "/robots/linear_delta.yaml\ncameras:\n  - name: top\n    file: " << data
        << "/cells/camera_1600x1200.yaml\n"
           "    pose: {position: [0, 0.3, 0.06], look_at: [0, 0, 0.06], up: [0, 0, 1]}\n"
        << (obstacle.empty() ? "" : "obstacles:\n  - " + obstacle + "\n")
        << "workspace: {min: [-0.08, -0.08, 0.02], max: [0.08, 0.08, 0.16]}\n"
           "target: {file: "
        << data << "/vision/apriltag_4x3.yaml}\n";
    return planner::load_cell_file(path);
  }

  Eigen::VectorXd readings_at(double x) {
    calib::TaskTarget t;
    t.pose.translation() = Eigen::Vector3d(x, 0.0, 0.06);
    const calib::IkResult ik = calib::solve_ik(model_, params_, t);
    EXPECT_TRUE(ik.ok());
    return ik.actuator_readings;
  }

  robotio::GuardVerdict check(const planner::Cell& c, double from_x, double to_x) {
    planner::CollisionOptions options;
    options.clearance = c.margins.clearance;
    options.self_clearance = c.margins.self_clearance;
    const planner::CollisionScene scene(model_, c, options);
    robotio::SafetyLimits limits;
    limits.workspace_min = Eigen::Vector3d(-0.08, -0.08, 0.02);
    limits.workspace_max = Eigen::Vector3d(0.08, 0.08, 0.16);
    limits.max_speed = 0.25;
    limits.max_acceleration = 5.0;
    limits.path_step = 2e-3;
    robotio::SafetyGuard guard(model_, params_, limits);
    guard.arm("test");
    guard.set_clearance_check(cell_clearance_check(model_, params_, scene));
    return guard.check_move(readings_at(from_x), readings_at(to_x), {0.1, 1.0});
  }

  calib::Mechanism model_ =
      calib::load_robot_file(std::string(ROBOCAL_TESTDATA_DIR) + "/robots/linear_delta.yaml");
  Eigen::VectorXd params_ = model_.nominal_parameters();
};

TEST_F(CellClearance, PathSweepingTheEffectorThroughAnObstacleIsRefusedNamingIt) {
  // A 5 mm ball at the tool's height on the path's midpoint; the 8 cm effector plate passes
  // through it. Both ends keep the plate's edge 15 mm from the ball (clearance 10 mm).
  const planner::Cell with_post =
      cell("{name: post, sphere: {center: [0, 0, 0.06], radius: 0.005}}");
  const robotio::GuardVerdict stand_left = check(with_post, -0.06, -0.06);
  EXPECT_TRUE(stand_left.allowed) << stand_left.reason;
  const robotio::GuardVerdict stand_right = check(with_post, 0.06, 0.06);
  EXPECT_TRUE(stand_right.allowed) << stand_right.reason;

  const robotio::GuardVerdict through = check(with_post, -0.06, 0.06);
  EXPECT_FALSE(through.allowed);
  EXPECT_NE(through.reason.find("post"), std::string::npos) << through.reason;

  const robotio::GuardVerdict free_cell = check(cell(""), -0.06, 0.06);
  EXPECT_TRUE(free_cell.allowed) << free_cell.reason;
}

}  // namespace
}  // namespace robocal::app
