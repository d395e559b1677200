// validation.json's per-pose held-out points (read by the report): read back as written, and a
// malformed row named by file and field.
#include "session/results_files.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace {

namespace fs = std::filesystem;
using robocal::app::ResultsLayout;

ResultsLayout layout_with(const std::string& name, const nlohmann::json& validation) {
  const fs::path dir = fs::temp_directory_path() / ("robocal_validation_file_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir / "results");
  const ResultsLayout results{dir};
  robocal::core::write_file_atomic(results.report("validation"), validation.dump());
  return results;
}

TEST(ValidationFile, HeldOutPointsReadBack) {
  const nlohmann::json v = {{"status", "ok"},
                            {"held_out_points",
                             {{"position_m", {{0.1, 0.2, 1.5}, {-0.1, 0.0, 1.2}}},
                              {"nominal_error_m", {{1e-3, 0, 0}, {0, -2e-3, 0}}},
                              {"calibrated_error_m", {{1e-5, 0, 0}, {0, 0, 3e-5}}},
                              {"inside_measured_region", {true, false}}}}};
  const auto file = robocal::app::read_validation(layout_with("ok", v), "");
  EXPECT_EQ(file.status, "ok");
  ASSERT_EQ(file.points.size(), 2U);
  EXPECT_EQ(file.points[1].position, Eigen::Vector3d(-0.1, 0.0, 1.2));
  EXPECT_EQ(file.points[1].nominal_error, Eigen::Vector3d(0, -2e-3, 0));
  EXPECT_EQ(file.points[1].calibrated_error, Eigen::Vector3d(0, 0, 3e-5));
  EXPECT_EQ(file.points[0].inside_measured_region, true);
  EXPECT_EQ(file.points[1].inside_measured_region, false);
}

TEST(ValidationFile, MalformedRowIsNamed) {
  const nlohmann::json v = {{"status", "ok"},
                            {"held_out_points",
                             {{"position_m", {{0.1, 0.2, 1.5}, {0.3, 0.4}}},
                              {"nominal_error_m", {{0, 0, 0}, {0, 0, 0}}},
                              {"calibrated_error_m", {{0, 0, 0}, {0, 0, 0}}}}}};
  try {
    robocal::app::read_validation(layout_with("bad", v), "");
    FAIL() << "a two-number position was accepted";
  } catch (const robocal::core::InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("validation.json"), std::string::npos) << what;
    EXPECT_NE(what.find("held_out_points.position_m[1]"), std::string::npos) << what;
  }
}

TEST(ValidationFile, MissingFileNamesTheHint) {
  const fs::path dir = fs::temp_directory_path() / "robocal_validation_file_missing";
  fs::remove_all(dir);
  try {
    robocal::app::read_validation(ResultsLayout{dir}, "run `robocal validate` first");
    FAIL() << "a missing file was accepted";
  } catch (const robocal::core::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("run `robocal validate` first"), std::string::npos)
        << e.what();
  }
}

}  // namespace
