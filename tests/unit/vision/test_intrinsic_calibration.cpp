// Intrinsic calibration on simulated observations with known truth.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "robocal/core/random_draws.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/pose.hpp"

namespace rv = robocal::vision;

namespace {

const rv::CameraModel kTruth =
    rv::make_camera(rv::CameraKind::kPinholeRadtan, 1280, 1024, 1210.0, 1205.0, 651.3, 498.7,
                    {-0.21, 0.12, 0.0007, -0.0004, -0.03});

// An 11 x 8 grid of corners, 30 mm pitch (0.30 x 0.21 m).
std::vector<Eigen::Vector3d> board_grid() {
  std::vector<Eigen::Vector3d> pts;
  for (int r = 0; r < 8; ++r)
    for (int c = 0; c < 11; ++c) pts.emplace_back(0.03 * c, 0.03 * r, 0.0);
  return pts;
}

// A view from `eye_dist` m, tilted by tilt_deg towards azimuth az_deg, aimed at a board point
// offset from the centre so the board lands in different image areas.
rv::CalibrationView make_view(const std::string& name, double tilt_deg, double az_deg, double dist,
                              const Eigen::Vector2d& aim_offset, double noise_px,
                              std::mt19937& rng) {
  const Eigen::Vector3d centre(0.15, 0.105, 0.0);
  const double t = tilt_deg * M_PI / 180.0;
  const double a = az_deg * M_PI / 180.0;
  const Eigen::Vector3d dir(std::sin(t) * std::cos(a), std::sin(t) * std::sin(a), -std::cos(t));
  const Eigen::Vector3d target = centre + Eigen::Vector3d(aim_offset.x(), aim_offset.y(), 0);
  const Eigen::Isometry3d camera_T_board =
      rv::camera_T_board_look_at(centre + dist * dir, target, Eigen::Vector3d(0, -1, 0));
  std::normal_distribution<double> n(0.0, noise_px);
  rv::CalibrationView v;
  v.name = name;
  const auto pts = board_grid();
  for (size_t i = 0; i < pts.size(); ++i) {
    const auto px = rv::project(kTruth, camera_T_board * pts[i]);
    if (!px || !rv::in_image(kTruth, *px, 2.0)) continue;
    v.corner_ids.push_back(static_cast<int>(i));
    v.board_points.push_back(pts[i]);
    v.pixels.push_back(*px + robocal::core::draw_vector2(n, rng));
  }
  return v;
}

// 20 views: tilts 0-50 deg in all directions, board aimed across the whole image.
std::vector<rv::CalibrationView> good_views(double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<rv::CalibrationView> views;
  for (int i = 0; i < 20; ++i) {
    const double tilt = 10.0 + 40.0 * std::abs(u(rng));
    const double az = 180.0 * u(rng);
    // One draw a statement, y first (robocal/core/random_draws.hpp says why).
    const double aim_y = 0.16 * u(rng);
    const double aim_x = 0.2 * u(rng);
    const Eigen::Vector2d aim(aim_x, aim_y);
    views.push_back(
        make_view("view" + std::to_string(i), tilt, az, 0.45 + 0.1 * u(rng), aim, noise, rng));
  }
  return views;
}

rv::IntrinsicCalibrationOptions options() {
  rv::IntrinsicCalibrationOptions o;
  o.width = 1280;
  o.height = 1024;
  return o;
}

}  // namespace

