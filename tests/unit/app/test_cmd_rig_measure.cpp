// `robocal rig` and `robocal measure` end to end on rendered images with known truth, including
// the bad-input cases: a missing camera image, an image whose size does not match the camera
// file, a target seen by no camera, and cameras sharing no views.
#include "cli/command_registry.hpp"
#include "stages/measure_steps.hpp"

#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/renderer.hpp"
#include "robocal/vision/target_io.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

namespace robocal::app {
namespace {

namespace fs = std::filesystem;
namespace rv = robocal::vision;

std::string fmt_view(int i) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "pose_%03d", i);
  return buf;
}

const fs::path kTarget = fs::path(ROBOCAL_TESTDATA_DIR) / "vision" / "apriltag_4x3.yaml";

struct Scene {
  std::vector<rv::CameraModel> cams;
  std::vector<Eigen::Isometry3d> camera_T_world;
  std::vector<rv::CameraRays> rays;
  rv::TargetBoard board;
  rv::RenderOptions options;
  Scene() {
    board = rv::load_target_file(kTarget);
    const auto cam =
        rv::load_camera_file(fs::path(ROBOCAL_TESTDATA_DIR) / "vision" / "camera_640x480.yaml");
    for (int i = 0; i < 2; ++i) {
      cams.push_back(cam);
      camera_T_world.push_back(
          rv::camera_T_board_look_at(Eigen::Vector3d(i == 0 ? -0.075 : 0.075, 0, 0),
                                     Eigen::Vector3d(0, 0, 0.45), Eigen::Vector3d(0, -1, 0)));
      rays.push_back(rv::precompute_rays(cam));
    }
    options.blur_sigma = 0.8;
    options.read_noise = 2.0;
  }
  Eigen::Isometry3d random_pose(std::mt19937_64& rng, double tilt_deg) const {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const Eigen::Vector3d c(0.5 * (board.extent_min + board.extent_max).x(),
                            0.5 * (board.extent_min + board.extent_max).y(), 0);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    // One draw a statement, in the order turn, axis y, axis x, tilt, then z, y, x
    // (robocal/core/random_draws.hpp says why).
    const double turn = 0.3 * u(rng);
    const double axis_y = u(rng);
    const double axis_x = u(rng);
    const double tilt = tilt_deg * M_PI / 180 * u(rng);
    pose.linear() = (Eigen::AngleAxisd(tilt, Eigen::Vector3d(axis_x, axis_y, 0).normalized()) *
                     Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitZ()))
                        .toRotationMatrix();
    const double z = 0.4 + 0.05 * u(rng);
    const double y = 0.03 * u(rng);
    const double x = 0.03 * u(rng);
    pose.translation() = Eigen::Vector3d(x, y, z) - pose.linear() * c;
    return pose;
  }
  void write(const fs::path& dir, const std::string& name, int cam,
             const Eigen::Isometry3d& world_T_board) {
    fs::create_directories(dir);
    options.seed += 1;
    const auto r =
        rv::render(rays[static_cast<size_t>(cam)],
                   {{board, camera_T_world[static_cast<size_t>(cam)] * world_T_board}}, options);
    cv::imwrite((dir / (name + ".png")).string(), r.image);
  }
};

int run(const std::vector<std::string>& args) {
  std::vector<const char*> argv = {"robocal"};
  for (const auto& a : args) argv.push_back(a.c_str());
  return run_cli(static_cast<int>(argv.size()), argv.data());
}

