// End to end: `robocal demo` on rendered images must calibrate the simulated Delta far better
// than the nominal model, against the hidden truth (by default with unmodelled error: the
// parameters the model holds fixed are off too, and the robot sags elastically). Each bound is
// 1.25x the largest figure of seeds 1-3 in the test's configuration (stated beside it): the
// small configuration (12 calibration views per camera leave camera 0's frame uncertain, 24
// poses) and the default demo (poses and cameras chosen by the planner).
#include "cli/command_registry.hpp"
#include "run_robocal.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

using robocal::test::run_robocal;

TEST(DemoEndToEnd, QuickDeltaCalibratesFromRenderedImages) {
  const auto dir = std::filesystem::temp_directory_path() / "robocal_e2e_demo";
  std::filesystem::remove_all(dir);
  ASSERT_EQ(run_robocal({"demo", "--quick", "--poses", "24", "--held-out", "200", "--seed", "3",
                         "--out", dir.string()}),
            0);
  std::ifstream in(dir / "results" / "demo.json");
  ASSERT_TRUE(in) << "no demo.json";
  const auto report = nlohmann::json::parse(in);
  const double nominal = report["validate"]["nominal"]["rms_m"];
  const double calibrated = report["validate"]["calibrated"]["rms_m"];
  EXPECT_GE(report["validate"]["held_out_poses"].get<int>(), 150);
  EXPECT_GT(nominal, 5e-4) << "the perturbed robot should be millimetres off nominally";
  // 1.25x the largest of seeds 1-3 in this configuration (`robocal demo --quick --poses 24
  // --held-out 200 --seed S`: 39.9 / 32.0 / 37.6 µm).
  EXPECT_LT(calibrated, 1.25 * 39.9e-6) << "calibrated error against truth";
  EXPECT_LT(calibrated, nominal / 10.0);
  // The worst held-out configurations, worst first; the first is the pose route's max unless the
  // pixel route is worse there.
  const auto& worst = report["validate"]["worst_held_out"];
  ASSERT_EQ(worst.size(), 5u);
  auto worst_error = [](const nlohmann::json& w) {
    return std::max(w["calibrated_error_m"].get<double>(),
                    w.value("calibrated_pixels_error_m", 0.0));
  };
  for (std::size_t k = 1; k < worst.size(); ++k)
    EXPECT_GE(worst_error(worst[k - 1]), worst_error(worst[k]));
  EXPECT_GE(worst_error(worst[0]), report["validate"]["calibrated"]["max_m"].get<double>());
  EXPECT_GT(worst[0]["task_conditioning"].get<double>(), 0.0);
  // Inside / outside the measured region: the parts add up to the all-configurations figures,
  // and each worst configuration says where it lies.
  const auto& v = report["validate"];
  // Held-out truth is compared in camera 0's frame as calibrated (the transform that carries the
  // measured poses' truth onto them): in it the measured positions lie closer to the truth, and
  // the figure against the true frame is kept beside the headline.
  ASSERT_TRUE(v.contains("camera_frame"));
  EXPECT_LE(v["camera_frame"]["measured_poses_vs_truth_in_it"]["rms_m"].get<double>(),
            v["measured_poses_vs_truth"]["rms_m"].get<double>());
  EXPECT_GT(v["camera_frame"]["held_out_in_true_frame"]["calibrated"]["rms_m"].get<double>(), 0.0);
  ASSERT_TRUE(v.contains("measured_region"));
  EXPECT_EQ(v["measured_region"]["measured_poses"].get<int>(), 24);
  const auto& inside = v["held_out_by_region"]["inside"];
  const auto& outside = v["held_out_by_region"]["outside"];
  const int n_in = inside["held_out_poses"], n_out = outside["held_out_poses"];
  EXPECT_EQ(n_in + n_out, v["held_out_poses"].get<int>());
  for (const char* route : {"nominal", "calibrated", "calibrated_pixels", "nominal_registered",
                            "calibrated_registered", "calibrated_pixels_registered"}) {
    if (std::string(route).starts_with("calibrated_pixels") && !v.contains(route)) continue;
    ASSERT_TRUE(inside.contains(route) && outside.contains(route)) << route;
    const double rms_in = inside[route]["rms_m"], rms_out = outside[route]["rms_m"];
    const double rms = v[route]["rms_m"];
    EXPECT_NEAR(n_in * rms_in * rms_in + n_out * rms_out * rms_out, (n_in + n_out) * rms * rms,
                1e-9 * (n_in + n_out) * rms * rms)
        << route;
    EXPECT_DOUBLE_EQ(
        std::max(inside[route]["max_m"].get<double>(), outside[route]["max_m"].get<double>()),
        v[route]["max_m"].get<double>())
        << route;
  }
  for (const auto& w : worst) {
    ASSERT_TRUE(w.contains("inside_measured_region"));
    const double distance = w["outside_measured_region_m"];
    EXPECT_EQ(w["inside_measured_region"].get<bool>(), distance <= 1e-6);
    EXPECT_LE(distance, w["nearest_measured_pose_m"].get<double>() + 1e-12);
    if (n_out > 0) {
      EXPECT_LE(distance, outside["distance_max_m"].get<double>() + 1e-12);
    }
  }
  // Changed parameters: the base frame (the Delta's root body, body1: where the robot stands in
  // camera 0's world) is flagged apart from robot dimensions; stand-ins say how many confounded
  // parameters they carry.
  int base_frame = 0, stand_ins = 0;
  for (const auto& p : v["parameters"]) {
    const bool flagged = p["base_frame"].get<bool>();
    EXPECT_EQ(flagged, p["name"].get<std::string>().starts_with("body1.")) << p["name"];
    base_frame += flagged;
    stand_ins += p["stands_in_for"].get<int>() > 0;
  }
  EXPECT_GT(base_frame, 0);
  EXPECT_GT(stand_ins, 0);
  // The demo went through a session folder: recorded data, results and the hidden truth.
  for (const char* f :
       {"session.yaml", "robot.yaml", "poses/pose_000/pose.yaml", "poses/pose_000/cam0.png",
        "results/measurements.yaml", "results/calibrated_robot.yaml", "truth/truth.json"})
    EXPECT_TRUE(std::filesystem::exists(dir / f)) << f;
  for (const char* stage : {"simulate: cell", "measure: poses", "identify", "validate"})
    EXPECT_TRUE(report["seconds"].contains(stage)) << stage;
  // The cameras were calibrated from rendered views, never given the truth.
  for (const auto& cam : report["validate"]["cameras"])
    EXPECT_LT(cam["projection_vs_truth_px"].get<double>(), 0.2);
}

