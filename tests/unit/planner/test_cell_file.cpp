// Cell files: the example cell reads as documented; bad input names file:line and the problem.
#include "robocal/planner/cell.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

namespace robocal::planner {
namespace {

const std::string kCells = std::string(ROBOCAL_TESTDATA_DIR) + "/cells/";

TEST(CellFile, ReadsTheDeltaCell) {
  const Cell cell = load_cell_file(kCells + "delta_two_cameras.yaml");
  ASSERT_EQ(cell.cameras.size(), 2u);
  EXPECT_EQ(cell.cameras[0].name, "left");
  EXPECT_EQ(cell.cameras[0].model.width, 1600);
  // look_at: the optical axis points from the camera at the look-at point.
  const Eigen::Vector3d axis = cell.cameras[0].world_T_camera.linear().col(2);
  const Eigen::Vector3d expected =
      (Eigen::Vector3d(0, 0, -0.9) - Eigen::Vector3d(-0.3, 0, -2.4)).normalized();
  EXPECT_LT((axis - expected).norm(), 1e-12);
  // Image "up" (-y) as close as possible to the given up vector (world +y).
  EXPECT_GT(-cell.cameras[0].world_T_camera.linear().col(1).dot(Eigen::Vector3d::UnitY()), 0.99);
  EXPECT_NEAR(cell.cameras[0].world_T_camera.linear().determinant(), 1.0, 1e-12);
  ASSERT_EQ(cell.obstacles.size(), 1u);
  EXPECT_EQ(cell.obstacles[0].kind, ObstacleKind::kBox);
  EXPECT_NEAR(cell.obstacles[0].size.y(), 0.5, 1e-15);
  EXPECT_TRUE(cell.workspace.declared);
  EXPECT_NEAR(cell.margins.joint_limit_angle, 2 * M_PI / 180, 1e-15);
  EXPECT_NEAR(cell.visibility.max_incidence, M_PI / 3, 1e-15);
  EXPECT_EQ(cell.target.frame, "body30");
  EXPECT_EQ(cell.required_cameras().size(), 2u);
}

// Parses `text` as a cell in testdata/cells and returns the error message ("" if none).
std::string error_of(const std::string& text) {
  try {
    (void)parse_cell_yaml(text, "bad.yaml", kCells);
  } catch (const CellFileError& e) {
    return e.what();
  }
  return "";
}

// Named apart from planner_test_geometry.hpp's kTarget (the Delta's posed target): a source
// compiled in a batch sees the names of the anonymous namespaces of the sources before it.
const char* kTargetWithoutPose = "target: {file: ../vision/apriltag_4x3.yaml}\n";

TEST(CellFile, MissingCameraFileIsNamedWithItsLine) {
  const std::string msg =
      error_of(std::string("cameras:\n  - name: left\n    file: no_such_camera.yaml\n"
                           "    pose: {position: [0, 0, -2], look_at: [0, 0, 0]}\n") +
               kTargetWithoutPose);
  EXPECT_NE(msg.find("bad.yaml:3:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("no_such_camera.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("does not exist"), std::string::npos) << msg;
}

TEST(CellFile, BadInputNamesTheLine) {
  const std::string cam =
      "cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: {position: [0, 0, -2], look_at: "
      "[0, 0, 0]}}\n";
  // Unknown key, with the known ones listed.
  std::string msg = error_of(
      cam + kTargetWithoutPose +
      "obstacles:\n  - {name: x, box: {center: [0, 0, 0], size: [1, 1, 1]}, colour: red}\n");
  EXPECT_NE(msg.find("bad.yaml:5:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("unknown key 'colour'"), std::string::npos) << msg;
  // A negative size.
  msg = error_of(cam + kTargetWithoutPose +
                 "obstacles:\n  - {name: x, box: {center: [0, 0, 0], size: [1, -1, 1]}}\n");
  EXPECT_NE(msg.find("bad.yaml:5:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("must be > 0"), std::string::npos) << msg;
  // Two shapes in one obstacle.
  msg = error_of(cam + kTargetWithoutPose +
                 "obstacles:\n  - {name: x, sphere: {center: [0, 0, 0], radius: 1}, box: {center: "
                 "[0, 0, 0], size: [1, 1, 1]}}\n");
  EXPECT_NE(msg.find("exactly one of"), std::string::npos) << msg;
  // Unknown unit.
  msg = error_of("units: inch\n" + cam + kTargetWithoutPose);
  EXPECT_NE(msg.find("bad.yaml:1:"), std::string::npos) << msg;
  // Degrees given as radians for the joint-limit margin.
  msg = error_of(cam + kTargetWithoutPose + "margins: {joint_limit: 2}\n");
  EXPECT_NE(msg.find("deg(2)"), std::string::npos) << msg;
  // Visibility naming a camera that does not exist.
  msg = error_of(cam + kTargetWithoutPose + "visibility: {cameras: [b]}\n");
  EXPECT_NE(msg.find("'b'"), std::string::npos) << msg;
  // 'unknown' pose without a rough position.
  msg = error_of("cameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: unknown}\n" +
                 std::string(kTargetWithoutPose));
  EXPECT_NE(msg.find("roughly"), std::string::npos) << msg;
  // No target.
  msg = error_of(cam);
  EXPECT_NE(msg.find("'target'"), std::string::npos) << msg;
  // YAML syntax.
  msg = error_of("cameras: [\n");
  EXPECT_NE(msg.find("not valid YAML"), std::string::npos) << msg;
}

TEST(CellFile, MillimetresAreConverted) {
  const Cell cell = parse_cell_yaml(
      "units: mm\ncameras:\n  - {name: a, file: camera_1600x1200.yaml, pose: unknown, roughly: "
      "{position: [0, 0, -2000], look_at: [0, 0, 0], uncertainty: 50}}\n"
      "obstacles:\n  - {name: post, cylinder: {center: [100, 0, -500], radius: 20, length: "
      "300}}\n" +
          std::string(kTargetWithoutPose) +
          "workspace: {min: [-500, -500, -1200], max: [500, 500, -500]}\nmargins: {clearance: "
          "15}\n",
      "mm.yaml", kCells);
  EXPECT_NEAR(cell.cameras[0].world_T_camera.translation().z(), -2.0, 1e-12);
  EXPECT_FALSE(cell.cameras[0].pose_known);
  EXPECT_NEAR(cell.cameras[0].pose_uncertainty, 0.05, 1e-12);
  EXPECT_NEAR(cell.obstacles[0].radius, 0.02, 1e-12);
  EXPECT_NEAR(cell.obstacles[0].length, 0.3, 1e-12);
  EXPECT_NEAR(cell.workspace.min.z(), -1.2, 1e-12);
  EXPECT_NEAR(cell.margins.clearance, 0.015, 1e-12);
}

TEST(CellFile, ReadsAsciiAndBinaryStl) {
  const auto dir = std::filesystem::temp_directory_path() / "planner_stl";
  std::filesystem::create_directories(dir);
  {
    std::ofstream a(dir / "tri.stl");
    a << "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1000 0 0\nvertex 0 1000 "
         "0\nendloop\nendfacet\nendsolid t\n";
  }
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  read_stl((dir / "tri.stl").string(), 1e-3, v, t);
  ASSERT_EQ(t.size(), 1u);
  EXPECT_NEAR(v[1].x(), 1.0, 1e-12);
  {
    std::ofstream b(dir / "bin.stl", std::ios::binary);
    const std::string header(80, ' ');
    b.write(header.data(), 80);
    const std::uint32_t n = 1;
    b.write(reinterpret_cast<const char*>(&n), 4);
    const float rec[12] = {0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 2, 0};
    b.write(reinterpret_cast<const char*>(rec), sizeof rec);
    const std::uint16_t attr = 0;
    b.write(reinterpret_cast<const char*>(&attr), 2);
  }
  read_stl((dir / "bin.stl").string(), 1.0, v, t);
  ASSERT_EQ(t.size(), 1u);
  EXPECT_NEAR(v[2].y(), 2.0, 1e-6);
  EXPECT_THROW(read_stl((dir / "missing.stl").string(), 1.0, v, t), CellFileError);
}

}  // namespace
}  // namespace robocal::planner
