// validation.json's per-pose held-out points (read by the report): read back as written, and a
// malformed row named by file and field. held_out.json (the wizard's held-out poses measured by
// the cameras): its figures computed from its poses, read back, malformed fields named. The
// parameter counts every summary prints, from an identification whose relinearised solve
// estimated a parameter the first analysis held.
#include "session/results_files.hpp"
#include "summary/validation_summary.hpp"

#include "robocal/core/files.hpp"
#include "robocal/core/input_error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

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

// ---- held_out.json

robocal::app::HeldOutRecord two_pose_record() {
  robocal::app::HeldOutRecord r;
  r.every = 4;
  r.fit_poses = 9;
  r.unanswered = {"pose_011"};
  r.poses.push_back({"pose_003", {0.1, 0.2, 1.5}, {3e-4, 0, 0}, {0, 6e-6, 0}});
  r.poses.push_back({"pose_007", {-0.1, 0.0, 1.2}, {0, 0, -4e-4}, {0, 0, 8e-6}});
  return r;
}

ResultsLayout empty_layout(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("robocal_held_out_file_" + name);
  fs::remove_all(dir);
  return ResultsLayout{dir};
}

TEST(HeldOutFile, FiguresFromThePosesAndReadBack) {
  const ResultsLayout results = empty_layout("ok");
  robocal::app::write_held_out(results, two_pose_record());
  const auto back = robocal::app::read_held_out(results, "");
  EXPECT_EQ(back.every, 4);
  EXPECT_EQ(back.fit_poses, 9U);
  EXPECT_EQ(back.unanswered, std::vector<std::string>{"pose_011"});
  ASSERT_EQ(back.poses.size(), 2U);
  EXPECT_EQ(back.poses[1].pose, "pose_007");
  EXPECT_EQ(back.poses[1].measured, Eigen::Vector3d(-0.1, 0.0, 1.2));
  EXPECT_EQ(back.poses[1].nominal_error, Eigen::Vector3d(0, 0, -4e-4));
  EXPECT_EQ(back.poses[1].calibrated_error, Eigen::Vector3d(0, 0, 8e-6));
  // RMS of 6 and 8 µm, of 300 and 400 µm; the worst of each.
  EXPECT_EQ(back.calibrated.poses, 2U);
  EXPECT_NEAR(back.calibrated.rms_m, std::sqrt((36e-12 + 64e-12) / 2), 1e-15);
  EXPECT_NEAR(back.calibrated.max_m, 8e-6, 1e-15);
  EXPECT_NEAR(back.nominal.rms_m, std::sqrt((9e-8 + 16e-8) / 2), 1e-15);
  EXPECT_NEAR(back.nominal.max_m, 4e-4, 1e-15);
}

TEST(HeldOutFile, MalformedFieldIsNamed) {
  const ResultsLayout results = empty_layout("bad");
  robocal::app::write_held_out(results, two_pose_record());
  auto doc = nlohmann::json::parse(std::ifstream(results.held_out()));
  doc["poses"][1]["calibrated_error_m"] = {0.0, 1.0};
  std::ofstream(results.held_out()) << doc.dump();
  try {
    robocal::app::read_held_out(results, "");
    FAIL() << "a two-number error was accepted";
  } catch (const robocal::core::InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("held_out.json"), std::string::npos) << what;
    EXPECT_NE(what.find("poses[1].calibrated_error_m"), std::string::npos) << what;
  }
  // Figures that do not count the listed poses: a hand-edited or truncated file.
  doc["poses"][1]["calibrated_error_m"] = {0.0, 0.0, 1e-6};
  doc["calibrated"]["poses"] = 5;
  std::ofstream(results.held_out()) << doc.dump();
  EXPECT_THROW(robocal::app::read_held_out(results, ""), robocal::core::InputError);
}

TEST(HeldOutFile, MissingFileNamesTheHint) {
  try {
    robocal::app::read_held_out(empty_layout("missing"), "run the wizard's validation step");
    FAIL() << "a missing file was accepted";
  } catch (const robocal::core::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("run the wizard's validation step"), std::string::npos)
        << e.what();
  }
}

