#include "robocal/calib/measurements_file.hpp"

#include "measurements_text.hpp"
#include "planar_fixture.hpp"

#include <fmt/core.h>
#include <gtest/gtest.h>

namespace {

using namespace robocal::calib;
using namespace robocal::calib::testing;

TEST(MeasurementsFile, RoundTripKeepsEveryObservationExactly) {
  PlanarPredictor model;
  std::mt19937 rng(1);
  MeasurementsFile f;
  f.robot = "planar";
  SimulationOptions sim;
  f.measurements = simulate_measurements(model, planar_truth(), planar_actuators(3, 1), sim, rng);
  sim.kind = SimulatedObservation::kPose;
  auto poses = simulate_measurements(model, planar_truth(), planar_actuators(2, 2), sim, rng);
  for (auto& p : poses.poses) {
    p.id += "b";
    f.measurements.poses.push_back(p);
  }
  sim.kind = SimulatedObservation::kProbeHeight;
  auto probes = simulate_measurements(model, planar_truth(), planar_actuators(2, 3), sim, rng);
  for (auto& p : probes.poses) {
    p.id += "c";
    f.measurements.poses.push_back(p);
  }
  f.measurements.distances.push_back(
      {"p0000", "p0001", {.measured_distance = 0.25, .sigma = 2e-6}});
  const auto back = parse_measurements_yaml(measurements_to_yaml(f), "rt.yaml");
  EXPECT_EQ(back.robot, "planar");
  ASSERT_EQ(back.measurements.poses.size(), f.measurements.poses.size());
  for (std::size_t k = 0; k < back.measurements.poses.size(); ++k) {
    const auto& a = f.measurements.poses[k];
    const auto& b = back.measurements.poses[k];
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.actuators, b.actuators);
    ASSERT_EQ(b.observations.size(), 1u);
    // Same residual at an arbitrary pose = same observation.
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() << 0.3, 0.2, 0.1;
    std::visit(
        [&](const auto& oa) {
          using O = std::decay_t<decltype(oa)>;
          if constexpr (!std::is_same_v<O, PixelObservation>) {  // pixels need a camera rig
            const auto& ob = std::get<O>(b.observations[0]);
            Eigen::Matrix<double, O::kResiduals, 1> ra;
            Eigen::Matrix<double, O::kResiduals, 1> rb;
            residual_and_twist_jacobian(oa, T, ra);
            residual_and_twist_jacobian(ob, T, rb);
            EXPECT_LT((ra - rb).norm(), 1e-6 * std::max(1.0, ra.norm())) << a.id;
          }
        },
        a.observations[0]);
  }
  ASSERT_EQ(back.measurements.distances.size(), 1u);
  EXPECT_EQ(back.measurements.distances[0].observation.measured_distance, 0.25);
}

TEST(MeasurementsFile, MillimetresAndDegreesAreConverted) {
  const auto f = parse_measurements_yaml(R"(
units: {length: mm, angle: deg}
noise: {position_sigma: 0.02, rotation_sigma: 0.01}
poses:
  - id: a
    actuators: [1, 2]
    point: [100, 200, -950]
  - id: b
    actuators: [1, 3]
    pose: {position: [1, 2, 3], rotation_vector: [0, 0, 90]}
)",
                                         "m.yaml");
  const auto& pt = std::get<PointObservation>(f.measurements.poses[0].observations[0]);
  EXPECT_NEAR((pt.measured - Eigen::Vector3d(0.1, 0.2, -0.95)).norm(), 0.0, 1e-15);
  EXPECT_NEAR(pt.weight(0, 0), 1.0 / 20e-6, 1e-6);
  const auto& po = std::get<PoseObservation>(f.measurements.poses[1].observations[0]);
  EXPECT_NEAR(Eigen::AngleAxisd(po.measured_rotation).angle(), M_PI / 2, 1e-12);
}