TEST(IntrinsicCalibration, RecoversTruthWithConsistentSigma) {
  const auto views = good_views(0.2, 3);
  const auto res = rv::calibrate_intrinsics(views, options());
  ASSERT_EQ(res.status, rv::CalibrationStatus::kOk) << res.reason;
  EXPECT_TRUE(res.converged);
  EXPECT_EQ(res.corners_rejected, 0);
  EXPECT_NEAR(res.rms_px, 0.2 * std::sqrt(2.0), 0.03);  // 2-D RMS of 0.2 px per-axis noise
  EXPECT_NEAR(res.residual_sigma_px, 0.2, 0.02);
  for (size_t i = 0; i < 9; ++i) {
    const double err = res.camera.params[i] - kTruth.params[i];
    ASSERT_TRUE(std::isfinite(res.param_stddev[i])) << res.param_names[i];
    EXPECT_GT(res.param_stddev[i], 0.0);
    // 4.5 sigma: a failure here means the estimate or its predicted sigma is wrong.
    EXPECT_LT(std::abs(err), 4.5 * res.param_stddev[i])
        << res.param_names[i] << " err " << err << " sigma " << res.param_stddev[i];
  }
  EXPECT_LT(res.param_stddev[0], 1.0);  // fx sigma below 1 px with 20 good views
  EXPECT_TRUE(res.uncovered_regions.empty());
  // The uncertainty map is filled, larger in the corners than in the centre, and consistent with
  // the actual projection error of the recovered model at each cell (within 5 sigma).
  const auto& m = res.coverage;
  for (int r = 0; r < m.rows; ++r)
    for (int c = 0; c < m.cols; ++c) {
      const Eigen::Vector2d px((c + 0.5) * 1280.0 / m.cols - 0.5,
                               (r + 0.5) * 1024.0 / m.rows - 0.5);
      const auto ray = rv::unproject(res.camera, px);
      ASSERT_TRUE(ray.has_value());
      const auto truth_px = rv::project(kTruth, *ray / ray->z());
      ASSERT_TRUE(truth_px.has_value());
      const double sigma = m.projection_sigma_px[static_cast<size_t>(r * m.cols + c)];
      EXPECT_LT((*truth_px - px).norm(), 5.0 * sigma) << "cell " << c << "," << r;
    }
  ASSERT_EQ(m.projection_sigma_px.size(), static_cast<size_t>(m.cols * m.rows));
  const double centre =
      m.projection_sigma_px[static_cast<size_t>(m.rows / 2 * m.cols + m.cols / 2)];
  const double corner = m.projection_sigma_px[0];
  EXPECT_GT(centre, 0.0);
  EXPECT_GT(corner, centre);
}

TEST(IntrinsicCalibration, NoiseFreeDataIsFitExactly) {
  const auto res = rv::calibrate_intrinsics(good_views(0.0, 5), options());
  ASSERT_EQ(res.status, rv::CalibrationStatus::kOk) << res.reason;
  EXPECT_LT(res.rms_px, 1e-6);
  for (size_t i = 0; i < 4; ++i) EXPECT_NEAR(res.camera.params[i], kTruth.params[i], 1e-5);
}

// A known camera as the start (initial_params) reaches the same minimum as the homography
// initialisation: on noisy views the two agree to far below sigma (the solver does not stop
// early along the focal / distortion valley), and a start of the wrong size is refused.
TEST(IntrinsicCalibration, StartingFromAGivenCameraReachesTheSameMinimum) {
  const auto views = good_views(0.1, 11);
  const auto from_views = rv::calibrate_intrinsics(views, options());
  ASSERT_EQ(from_views.status, rv::CalibrationStatus::kOk) << from_views.reason;
  auto o = options();
  o.initial_params = kTruth.params;
  const auto from_truth = rv::calibrate_intrinsics(views, o);
  ASSERT_EQ(from_truth.status, rv::CalibrationStatus::kOk) << from_truth.reason;
  for (size_t i = 0; i < kTruth.params.size(); ++i)
    EXPECT_NEAR(from_truth.camera.params[i], from_views.camera.params[i],
                1e-3 * from_views.param_stddev[i])
        << from_views.param_names[i];
  o.initial_params.pop_back();
  EXPECT_THROW(rv::calibrate_intrinsics(views, o), std::invalid_argument);
}

TEST(IntrinsicCalibration, RejectsInjectedOutliers) {
  auto views = good_views(0.2, 7);
  views[2].pixels[5] += Eigen::Vector2d(4.0, -3.0);
  views[9].pixels[0] += Eigen::Vector2d(-6.0, 0.0);
  const auto res = rv::calibrate_intrinsics(views, options());
  ASSERT_EQ(res.status, rv::CalibrationStatus::kOk) << res.reason;
  int flagged = 0;
  for (const auto& r : res.residuals) {
    const bool injected = (r.view == 2 && r.corner_id == views[2].corner_ids[5]) ||
                          (r.view == 9 && r.corner_id == views[9].corner_ids[0]);
    if (injected) {
      EXPECT_TRUE(r.outlier) << "view " << r.view;
    }
    flagged += r.outlier ? 1 : 0;
  }
  EXPECT_GE(flagged, 2);
  EXPECT_LE(flagged, 4);  // a 4-sigma rule flags ~0.03 % of 1700 clean corners
  EXPECT_LT(std::abs(res.camera.params[0] - kTruth.params[0]), 4.5 * res.param_stddev[0]);
}