// ---- the parameter counts of identification.json

// Six parameters, one fixed in the robot file: the first analysis found 2 identifiable and held
// 3 (one without effect); the relinearised solve then estimated one of the held ones.
nlohmann::json relinearised_identification() {
  nlohmann::json params = nlohmann::json::array();
  for (const auto& [name, label, estimated] :
       {std::tuple{"body1.d1", "base x", true}, std::tuple{"body1.d2", "base y", true},
        std::tuple{"body5.a3", "upper arm twist", true},
        std::tuple{"body6.d1", "elbow offset", false}, std::tuple{"body7.d3", "", false},
        std::tuple{"body8.d1", "ball joint x", false}})
    params.push_back({{"name", name}, {"label", label}, {"estimated", estimated}});
  return {{"status", "ok"},
          {"result",
           {{"parameters", params},
            {"identifiability",
             {{"identifiable", {"body1.d1", "body1.d2"}},
              {"held_at_nominal", {"body5.a3", "body6.d1", "body7.d3"}},
              {"no_effect", {"body7.d3"}},
              {"equations", 60},
              {"underdetermined", false},
              {"redundancies",
               {{{"parameter", "body5.a3"}, {"explanation", "body5.a3 moves like body1.d1"}},
                {{"parameter", "body6.d1"},
                 {"explanation", "body6.d1 moves like body1.d2; body6.d1 is held"}}}},
              {"ill_conditioned", nlohmann::json::array()}}},
            {"relinearisation",
             {{"attempted", true}, {"message", "relinearised: body5.a3 became identifiable"}}}}}};
}

TEST(ParameterAccount, CountsAfterARelinearisedSolve) {
  const auto a = robocal::app::parameter_account(relinearised_identification(), "id.json");
  EXPECT_EQ(a.counts.total, 6U);
  EXPECT_EQ(a.counts.free, 5U);
  EXPECT_EQ(a.counts.identified, 3U);
  EXPECT_EQ(a.counts.held, 2U);  // not the first analysis's 3
  EXPECT_EQ(a.counts.no_effect, 1U);
  EXPECT_EQ(a.counts.fixed(), 1U);
  // The parameter the second solve estimated is no longer explained as held.
  EXPECT_EQ(a.confounded,
            std::vector<std::string>{"body6.d1 moves like body1.d2; body6.d1 is held"});
  EXPECT_EQ(a.labels[4], "body7.d3");  // no label: its name

  const auto words = robocal::app::parameter_words(a);
  EXPECT_NE(words.identified.find("3 of the 5 free parameters were identified"), std::string::npos)
      << words.identified;
  EXPECT_NE(words.identified.find("1 more is fixed in the robot file (6 parameters in all)"),
            std::string::npos)
      << words.identified;
  EXPECT_NE(words.held.find("2 of the 5 free parameters are held at nominal"), std::string::npos)
      << words.held;
  EXPECT_NE(words.held.find("1 has no effect on these measurements, 1 moves them like"),
            std::string::npos)
      << words.held;
  ASSERT_EQ(words.reasons.size(), 2U);  // the one without effect, the confounded one
  EXPECT_EQ(robocal::app::with_labels(words.reasons[0], a),
            "No effect on any measurement with these poses: body7.d3.");
  EXPECT_EQ(robocal::app::with_labels(words.reasons[1], a),
            "elbow offset moves like base y; elbow offset is held");
  ASSERT_EQ(words.notes.size(), 1U);
  EXPECT_EQ(robocal::app::with_labels(words.notes[0], a),
            "relinearised: upper arm twist became identifiable");
}

TEST(ParameterAccount, MissingAnalysisIsNamed) {
  nlohmann::json id = relinearised_identification();
  id["result"].erase("identifiability");
  try {
    robocal::app::parameter_account(id, "results/identification.json");
    FAIL() << "an identification without its analysis was accepted";
  } catch (const robocal::core::InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("results/identification.json"), std::string::npos) << what;
    EXPECT_NE(what.find("identifiability"), std::string::npos) << what;
  }
}

}  // namespace
