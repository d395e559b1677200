// `robocal plan --suggest-cameras` in-process: a pair by default; with --max-cameras, an array of
// pairs on a robot whose range one pair cannot see (the Gantry-Tau), each camera looking at its
// own station's point and the operator told to ask for two cameras per pose; a count below a
// pair is refused by the command line.
#include "run_robocal.hpp"

#include "robocal/core/files.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <Eigen/Core>

#include <cstdio>
#include <filesystem>
#include <set>
#include <string>
#include <tuple>

namespace {
namespace fs = std::filesystem;

using robocal::test::CliRun;
constexpr auto& run = robocal::test::run_robocal_captured;

// A fresh folder `name` in the temp dir holding cell.yaml with `yaml`.
fs::path cell_folder(const std::string& name, const std::string& yaml) {
  const fs::path dir = fs::temp_directory_path() / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  robocal::core::write_file_atomic(dir / "cell.yaml", yaml);
  return dir;
}

// A Gantry-Tau cell: one camera (whose model the suggestion uses), the board under the
// platform's box, facing down.
fs::path gantry_cell() {
  const std::string data = ROBOCAL_TESTDATA_DIR;
  return cell_folder(
      "robocal_plan_cli",
      "cameras:\n  - {name: a, file: " + data +
          "/cells/camera_1600x1200.yaml, pose: {position: [1.5, -0.5, -2], look_at: [1.5, "
          "-0.5, 0]}}\ntarget: {file: " +
          data + "/vision/apriltag_4x3.yaml, position: [0, 0, -0.06]}\n" +
          "visibility: {min_image_size: 150}\n");
}

nlohmann::json suggestion(const fs::path& dir, const std::string& max_cameras) {
  std::vector<std::string> args = {"plan",
                                   "--cell",
                                   (dir / "cell.yaml").string(),
                                   "--robot",
                                   "gantry_tau",
                                   "--suggest-cameras",
                                   "--count",
                                   "5",
                                   "--no-order",
                                   "--out",
                                   (dir / "plan.yaml").string(),
                                   "--json"};
  if (!max_cameras.empty()) {
    args.emplace_back("--max-cameras");
    args.push_back(max_cameras);
  }
  const CliRun r = run(args);
  // The cell's own camera sees no feasible pose: no plan (exit 1), the suggestion all the same.
  EXPECT_EQ(r.code, 1) << r.err;
  return nlohmann::json::parse(r.out).at("camera_suggestion");
}

TEST(PlanCli, SuggestsAPairOrWithMaxCamerasAnArrayOfPairs) {
  const fs::path dir = gantry_cell();
  const auto pair = suggestion(dir, "");
  EXPECT_EQ(pair.at("cameras").size(), 2u);
  EXPECT_EQ(pair.at("min_cameras"), 0);

  const auto array = suggestion(dir, "6");
  const auto& cams = array.at("cameras");
  ASSERT_GE(cams.size(), 4u) << array.at("summary");
  ASSERT_EQ(cams.size() % 2, 0u);
  EXPECT_EQ(array.at("min_cameras"), 2);
  EXPECT_GT(array.at("coverage").get<double>(), pair.at("coverage").get<double>());
  // Each pair looks at its own point: as many distinct look-at points as pairs, shared within
  // a pair.
  std::set<std::tuple<double, double, double>> points;
  for (std::size_t i = 0; i < cams.size(); ++i) {
    const auto& at = cams[i].at("look_at");
    points.emplace(at[0].get<double>(), at[1].get<double>(), at[2].get<double>());
    if (i % 2 == 1) {
      EXPECT_EQ(cams[i].at("look_at"), cams[i - 1].at("look_at")) << i;
    }
  }
  EXPECT_EQ(points.size(), cams.size() / 2);
}

TEST(PlanCli, FewerThanAPairIsRefused) {
  const fs::path dir = gantry_cell();
  const CliRun r = run(
      {"plan", "--cell", (dir / "cell.yaml").string(), "--suggest-cameras", "--max-cameras", "1"});
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("--max-cameras"), std::string::npos) << r.err;
}

}  // namespace

namespace {

// `robocal plan` for the wire robot's branch (four actuators, its platform's pitch and yaw turn
// the board): the candidates are turned towards the cameras, as the demos plan them. Sampled in
// joint space, 31 of this cell's 600 candidates are feasible (most turned away from the pair);
// turned, 210.
TEST(PlanCli, AWireRobotsBoardIsTurnedTowardsTheCameras) {
  const std::string data = ROBOCAL_TESTDATA_DIR;
  const fs::path dir = cell_folder(
      "robocal_plan_cli_wire",
      "cameras:\n"
      "  - {name: a, file: " +
          data +
          "/cells/camera_1600x1200.yaml, pose: {position: [2.6, -0.4, 0.6], look_at: [0.9, 0, "
          "0]}}\n"
          "  - {name: b, file: " +
          data +
          "/cells/camera_1600x1200.yaml, pose: {position: [2.6, 0.4, 0.6], look_at: [0.9, 0, "
          "0]}}\n"
          "target: {file: " +
          data +
          "/vision/apriltag_4x3.yaml, position: [0, 0, 0.02], rpy: [0, pi/2, 0]}\n"
          "visibility: {min_image_size: 60}\n");
  const CliRun r = run({"plan", "--cell", (dir / "cell.yaml").string(), "--robot",
                        "wire_robot_branch", "--count", "20", "--pool", "600", "--no-order",
                        "--out", (dir / "plan.yaml").string(), "--json"});
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("poses").get<int>(), 20);
  // "of 600 candidates N are feasible; ..."
  const std::string feasibility = j.at("feasibility").get<std::string>();
  int feasible = -1;
  ASSERT_EQ(std::sscanf(feasibility.c_str(), "of 600 candidates %d are feasible", &feasible), 1)
      << feasibility;
  EXPECT_GE(feasible, 100) << feasibility;
  EXPECT_TRUE(fs::exists(dir / "plan.yaml"));
  fs::remove_all(dir);
}

}  // namespace
