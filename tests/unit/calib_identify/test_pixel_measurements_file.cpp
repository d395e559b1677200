// Measurements files with cameras and pixel observations: exact round trip (the identification
// from the re-read file is the same) and file:line errors for every kind of bad camera or pixel.
#include "robocal/calib/measurements_file.hpp"

#include "measurements_text.hpp"
#include "pixel_fixture.hpp"

#include <gtest/gtest.h>

namespace {

using namespace robocal::calib;
using namespace robocal::calib::testing;

const char* kHeader = R"(robot: planar
units: {length: mm, angle: deg}
noise: {pixel_sigma: 0.2}
cameras:
  - name: left
    model: pinhole_radtan
    size: [1280, 960]
    params: [800, 800, 639.5, 479.5, 0, 0, 0, 0, 0]
    position: [0, 0, 0]
    rotation_vector: [0, 0, 0]
  - name: right
    model: fisheye_kb4
    size: [1280, 960]
    params: [600, 600, 640, 480, 0, 0, 0, 0]
    position: [500, 0, 0]
    rotation_vector: [0, 0, 10]
target:
  - {id: 0, point: [0, 0, 0]}
  - {id: 1, point: [50, 0, 0]}
poses:
  - id: a
    actuators: [0.1, 0.2]
)";

TEST(PixelMeasurementsFile, ParsesCamerasTargetAndPixelsInTheFileUnits) {
  const auto f = parse_measurements_yaml(std::string(kHeader) + R"(    pixels:
      - {camera: left, corner: 1, pixel: [700.5, 480.25]}
      - {camera: right, point: [10, 20, 30], pixel: [600, 400], covariance: [0.04, 0.01, 0.01, 0.09]}
)",
                                         "m.yaml");
  ASSERT_EQ(f.cameras.size(), 2u);
  EXPECT_EQ(f.cameras[1].name, "right");
  EXPECT_EQ(f.cameras[1].model.kind, robocal::vision::CameraKind::kFisheyeKB4);
  EXPECT_NEAR(f.cameras[1].world_T_camera.translation().x(), 0.5, 1e-15);
  EXPECT_NEAR(Eigen::AngleAxisd(f.cameras[1].world_T_camera.linear()).angle(), 10 * M_PI / 180,
              1e-12);
  const auto& obs = f.measurements.poses[0].observations;
  ASSERT_EQ(obs.size(), 2u);
  const auto& a = std::get<PixelObservation>(obs[0]);
  EXPECT_EQ(a.camera, 0);
  EXPECT_EQ(a.corner, 1);
  EXPECT_TRUE(a.point.isApprox(Eigen::Vector3d(0.05, 0, 0)));
  EXPECT_TRUE(a.weight.isApprox(Eigen::Matrix2d::Identity() / 0.2));
  const auto& b = std::get<PixelObservation>(obs[1]);
  EXPECT_EQ(b.camera, 1);
  EXPECT_TRUE(b.point.isApprox(Eigen::Vector3d(0.01, 0.02, 0.03)));
  const Eigen::Matrix2d cov = (b.weight.transpose() * b.weight).inverse();
  EXPECT_NEAR(cov(0, 1), 0.01, 1e-15);
  EXPECT_NEAR(cov(1, 1), 0.09, 1e-15);
}