// The headline: the default demo (seed 1) reaches its documented figures, on every held-out
// configuration drawn from the truth.
TEST(DemoEndToEnd, DefaultDeltaSeed1ReachesItsDocumentedFigure) {
  const auto dir = std::filesystem::temp_directory_path() / "robocal_e2e_demo_default";
  std::filesystem::remove_all(dir);
  ASSERT_EQ(run_robocal({"demo", "--seed", "1", "--out", dir.string()}), 0);
  std::ifstream in(dir / "results" / "demo.json");
  ASSERT_TRUE(in) << "no demo.json";
  const auto report = nlohmann::json::parse(in);
  const auto& v = report["validate"];
  EXPECT_EQ(v["held_out_drawn"].get<int>(), 500) << "every requested configuration drawn";
  EXPECT_LE(v["unanswered"]["calibrated"].get<int>(), 1);
  // 96 intrinsic and 24 rig views (docs/figures.md). Each bound is 1.25 times the largest of
  // seeds 1-3 (`robocal demo --seed S`, camera 0's frame as calibrated, GCC build) and of seed 1
  // on a processor whose libm and OpenCV take other SIMD paths (an AMD EPYC with AVX-512), where
  // identification holds other members of exactly confounded groups (calib/identifiability.hpp,
  // stable_tie_break; the clang build does too: seed 1 22.8 µm from measured poses, 30.6 from
  // pixels): over all held-out poses 31.6 / 29.0 / 16.1 µm (30.6 there) from measured
  // poses, 30.6 / 24.6 / 20.6 µm (40.7 there) from pixels; inside the measured region
  // 9.3 / 7.0 / 6.2 µm (10.4) and 5.9 / 7.1 / 4.9 µm (9.0).
  EXPECT_LT(v["calibrated"]["rms_m"].get<double>(), 1.25 * 31.6e-6);
  EXPECT_LT(v["calibrated_pixels"]["rms_m"].get<double>(), 1.25 * 40.7e-6);
  const auto& inside = v["held_out_by_region"]["inside"];
  EXPECT_LT(inside["calibrated"]["rms_m"].get<double>(), 1.25 * 10.4e-6);
  EXPECT_LT(inside["calibrated_pixels"]["rms_m"].get<double>(), 1.25 * 9.0e-6);
  std::filesystem::remove_all(dir);
}

}  // namespace

namespace {

// A stage that cannot go on ends the demo in one line that names the stage and the reason, with
// exit code 1 and the session folder kept. The modular arm's cell is an array of three camera
// pairs, and two board views cannot link all six cameras: the rig calibration, in measure, says
// which camera saw the board in none of them. (This used the wire robot with --quick, whose pair
// saw its board at no planned pose; its board is now turned towards the cameras and it runs.)
TEST(DemoEndToEnd, AStageThatCannotGoOnIsNamedAndTheFolderKept) {
  const auto dir = std::filesystem::temp_directory_path() / "robocal_e2e_demo_stopped";
  std::filesystem::remove_all(dir);
  const auto r = robocal::test::run_robocal_captured({"demo", "--robot", "modular_arm", "--quick",
                                                      "--rig-views", "2", "--poses", "10", "--out",
                                                      dir.string()});
  EXPECT_EQ(r.code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("demo stopped at measure (failed): rig calibration failed: "),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("sees the board (>= 6 corners) in none of the 2 views"), std::string::npos)
      << r.out;
  // A step that failed commits no results (session/results_transaction.hpp): the reason is in
  // the demo's line, results/ holds nothing of the failed measurement.
  EXPECT_FALSE(std::filesystem::exists(dir / "results" / "measure.json"));
  EXPECT_TRUE(std::filesystem::exists(dir / "session.yaml"));
  std::filesystem::remove_all(dir);
}

}  // namespace