// Euler angles as robot controllers and URDF give them: roll, pitch, yaw about the fixed x, y, z
// axes, here in degrees. Closed form: R = Rz(yaw) Ry(pitch) Rx(roll), each elementary rotation
// written out.
TEST(MeasurementsFile, RollPitchYawInDegreesIsTheFixedAxisRotation) {
  const auto f = parse_measurements_yaml(R"(
units: {length: m, angle: deg}
noise: {position_sigma: 0.00002, rotation_sigma: 0.01}
poses:
  - id: a
    actuators: [1, 2]
    pose: {position: [0.41, -0.02, 0.33], rpy: [30, -20, 110]}
)",
                                         "m.yaml");
  const auto& po = std::get<PoseObservation>(f.measurements.poses[0].observations[0]);
  const double r = 30 * M_PI / 180;
  const double p = -20 * M_PI / 180;
  const double y = 110 * M_PI / 180;
  Eigen::Matrix3d Rx;
  Rx << 1, 0, 0, 0, std::cos(r), -std::sin(r), 0, std::sin(r), std::cos(r);
  Eigen::Matrix3d Ry;
  Ry << std::cos(p), 0, std::sin(p), 0, 1, 0, -std::sin(p), 0, std::cos(p);
  Eigen::Matrix3d Rz;
  Rz << std::cos(y), -std::sin(y), 0, std::sin(y), std::cos(y), 0, 0, 0, 1;
  EXPECT_LT((po.measured_rotation - Rz * Ry * Rx).cwiseAbs().maxCoeff(), 1e-15);
  // Two orientations for one pose are refused.
  EXPECT_THROW(parse_measurements_yaml(R"(
poses:
  - id: a
    actuators: [1, 2]
    pose: {position: [0, 0, 0], rpy: [0, 0, 0], rotation_vector: [0, 0, 0], position_sigma: 1e-5, rotation_sigma: 1e-4}
)",
                                       "m.yaml"),
               MeasurementsFileError);
}

TEST(MeasurementsFile, ErrorsNameFileLineAndItem) {
  EXPECT_NE(measurements_error("poses:\n  - id: a\n    actuators: [1, x2]\n    point: [0, 0, 0]\n")
                .find("m.yaml:3"),
            std::string::npos);
  const std::string mismatch = measurements_error(
      "noise: {position_sigma: 1e-5}\nposes:\n  - id: a\n    actuators: [1, 2]\n    point: [0, 0, "
      "0]\n"
      "  - id: b\n    actuators: [1, 2, 3]\n    point: [0, 0, 0]\n");
  EXPECT_NE(mismatch.find("m.yaml:7"), std::string::npos) << mismatch;
  EXPECT_NE(mismatch.find("pose 'b' has 3 actuator readings"), std::string::npos) << mismatch;
  EXPECT_NE(measurements_error("poses:\n  - id: a\n    actuators: [1]\n").find("no observation"),
            std::string::npos);
  EXPECT_NE(measurements_error("poses:\n  - id: a\n    actuators: [1]\n    point: [0, 0, 0]\n")
                .find("point_sigma"),
            std::string::npos);
  EXPECT_NE(measurements_error("poses: []\ncolour: red\n").find("unknown key 'colour'"),
            std::string::npos);
  EXPECT_NE(measurements_error("poses: [\n").find("not valid YAML"), std::string::npos);
}

TEST(MeasurementsFile, NanReadingIsLoadedThenExcludedByIdentification) {
  std::string text = "noise: {position_sigma: 1e-6}\nposes:\n";
  PlanarPredictor model;
  Eigen::VectorXd truth = planar_truth();
  const auto qs = planar_actuators(12, 4);
  for (std::size_t k = 0; k < qs.size(); ++k) {
    FramePrediction pred;
    std::string why;
    model.predict(truth, qs[k], 0, false, pred, why);
    const Eigen::Vector3d p = pred.pose.translation();
    text += fmt::format(
        "  - id: q{}\n    actuators: [{}, {:.17g}]\n    point: [{:.17g}, {:.17g}, {:.17g}]\n", k,
        k == 3 ? std::string("nan") : fmt::format("{:.17g}", qs[k](0)), qs[k](1), p.x(), p.y(),
        p.z());
  }
  const auto f = parse_measurements_yaml(text, "m.yaml");
  SolveOptions opt;
  opt.preference = {1, 1, 1, 1, 0, 0, 0, 0, 2, 2};
  const auto res = identify(model, planar_nominal(), f.measurements, opt);
  ASSERT_EQ(res.excluded.size(), 1u);
  EXPECT_EQ(res.excluded[0].id, "q3");
  EXPECT_EQ(res.status, IdentificationStatus::kConverged) << res.message;
}

}  // namespace
