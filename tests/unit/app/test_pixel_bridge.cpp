// Detections + calibrated rig + target corners -> calib pixel observations: the conventions
// (camera_T_world inverted, corner points in the measured frame, pixel sigma) are checked by the
// identification's own residual, which must vanish at the true frame pose.
#include "stages/pixel_bridge.hpp"

#include "robocal/vision/camera_model.hpp"

#include <gtest/gtest.h>

namespace {

using namespace robocal;

// The measured frame's pose is the actuator vector itself: [translation; rotation vector].
class PoseAsReadings final : public calib::FramePredictor {
 public:
  std::size_t parameter_count() const override { return 0; }
  std::vector<std::string> parameter_names() const override { return {}; }
  bool predict(const Eigen::VectorXd& /*params*/, const Eigen::VectorXd& q, int /*slot*/,
               bool with_jacobian, calib::FramePrediction& out,
               std::string& /*why*/) const override {
    out.pose = pose_of(q);
    if (with_jacobian) out.jacobian.setZero(6, 0);
    return true;
  }
  static Eigen::Isometry3d pose_of(const Eigen::VectorXd& q) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = q.head<3>();
    const Eigen::Vector3d r = q.tail<3>();
    T.linear() = Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix();
    return T;
  }
};

struct RigAndTarget {
  std::vector<vision::RigCamera> rig;
  vision::BoardPoints target;
  RigAndTarget() {
    for (int c = 0; c < 2; ++c) {
      vision::RigCamera cam;
      cam.name = c == 0 ? "left" : "right";
      cam.model = vision::make_camera(vision::CameraKind::kPinholeRadtan, 1280, 960, 1000, 1000,
                                      640, 480, {-0.05, 0.01});
      if (c == 1) {
        cam.camera_T_world.linear() =
            Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitY()).toRotationMatrix();
        cam.camera_T_world.translation() = Eigen::Vector3d(-0.4, 0.01, 0.1);
      }
      rig.push_back(cam);
    }
    for (int i = 0; i < 9; ++i) target[i] = Eigen::Vector3d(0.04 * (i % 3), 0.04 * (i / 3), 0.0);
  }
  // What camera c sees of the target at frame pose q (exact pixels).
  vision::CameraFrame seen(int c, const Eigen::VectorXd& q, int count, double sigma) const {
    vision::CameraFrame f;
    const Eigen::Isometry3d T = PoseAsReadings::pose_of(q);
    for (int i = 0; i < count; ++i) {
      const auto px =
          vision::project(rig[static_cast<std::size_t>(c)].model,
                          rig[static_cast<std::size_t>(c)].camera_T_world * (T * target.at(i)));
      f.corners.push_back({i, *px, sigma});
    }
    return f;
  }
};

Eigen::VectorXd pose_readings(double x, double y) {
  Eigen::VectorXd q(6);
  q << x, y, 1.2, 0.1, -0.2, 0.3;
  return q;
}

TEST(PixelBridge, ObservationsReproduceTheDetectionsAtTheTrueFramePose) {
  const RigAndTarget s;
  std::vector<app::PixelPose> poses;
  for (int k = 0; k < 3; ++k) {
    const auto q = pose_readings(0.05 * k - 0.1, 0.02 * k);
    app::PixelPose p{"pose" + std::to_string(k), q, {s.seen(0, q, 9, 0.0), s.seen(1, q, 9, 0.3)}};
    p.cameras[0].corners.push_back({99, Eigen::Vector2d(10, 10), 0.1});  // not a target corner
    poses.push_back(p);
  }
  const auto pm = app::build_pixel_measurements(s.rig, s.target, poses);
  ASSERT_EQ(pm.cameras.size(), 2u);
  EXPECT_EQ(pm.cameras[1].name, "right");
  EXPECT_TRUE(pm.cameras[1].world_T_camera.isApprox(s.rig[1].camera_T_world.inverse()));
  EXPECT_EQ(pm.unknown_corners, 3u);
  ASSERT_EQ(pm.measurements.poses.size(), 3u);
  EXPECT_EQ(pm.measurements.poses[2].id, "pose2");
  ASSERT_EQ(pm.measurements.poses[0].observations.size(), 18u);
  const auto& first = std::get<calib::PixelObservation>(pm.measurements.poses[0].observations[0]);
  EXPECT_EQ(first.camera, 0);
  EXPECT_TRUE(first.weight.isApprox(Eigen::Matrix2d::Identity() / 0.1));  // the default sigma
  const auto& last = std::get<calib::PixelObservation>(pm.measurements.poses[0].observations[17]);
  EXPECT_EQ(last.camera, 1);
  EXPECT_EQ(last.corner, 8);
  EXPECT_TRUE(last.weight.isApprox(Eigen::Matrix2d::Identity() / 0.3));
  // The identification's residual vanishes at the true frame pose, for both cameras.
  const PoseAsReadings frames;
  const calib::CameraRigPredictor rig(frames, pm.cameras);
  const Eigen::VectorXd x = rig.initial_parameters(Eigen::VectorXd(0));
  for (const auto& pose : pm.measurements.poses) {
    calib::FramePrediction fp;
    std::string why;
    ASSERT_TRUE(rig.predict(x, pose.actuators, 0, false, fp, why));
    for (const auto& obs : pose.observations) {
      Eigen::Vector2d r;
      ASSERT_TRUE(
          rig.pixel_residual(std::get<calib::PixelObservation>(obs), x, fp, r, nullptr, why));
      EXPECT_LT(r.norm(), 1e-9);
    }
  }
  EXPECT_LT(calib::pixel_errors(rig, x, pm.measurements.poses).rms_px, 1e-10);
}

TEST(PixelBridge, CamerasWithTooFewCornersAndEmptyPosesAreLeftOut) {
  const RigAndTarget s;
  const auto q = pose_readings(0.0, 0.0);
  std::vector<app::PixelPose> poses = {
      {"few", q, {s.seen(0, q, 9, 0.1), s.seen(1, q, 3, 0.1)}},  // camera 1: 3 corners
      {"none", q, {vision::CameraFrame{}, s.seen(1, q, 2, 0.1)}}};
  const auto pm = app::build_pixel_measurements(s.rig, s.target, poses);
  ASSERT_EQ(pm.measurements.poses.size(), 1u);
  EXPECT_EQ(pm.measurements.poses[0].observations.size(), 9u);
  ASSERT_EQ(pm.skipped.size(), 1u);
  EXPECT_EQ(pm.skipped[0], "none: no camera saw at least 4 target corners");
  // One frame per rig camera is required.
  poses[0].cameras.pop_back();
  EXPECT_THROW(app::build_pixel_measurements(s.rig, s.target, poses), std::invalid_argument);
}

}  // namespace