TEST(IntrinsicCalibration, ViewsBunchedInCentreNameUncoveredRegions) {
  std::mt19937 rng(11);
  std::vector<rv::CalibrationView> views;
  // Far away (1.6 m): the board covers only the middle of the image.
  for (int i = 0; i < 12; ++i) {
    views.push_back(make_view("far" + std::to_string(i), 20.0 + 2.0 * i, 30.0 * i, 1.6,
                              Eigen::Vector2d::Zero(), 0.2, rng));
  }
  const auto res = rv::calibrate_intrinsics(views, options());
  EXPECT_FALSE(res.uncovered_regions.empty());
  const auto has = [&](const std::string& n) {
    return std::find(res.uncovered_regions.begin(), res.uncovered_regions.end(), n) !=
           res.uncovered_regions.end();
  };
  EXPECT_TRUE(has("top-left"));
  EXPECT_TRUE(has("bottom-right"));
  EXPECT_FALSE(has("centre"));
  ASSERT_FALSE(res.advice.empty());
  bool advice_names_corner = false;
  for (const auto& a : res.advice) advice_names_corner |= a.find("top-left") != std::string::npos;
  EXPECT_TRUE(advice_names_corner);
  if (res.status == rv::CalibrationStatus::kOk) {
    bool warned = false;
    for (const auto& w : res.warnings) warned |= w.find("top-left") != std::string::npos;
    EXPECT_TRUE(warned);
  } else {
    EXPECT_EQ(res.status, rv::CalibrationStatus::kRefused);
    EXPECT_NE(res.reason.find("image regions"), std::string::npos) << res.reason;
  }
}

TEST(IntrinsicCalibration, RefusesTooFewViewsAndFlatViews) {
  auto views = good_views(0.2, 13);
  views.resize(3);
  auto res = rv::calibrate_intrinsics(views, options());
  EXPECT_EQ(res.status, rv::CalibrationStatus::kRefused);
  EXPECT_NE(res.reason.find("3 usable views"), std::string::npos) << res.reason;
  EXPECT_FALSE(res.advice.empty());

  std::mt19937 rng(2);
  std::vector<rv::CalibrationView> flat;
  for (int i = 0; i < 10; ++i) {
    flat.push_back(make_view("flat" + std::to_string(i), 2.0, 36.0 * i, 0.5,
                             Eigen::Vector2d(0.02 * (i % 3 - 1), 0.02 * (i % 2)), 0.2, rng));
  }
  res = rv::calibrate_intrinsics(flat, options());
  EXPECT_EQ(res.status, rv::CalibrationStatus::kRefused);
  EXPECT_NE(res.reason.find("fronto-parallel"), std::string::npos) << res.reason;

  res = rv::calibrate_intrinsics({}, options());
  EXPECT_EQ(res.status, rv::CalibrationStatus::kRefused);
  EXPECT_THROW(rv::calibrate_intrinsics(views, rv::IntrinsicCalibrationOptions{}),
               std::invalid_argument);
}

TEST(IntrinsicCalibration, BadViewsAreRejectedOneByOneAndTheRestCalibrates) {
  auto views = good_views(0.2, 17);
  // Mirrored: the image flipped left-right.
  for (auto& p : views[1].pixels) p.x() = 1279.0 - p.x();
  // Duplicate ids.
  views[4].corner_ids[1] = views[4].corner_ids[0];
  // Too few corners.
  views[6].pixels.resize(5);
  views[6].board_points.resize(5);
  views[6].corner_ids.resize(5);
  const auto res = rv::calibrate_intrinsics(views, options());
  ASSERT_EQ(res.status, rv::CalibrationStatus::kOk) << res.reason;
  EXPECT_FALSE(res.views[1].used);
  EXPECT_NE(res.views[1].rejection.find("mirrored"), std::string::npos) << res.views[1].rejection;
  EXPECT_FALSE(res.views[4].used);
  EXPECT_NE(res.views[4].rejection.find("duplicate"), std::string::npos);
  EXPECT_FALSE(res.views[6].used);
  EXPECT_NE(res.views[6].rejection.find("only 5 corners"), std::string::npos);
  int used = 0;
  for (const auto& v : res.views) used += v.used ? 1 : 0;
  EXPECT_EQ(used, 17);
  EXPECT_LT(std::abs(res.camera.params[0] - kTruth.params[0]), 4.5 * res.param_stddev[0]);
}
