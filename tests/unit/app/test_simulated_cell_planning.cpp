// The simulated cell plans its cameras and poses (planner/): for robots unlike the Delta (a
// serial arm whose board sweeps a ring, the Gantry-Tau whose tool point sits inside its
// platform box, the UR5 whose poses are built in task space with the board on its flange) the
// planned poses are seen whole by both TRUE cameras, checked with the
// renderer's own corner visibility on the true robot, and the board is outside the tool's
// collision shapes (the plan's lines of sight would be blocked otherwise).
#include "simcell/simulated_cell.hpp"

#include "robocal/calib/closure.hpp"
#include "robocal/vision/renderer.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>

namespace {

using namespace robocal;

class SimulatedCellPlanning : public ::testing::TestWithParam<std::string> {};

TEST_P(SimulatedCellPlanning, PlannedPosesAreSeenWholeByBothTrueCameras) {
  std::mt19937 rng(11);
  app::CellOptions options;
  options.image_width = 1280;
  options.image_height = 960;
  options.focal_px = 1300;
  const app::SimulatedCell cell = app::make_simulated_cell(
      std::string(ROBOCAL_TESTDATA_DIR) + "/robots/" + GetParam() + ".yaml", options, rng);
  ASSERT_EQ(cell.cameras.size(), 2u);
  std::string summary;
  const std::vector<Eigen::VectorXd> planned = app::plan_cell_poses(cell, 20, rng, &summary);
  ASSERT_EQ(planned.size(), 20u) << summary;
  int seen = 0;
  for (const Eigen::VectorXd& q : planned) {
    Eigen::Isometry3d world_T_board;
    ASSERT_TRUE(app::true_frame_pose(cell, q, &world_T_board));
    bool all = true;
    for (const app::SimulatedCamera& cam : cell.cameras) {
      const auto corners = vision::corner_truth(
          cam.model, {{cell.ee_board, cam.camera_T_world * world_T_board}}, options.render);
      all = all && !corners.empty() &&
            std::all_of(corners.begin(), corners.end(), [](const auto& c) { return c.visible; });
    }
    seen += all ? 1 : 0;
  }
  // The plan knows only the nominal robot and intrinsics (no distortion): a pose at the image
  // border may slip out on the true cell, rarely.
  EXPECT_GE(seen, 18) << summary;
  // The board (its frame origin, the pattern's corner) is not inside any box of the bodies
  // rigidly carrying it, at the nominal robot.
  const Eigen::VectorXd q = planned.front();
  for (int b = cell.target_frame; b >= 0;) {
    const calib::Body& body = cell.model.bodies.at(static_cast<std::size_t>(b));
    const auto fk = calib::forward_kinematics(cell.model, cell.nominal, q, b);
    const auto board = calib::forward_kinematics(cell.model, cell.nominal, q, cell.target_frame);
    ASSERT_TRUE(fk.closure.ok() && board.closure.ok());
    for (const calib::CollisionShape& s : body.collision) {
      if (s.kind != calib::ShapeKind::kBox) continue;
      for (const vision::TargetCorner& c : cell.ee_board.corners) {
        const Eigen::Vector3d local =
            s.rotation.transpose() * (fk.pose.inverse() * (board.pose * c.point) - s.a);
        EXPECT_FALSE((local.cwiseAbs() - s.half_size).maxCoeff() < -1e-9)
            << GetParam() << ": board corner inside a box of body " << body.name;
      }
    }
    if (body.joint != calib::JointType::kFixed) break;
    b = body.parent;
  }
}

INSTANTIATE_TEST_SUITE_P(Robots, SimulatedCellPlanning,
                         ::testing::Values("rotary_delta", "gantry_tau", "modular_arm", "ur5"));

}  // namespace