nlohmann::json read_json(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

TEST(RigMeasureCli, CalibratesARigAndMeasuresPosesWithPerPoseStatus) {
  const fs::path root = fs::current_path() / "rig_cli_data";
  fs::remove_all(root);
  fs::create_directories(root);
  Scene scene;
  std::mt19937_64 rng(3);
  const char* names[2] = {"left", "right"};
  for (int i = 0; i < 2; ++i)
    rv::save_camera_file(scene.cams[static_cast<size_t>(i)],
                         root / (std::string(names[i]) + ".yaml"), names[i]);
  for (int v = 0; v < 12; ++v) {
    const auto pose = scene.random_pose(rng, 35.0);
    for (int c = 0; c < 2; ++c) scene.write(root / "views" / fmt_view(v), names[c], c, pose);
  }
  ASSERT_EQ(run({"rig", "--camera", "left=" + (root / "left.yaml").string(), "--camera",
                 "right=" + (root / "right.yaml").string(), "--target", kTarget.string(), "--views",
                 (root / "views").string(), "--out", (root / "rig.json").string()}),
            0);
  const auto rig = read_json(root / "rig.json");
  ASSERT_TRUE(rig["ok"].get<bool>()) << rig.dump(2);
  const double baseline = rig["cameras"][1]["baseline_m"].get<double>();
  const double sigma = rig["cameras"][1]["baseline_sigma_m"].get<double>();
  EXPECT_GT(sigma, 0.0);
  EXPECT_LT(std::abs(baseline - 0.15), std::max(5.0 * sigma, 1e-4)) << baseline << " +- " << sigma;
  EXPECT_LT(rig["rms_px"].get<double>(), 0.2);
  EXPECT_TRUE(rig["opencv_stereoCalibrate"][0]["ok"].get<bool>());

  // Poses: two good ones (one with two frames), a missing right image, a right image of the
  // wrong size, and the target out of every camera's view.
  std::vector<Eigen::Isometry3d> truth;
  for (int p = 0; p < 2; ++p) {
    truth.push_back(scene.random_pose(rng, 30.0));
    for (int c = 0; c < 2; ++c)
      scene.write(root / "poses" / fmt_view(p), names[c], c, truth.back());
  }
  scene.write(root / "poses" / "pose_001", "left_1", 0, truth[1]);
  scene.write(root / "poses" / "pose_001", "right_1", 1, truth[1]);
  scene.write(root / "poses" / "pose_002", "left", 0, scene.random_pose(rng, 20.0));
  const auto p3 = scene.random_pose(rng, 20.0);
  scene.write(root / "poses" / "pose_003", "left", 0, p3);
  {
    scene.write(root / "poses" / "pose_003", "right", 1, p3);
    cv::Mat img =
        cv::imread((root / "poses" / "pose_003" / "right.png").string(), cv::IMREAD_GRAYSCALE);
    cv::Mat small;
    cv::resize(img, small, cv::Size(320, 240));
    cv::imwrite((root / "poses" / "pose_003" / "right.png").string(), small);
  }
  Eigen::Isometry3d away = scene.random_pose(rng, 0.0);
  away.translation().x() += 2.0;
  for (int c = 0; c < 2; ++c) scene.write(root / "poses" / "pose_004", names[c], c, away);

  ASSERT_EQ(run({"measure", "--rig", (root / "rig.json").string(), "--target", kTarget.string(),
                 "--poses", (root / "poses").string(), "--out", (root / "m.json").string()}),
            0);
  const auto m = read_json(root / "m.json");
  ASSERT_EQ(m["poses"].size(), 5u);
  const auto& poses = m["poses"];
  for (int p = 0; p < 2; ++p) {
    EXPECT_EQ(poses[p]["status"], "ok") << poses[p].dump(1);
    const auto r = poses[p]["rig_T_target"]["rvec"];
    const auto t = poses[p]["rig_T_target"]["tvec"];
    const Eigen::Isometry3d est = rv::pose_from_rvec_tvec(Eigen::Vector3d(r[0], r[1], r[2]),
                                                          Eigen::Vector3d(t[0], t[1], t[2]));
    const Eigen::Isometry3d expected = scene.camera_T_world[0] * truth[static_cast<size_t>(p)];
    EXPECT_LT(rv::translation_between(est, expected), 2e-4);
    EXPECT_EQ(poses[p]["covariance"].size(), 6u);
    EXPECT_FALSE(poses[p]["observations"].empty());
  }
  EXPECT_EQ(poses[1]["frames"], 2);
  // Missing right image: measured with the left camera alone, and said so.
  EXPECT_EQ(poses[2]["status"], "ok");
  EXPECT_NE(poses[2]["problems"].dump().find("no image for camera 'right'"), std::string::npos);
  // Wrong image size: that image is not used, the problem is named.
  EXPECT_EQ(poses[3]["status"], "ok");
  EXPECT_NE(poses[3]["problems"].dump().find("calibrated for 640x480"), std::string::npos)
      << poses[3]["problems"].dump();
  // Out of view: per-pose status, the rest proceeded.
  EXPECT_EQ(poses[4]["status"], "not_seen");
  EXPECT_GE(m["summary"]["usable"].get<int>(), 2);

  // Cameras sharing no views: the rig command fails naming the camera.
  fs::remove_all(root / "views_disjoint");
  for (int v = 0; v < 4; ++v) {
    const auto pose = scene.random_pose(rng, 30.0);
    scene.write(root / "views_disjoint" / fmt_view(v), names[v % 2], v % 2, pose);
  }
  EXPECT_EQ(run({"rig", "--camera", "left=" + (root / "left.yaml").string(), "--camera",
                 "right=" + (root / "right.yaml").string(), "--target", kTarget.string(), "--views",
                 (root / "views_disjoint").string(), "--out", (root / "rig_bad.json").string()}),
            1);
  const auto bad = read_json(root / "rig_bad.json");
  EXPECT_NE(bad["message"].get<std::string>().find("camera 1 'right' shares no views"),
            std::string::npos)
      << bad["message"];
}

// `measure --rig` refuses what a session's measure refuses, with the same words: one
// camera whose every image is of another size (nothing written, exit 3), a rig file whose camera
// names are swapped (every fit 1e6x the corner noise: exit 1, nothing usable), and one camera's
// images swapped between two poses (those two excluded, the rest used).
TEST(RigMeasureCli, FileModeHasTheSessionsPlausibilityGate) {
  const fs::path root = fs::current_path() / "rig_cli_gate";
  fs::remove_all(root);
  Scene scene;
  std::mt19937_64 rng(11);
  const char* names[2] = {"left", "right"};
  fs::create_directories(root);
  for (int i = 0; i < 2; ++i)
    rv::save_camera_file(scene.cams[static_cast<size_t>(i)],
                         root / (std::string(names[i]) + ".yaml"), names[i]);
  for (int v = 0; v < 10; ++v) {
    const auto pose = scene.random_pose(rng, 35.0);
    for (int c = 0; c < 2; ++c) scene.write(root / "views" / fmt_view(v), names[c], c, pose);
  }
  ASSERT_EQ(run({"rig", "--camera", "left=" + (root / "left.yaml").string(), "--camera",
                 "right=" + (root / "right.yaml").string(), "--target", kTarget.string(), "--views",
                 (root / "views").string(), "--out", (root / "rig.json").string()}),
            0);
  constexpr int kPoses = 6;
  for (int p = 0; p < kPoses; ++p) {
    const auto pose = scene.random_pose(rng, 30.0);
    for (int c = 0; c < 2; ++c) scene.write(root / "poses" / fmt_view(p), names[c], c, pose);
  }
  auto measure = [&](const fs::path& rig, const fs::path& poses, const fs::path& out) {
    return run({"measure", "--rig", rig.string(), "--target", kTarget.string(), "--poses",
                poses.string(), "--out", out.string()});
  };
  ASSERT_EQ(measure(root / "rig.json", root / "poses", root / "good.json"), 0);
  EXPECT_TRUE(read_json(root / "good.json")["board_fit_gate"]["plausible"].get<bool>());

  // One camera's images swapped between pose_001 and pose_004.
  fs::copy(root / "poses", root / "swapped", fs::copy_options::recursive);
  fs::rename(root / "swapped" / "pose_001" / "right.png", root / "swapped" / "right.png");
  fs::rename(root / "swapped" / "pose_004" / "right.png",
             root / "swapped" / "pose_001" / "right.png");
  fs::rename(root / "swapped" / "right.png", root / "swapped" / "pose_004" / "right.png");
  ASSERT_EQ(measure(root / "rig.json", root / "swapped", root / "swapped.json"), 0);
  const auto swapped = read_json(root / "swapped.json");
  for (int p = 0; p < kPoses; ++p) {
    const bool foreign = p == 1 || p == 4;
    EXPECT_EQ(swapped["poses"][p]["usable"].get<bool>(), !foreign) << fmt_view(p);
    if (foreign) {
      EXPECT_NE(swapped["poses"][p]["excluded"].get<std::string>().find("images disagree"),
                std::string::npos)
          << swapped["poses"][p].dump(1);
    }
  }

  // The rig file's camera names swapped: every pose is seen "from the wrong side".
  auto rig = read_json(root / "rig.json");
  std::swap(rig["cameras"][0]["name"], rig["cameras"][1]["name"]);
  std::ofstream(root / "rig_swapped.json") << rig.dump(2);
  testing::internal::CaptureStderr();
  EXPECT_EQ(measure(root / "rig_swapped.json", root / "poses", root / "names.json"), 1);
  const std::string refused = testing::internal::GetCapturedStderr();
  const auto names_swapped = read_json(root / "names.json");
  EXPECT_FALSE(names_swapped["board_fit_gate"]["plausible"].get<bool>());
  EXPECT_EQ(names_swapped["summary"]["usable"].get<int>(), 0);
  // The refusal names the rig file and the exchanged names, found by measuring them swapped back.
  const std::string said = (root / "rig_swapped.json").string() +
                           ": the rig file's camera names '" +
                           rig["cameras"][0]["name"].get<std::string>() + "' and '" +
                           rig["cameras"][1]["name"].get<std::string>() + "' look exchanged";
  EXPECT_NE(refused.find(said), std::string::npos) << refused;
  EXPECT_NE(names_swapped["board_fit_gate"]["reason"].get<std::string>().find("look exchanged"),
            std::string::npos);
  // A rig whose fits fail for another reason is not blamed on its names.
  testing::internal::CaptureStderr();
  measure(root / "rig.json", root / "swapped", root / "swapped_again.json");
  EXPECT_EQ(testing::internal::GetCapturedStderr().find("look exchanged"), std::string::npos);

  // Every image of one camera at another resolution: refused, nothing written.
  fs::copy(root / "poses", root / "resized", fs::copy_options::recursive);
  for (int p = 0; p < kPoses; ++p) {
    const fs::path f = root / "resized" / fmt_view(p) / "right.png";
    cv::Mat small;
    cv::resize(cv::imread(f.string(), cv::IMREAD_GRAYSCALE), small, cv::Size(320, 240));
    cv::imwrite(f.string(), small);
  }
  testing::internal::CaptureStderr();
  EXPECT_EQ(measure(root / "rig.json", root / "resized", root / "resized.json"), 3);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("camera 'right' gives no board corners at any of the 6 poses"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("calibrated for 640x480"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(root / "resized.json"));
}

// The cameras' intrinsics solved side by side (calibrate_cameras) are those of one camera at a
// time, bit for bit, and each result belongs to its own camera (their focal lengths differ by 10
// %).
TEST(MeasureSteps, IntrinsicsSolvedSideBySideEqualOneCameraAtATime) {
  Scene scene;
  scene.cams[1].params[0] *= 1.1;
  scene.cams[1].params[1] *= 1.1;
  scene.rays[1] = rv::precompute_rays(scene.cams[1]);
  const fs::path dir = fs::temp_directory_path() / "robocal_unit_intrinsics_side_by_side";
  fs::remove_all(dir);
  std::mt19937_64 rng(5);
  std::vector<CameraViews> cameras;
  for (int c = 0; c < 2; ++c) {
    const std::string name = "cam" + std::to_string(c);
    CameraViews views{name, scene.cams[0].width, scene.cams[0].height, {}};
    for (int i = 0; i < 14; ++i) {
      // World = this camera's frame, so every view faces it.
      scene.write(
          dir / name, fmt_view(i), c,
          scene.camera_T_world[static_cast<size_t>(c)].inverse() * scene.random_pose(rng, 45.0));
      views.files.push_back(dir / name / (fmt_view(i) + ".png"));
    }
    cameras.push_back(views);
  }
  const StepLog quiet{nullptr, 2};
  const std::vector<IntrinsicsStep> both = calibrate_cameras(cameras, scene.board, quiet);
  ASSERT_EQ(both.size(), 2U);
  for (std::size_t c = 0; c < 2; ++c) {
    const IntrinsicsStep one =
        calibrate_camera(cameras[c].camera, cameras[c].width, cameras[c].height, cameras[c].files,
                         scene.board, quiet);
    ASSERT_EQ(one.result.status, rv::CalibrationStatus::kOk) << one.result.reason;
    EXPECT_EQ(both[c].result.status, one.result.status);
    EXPECT_EQ(both[c].result.camera.params, one.result.camera.params) << "camera " << c;
    // The covariance can differ in its last digits (seen: up to 6e-12 relative) when it is
    // computed on another thread; repeats on one thread are bit-equal, and so are the parameters
    // either way. Equal to rounding.
    ASSERT_EQ(both[c].result.param_stddev.size(), one.result.param_stddev.size());
    for (std::size_t k = 0; k < one.result.param_stddev.size(); ++k)
      EXPECT_NEAR(both[c].result.param_stddev[k], one.result.param_stddev[k],
                  1e-9 * one.result.param_stddev[k])
          << "camera " << c << ", parameter " << k;
    EXPECT_EQ(both[c].views.size(), one.views.size());
    EXPECT_NEAR(both[c].result.camera.params[0], scene.cams[c].params[0], 1.0) << "camera " << c;
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace robocal::app