TEST(PixelMeasurementsFile, RoundTripGivesTheSameIdentification) {
  PlanarPredictor planar;
  const CameraRigPredictor rig(planar, planar_start_cameras());
  Eigen::VectorXd truth = rig.initial_parameters(planar_truth());
  rig.set_camera(truth, 1, planar_true_cameras()[1].world_T_camera);
  std::mt19937 rng(3);
  PixelSimulationOptions sim;
  MeasurementsFile f;
  f.cameras = planar_start_cameras();
  f.measurements =
      simulate_pixel_measurements(rig, truth, planar_actuators(12, 3), planar_target(), sim, rng);
  // A corner with its own covariance and one without an id (point written inline).
  auto& first = std::get<PixelObservation>(f.measurements.poses[0].observations[0]);
  first.weight = sqrt_information((Eigen::Matrix2d() << 0.04, 0.01, 0.01, 0.09).finished());
  std::get<PixelObservation>(f.measurements.poses[0].observations[1]).corner = -1;
  const std::string text = measurements_to_yaml(f);
  const auto back = parse_measurements_yaml(text, "rt.yaml");
  ASSERT_EQ(back.cameras.size(), 2u);
  for (std::size_t c = 0; c < 2; ++c) {
    EXPECT_EQ(back.cameras[c].model.params, f.cameras[c].model.params);
    EXPECT_TRUE(back.cameras[c].world_T_camera.isApprox(f.cameras[c].world_T_camera, 1e-15));
  }
  ASSERT_EQ(back.measurements.poses.size(), f.measurements.poses.size());
  for (std::size_t k = 0; k < back.measurements.poses.size(); ++k) {
    const auto& a = f.measurements.poses[k].observations;
    const auto& b = back.measurements.poses[k].observations;
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      const auto& pa = std::get<PixelObservation>(a[i]);
      const auto& pb = std::get<PixelObservation>(b[i]);
      EXPECT_EQ(pa.camera, pb.camera);
      EXPECT_EQ(pa.corner, pb.corner);
      EXPECT_EQ(pa.point, pb.point);
      EXPECT_EQ(pa.measured, pb.measured);
      EXPECT_TRUE(pa.weight.isApprox(pb.weight, 1e-14));
    }
  }
  const CameraRigPredictor rig_back(planar, back.cameras);
  const Eigen::VectorXd start = rig.initial_parameters(planar_nominal());
  const auto r1 = identify(rig, start, f.measurements, rig.solve_options({}));
  const auto r2 = identify(rig_back, start, back.measurements, rig_back.solve_options({}));
  ASSERT_EQ(r1.status, IdentificationStatus::kConverged) << r1.message;
  EXPECT_LT((r1.estimate - r2.estimate).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(PixelMeasurementsFile, BadCamerasAndPixelsNameFileAndLine) {
  const std::string h = kHeader;
  auto with_pixels = [&](const std::string& px) { return h + "    pixels:\n" + px; };
  EXPECT_EQ(measurements_error(with_pixels("      - {camera: middle, corner: 0, pixel: [1, 2]}\n")),
            "m.yaml:24: pose 'a': unknown camera 'middle'");
  EXPECT_EQ(measurements_error(with_pixels("      - {camera: left, corner: 7, pixel: [1, 2]}\n")),
            "m.yaml:24: pose 'a': corner 7 has no 'point' and is not in 'target'");
  EXPECT_EQ(measurements_error(with_pixels("      - {camera: left, corner: 0, pixel: [1]}\n")),
            "m.yaml:24: pixel [u, v] must have 2 numbers (has 1)");
  EXPECT_EQ(measurements_error(with_pixels(
                "      - {camera: left, corner: 0, pixel: [1, 2], covariance: [1, 2, 2, 1]}\n")),
            "m.yaml:24: pose 'a': pixel covariance must be positive definite");
  EXPECT_EQ(measurements_error(
                with_pixels("      - {camera: left, corner: 0, pixel: [1, 2], sigma: 0}\n")),
            "m.yaml:24: pixel sigma must be > 0");
  // Camera definitions.
  auto replaced = [&](const std::string& from, const std::string& to) {
    std::string t = with_pixels("      - {camera: left, corner: 0, pixel: [1, 2]}\n");
    t.replace(t.find(from), from.size(), to);
    return measurements_error(t);
  };
  EXPECT_EQ(replaced("model: fisheye_kb4", "model: orthographic"),
            "m.yaml:12: camera 'right': unknown model 'orthographic' (pinhole_radtan, "
            "pinhole_rational, fisheye_kb4)");
  EXPECT_EQ(replaced("params: [600, 600, 640, 480, 0, 0, 0, 0]", "params: [600, 600, 640, 480]"),
            "m.yaml:14: camera 'right' params must have 8 numbers (has 4)");
  EXPECT_EQ(replaced("params: [600, 600,", "params: [-600, 600,"),
            "m.yaml:11: camera 'right': focal lengths fx, fy must be positive");
  EXPECT_EQ(replaced("name: right", "name: left"),
            "m.yaml:11: camera 'left' appears more than once");
  EXPECT_EQ(replaced("    rotation_vector: [0, 0, 10]\n", ""),
            "m.yaml:11: camera 'right' needs rotation_vector or quaternion");
  // Pixels without cameras.
  const std::string no_cams =
      "poses:\n  - id: a\n    actuators: [0, 0]\n    pixels:\n"
      "      - {camera: left, point: [0, 0, 0], pixel: [1, 2], sigma: 1}\n";
  EXPECT_EQ(measurements_error(no_cams),
            "m.yaml:5: pose 'a' has pixels but the file lists no cameras");
}

TEST(PixelMeasurementsFile, NanPixelsAreKeptForTheIdentificationToExclude) {
  const auto f = parse_measurements_yaml(
      std::string(kHeader) + "    pixels:\n      - {camera: left, corner: 0, pixel: [nan, 2]}\n",
      "m.yaml");
  EXPECT_TRUE(
      std::isnan(std::get<PixelObservation>(f.measurements.poses[0].observations[0]).measured.x()));
}

}  // namespace
