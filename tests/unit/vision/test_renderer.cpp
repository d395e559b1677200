// Renderer: rendered corners lie where the camera model projects them (measured from the
// rendered intensities alone), detectors decode the renders, determinism, noise statistics.
#include "robocal/vision/edge_fit.hpp"
#include "robocal/vision/pose.hpp"
#include "robocal/vision/renderer.hpp"

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <map>

#include "target_boards.hpp"

namespace rv = robocal::vision;
namespace rt = robocal::testing;

namespace {

// Position of a single edge crossing a row (or column) segment, from the intensities alone:
// for an ideal area-sampled image, sum over pixels a..b of I = cL (e - (a - 1/2)) +
// cR ((b + 1/2) - e) exactly, where cL, cR are the intensities on either side (read from the
// end pixels, which the edge does not touch).
double edge_crossing(const double* values, int n, int a) {
  const int b = a + n - 1;
  const double cl = values[0], cr = values[n - 1];
  double sum = 0;
  for (int k = 0; k < n; ++k) sum += values[k];
  return (sum - cr * (b + 0.5) + cl * (a - 0.5)) / (cl - cr);
}

// Quadratic least-squares fit x = c0 + c1 t + c2 t^2.
Eigen::Vector3d fit_quadratic(const std::vector<double>& t, const std::vector<double>& x) {
  Eigen::MatrixXd A(static_cast<int>(t.size()), 3);
  Eigen::VectorXd b(static_cast<int>(t.size()));
  for (int k = 0; k < static_cast<int>(t.size()); ++k) {
    A.row(k) << 1, t[static_cast<size_t>(k)], t[static_cast<size_t>(k)] * t[static_cast<size_t>(k)];
    b[k] = x[static_cast<size_t>(k)];
  }
  return A.colPivHouseholderQr().solve(b);
}

// Measures a chessboard corner from the ideal image: the two edges through it are located row
// by row (column by column) on both sides, clear of the other edge, fitted with quadratics and
// intersected.
// `along_v`: image direction of the board's y axis near the corner (to place the windows).
std::optional<Eigen::Vector2d> measure_corner(const cv::Mat& img, const Eigen::Vector2d& guess,
                                              const Eigen::Vector2d& dir_v,
                                              const Eigen::Vector2d& dir_u) {
  constexpr int kHalf = 6;
  std::vector<double> tv, xv, tu, yu;
  const int cu = static_cast<int>(std::lround(guess.x()));
  const int cv_ = static_cast<int>(std::lround(guess.y()));
  // Rows (columns) used must keep the other edge out of their window: stay further from the
  // corner than the other edge's slope times the window half-width, plus a pixel.
  const double min_tv = std::abs(dir_u.y() / dir_u.x()) * (kHalf + 1) + 1.5;
  const double min_tu = std::abs(dir_v.x() / dir_v.y()) * (kHalf + 1) + 1.5;
  for (int d = -25; d <= 25; ++d) {
    {  // vertical edge crossing row cv_ + d
      const int v = cv_ + d;
      const double t = v - guess.y();
      if (std::abs(t) >= min_tv && std::abs(t) <= min_tv + 9) {
        const double x_pred = guess.x() + dir_v.x() / dir_v.y() * t;
        const int a = static_cast<int>(std::lround(x_pred)) - kHalf;
        if (a < 0 || a + 2 * kHalf >= img.cols || v < 0 || v >= img.rows) return std::nullopt;
        double vals[2 * kHalf + 1];
        for (int k = 0; k <= 2 * kHalf; ++k) vals[k] = img.at<float>(v, a + k);
        if (std::abs(vals[0] - vals[2 * kHalf]) < 100) return std::nullopt;
        tv.push_back(t);
        xv.push_back(edge_crossing(vals, 2 * kHalf + 1, a));
      }
    }
    {  // horizontal edge crossing column cu + d
      const int u = cu + d;
      const double t = u - guess.x();
      if (std::abs(t) >= min_tu && std::abs(t) <= min_tu + 9) {
        const double y_pred = guess.y() + dir_u.y() / dir_u.x() * t;
        const int a = static_cast<int>(std::lround(y_pred)) - kHalf;
        if (a < 0 || a + 2 * kHalf >= img.rows || u < 0 || u >= img.cols) return std::nullopt;
        double vals[2 * kHalf + 1];
        for (int k = 0; k <= 2 * kHalf; ++k) vals[k] = img.at<float>(a + k, u);
        if (std::abs(vals[0] - vals[2 * kHalf]) < 100) return std::nullopt;
        tu.push_back(t);
        yu.push_back(edge_crossing(vals, 2 * kHalf + 1, a));
      }
    }
  }
  if (tv.size() < 10 || tu.size() < 10) return std::nullopt;
  const Eigen::Vector3d fv = fit_quadratic(tv, xv);
  const Eigen::Vector3d fu = fit_quadratic(tu, yu);
  Eigen::Vector2d p = guess;
  for (int it = 0; it < 50; ++it) {
    const double ty = p.y() - guess.y();
    p.x() = fv[0] + fv[1] * ty + fv[2] * ty * ty;
    const double tx = p.x() - guess.x();
    p.y() = fu[0] + fu[1] * tx + fu[2] * tx * tx;
  }
  return p;
}

struct CornerCheck {
  int measured = 0;
  double worst = 0;
  double rms = 0;
};

CornerCheck check_chessboard_corners(const rv::CameraModel& cam, const Eigen::Isometry3d& pose) {
  const rv::TargetBoard board = rt::chessboard_board(9, 7, 0.03);
  const rv::CameraRays rays = rv::precompute_rays(cam);
  std::vector<rv::RenderTarget> targets = {{board, pose}};
  rv::RenderOptions opt;
  const cv::Mat img = rv::render_ideal(rays, targets, opt);
  const auto truth = rv::corner_truth(cam, targets, opt);
  CornerCheck r;
  for (const auto& t : truth) {
    if (!t.visible || !rv::in_image(cam, t.pixel, 25)) continue;
    const Eigen::Vector3d p = *rv::corner_point(board, t.id);
    const auto proj = [&](const Eigen::Vector3d& q) { return *rv::project(cam, pose * q); };
    const Eigen::Vector2d dir_v =
        proj(p + Eigen::Vector3d(0, 0.01, 0)) - proj(p - Eigen::Vector3d(0, 0.01, 0));
    const Eigen::Vector2d dir_u =
        proj(p + Eigen::Vector3d(0.01, 0, 0)) - proj(p - Eigen::Vector3d(0.01, 0, 0));
    const auto m = measure_corner(img, t.pixel, dir_v, dir_u);
    if (!m) continue;
    const double e = (*m - t.pixel).norm();
    r.worst = std::max(r.worst, e);
    r.rms += e * e;
    ++r.measured;
  }
  if (r.measured > 0) r.rms = std::sqrt(r.rms / r.measured);
  return r;
}

}  // namespace

TEST(Renderer, CornersLieWhereTheModelProjectsThem_Radtan) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRadtan, 800, 600, 820.0, 818.0, 401.3,
                                   297.8, {-0.28, 0.12, 0.0008, -0.0005, -0.02});
  const auto board = rt::chessboard_board(9, 7, 0.03);
  const CornerCheck r =
      check_chessboard_corners(cam, rt::tilted_board_pose(board, 0.42, 20, -25, 4));
  EXPECT_GE(r.measured, 40);
  EXPECT_LT(r.worst, 0.002) << "rms " << r.rms;
  RecordProperty("worst_px", std::to_string(r.worst));
  RecordProperty("rms_px", std::to_string(r.rms));
  RecordProperty("corners", std::to_string(r.measured));
}

TEST(Renderer, CornersLieWhereTheModelProjectsThem_Fisheye) {
  const auto cam = rv::make_camera(rv::CameraKind::kFisheyeKB4, 800, 600, 380.0, 379.0, 399.2,
                                   301.1, {0.02, -0.01, 0.003, -0.0005});
  const auto board = rt::chessboard_board(9, 7, 0.03);
  const CornerCheck r =
      check_chessboard_corners(cam, rt::tilted_board_pose(board, 0.22, -15, 30, -3));
  EXPECT_GE(r.measured, 40);
  EXPECT_LT(r.worst, 0.002) << "rms " << r.rms;
  RecordProperty("worst_px", std::to_string(r.worst));
  RecordProperty("rms_px", std::to_string(r.rms));
  RecordProperty("corners", std::to_string(r.measured));
}

TEST(Renderer, BlurKeepsEdgePositions) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRadtan, 200, 120, 300, 300, 99.5, 59.5);
  const auto board = rt::chessboard_board(2, 2, 0.2);
  // The vertical edge of the board's centre slightly right of the image centre, tilted.
  auto pose = rt::tilted_board_pose(board, 1.0, 0, 0, 3);
  pose.translation().x() += 0.0013;
  const auto rays = rv::precompute_rays(cam);
  rv::RenderOptions opt;
  const cv::Mat sharp = rv::render_ideal(rays, {{board, pose}}, opt);
  cv::Mat blurred;
  cv::GaussianBlur(sharp, blurred, cv::Size(0, 0), 1.2, 1.2, cv::BORDER_REFLECT);
  double worst = 0;
  for (int v = 10; v < 50; ++v) {  // upper half: one vertical edge near u = 100
    double a[25], b[25];
    for (int k = 0; k < 25; ++k) {
      a[k] = sharp.at<float>(v, 88 + k);
      b[k] = blurred.at<float>(v, 88 + k);
    }
    worst = std::max(worst, std::abs(edge_crossing(a, 25, 88) - edge_crossing(b, 25, 88)));
  }
  EXPECT_LT(worst, 1e-3);
}

namespace {
rv::TargetBoard april_board() {
  return rt::apriltag_grid_board(4, 3, 0.03, 20);
}
// A small camera and a sensor with read and shot noise behind a 0.8 px lens blur.
rv::CameraModel small_camera() {
  return rv::make_camera(rv::CameraKind::kPinholeRadtan, 320, 240, 300, 300, 159.5, 119.5);
}
rv::RenderOptions noisy_blurred() {
  rv::RenderOptions opt;
  opt.read_noise = 2.0;
  opt.shot_noise_gain = 4.0;
  opt.blur_sigma = 0.8;
  return opt;
}
}  // namespace

TEST(Renderer, AprilTagDecodesRenderWithTruthCorners) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRadtan, 640, 480, 600, 600, 319.5, 239.5,
                                   {-0.1, 0.02, 0, 0, 0});
  const auto board = april_board();
  std::vector<rv::RenderTarget> targets = {{board, rt::tilted_board_pose(board, 0.25, 25, 15, 10)}};
  rv::RenderOptions opt;
  opt.blur_sigma = 0.6;
  opt.read_noise = 1.0;
  const auto res = rv::render(rv::precompute_rays(cam), targets, opt);
  std::map<int, Eigen::Vector2d> truth;
  for (const auto& c : res.corners) {
    EXPECT_TRUE(c.visible);
    truth[c.id] = c.pixel;
  }
  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* det = apriltag_detector_create();
  apriltag_detector_add_family(det, family);
  det->quad_decimate = 1.0;
  det->nthreads = 1;
  cv::Mat img = res.image;
  image_u8_t im{img.cols, img.rows, static_cast<int32_t>(img.step), img.data};
  zarray_t* found = apriltag_detector_detect(det, &im);
  int n = zarray_size(found);
  double worst = 0;
  for (int i = 0; i < n; ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(found, i, &d);
    for (int k = 0; k < 4; ++k) {
      ASSERT_TRUE(truth.count(d->id * 4 + k)) << d->id;
      const Eigen::Vector2d p(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
      worst = std::max(worst, (p - truth[d->id * 4 + k]).norm());
    }
  }
  apriltag_detections_destroy(found);
  apriltag_detector_destroy(det);
  tag36h11_destroy(family);
  EXPECT_EQ(n, 12);
  EXPECT_LT(worst, 0.5);  // a mirrored or shifted render would be many pixels off
}

TEST(Renderer, CharucoDecodesRender) {
  const auto board = rt::charuco_board(5, 4, 0.03, 0.022);
  const auto cam =
      rv::make_camera(rv::CameraKind::kPinholeRadtan, 640, 480, 600, 600, 319.5, 239.5);
  const auto pose = rt::tilted_board_pose(board, 0.3, -20, 10, 0);
  const auto res = rv::render(rv::precompute_rays(cam), {{board, pose}}, rv::RenderOptions{});
  const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_6X6_250);
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(res.image, dict, corners, ids);
  ASSERT_EQ(ids.size(), 10u);
  for (size_t m = 0; m < ids.size(); ++m) {
    const auto& mk = board.markers[static_cast<size_t>(ids[m])];
    for (int k = 0; k < 4; ++k) {  // unrefined ArUco corners: about a pixel
      const auto px = *rv::project(cam, pose * mk.corners[k]);
      EXPECT_LT(std::hypot(corners[m][static_cast<size_t>(k)].x - px.x(),
                           corners[m][static_cast<size_t>(k)].y - px.y()),
                1.5);
    }
  }
  const auto cvb = cv::aruco::CharucoBoard::create(5, 4, 0.03f, 0.022f, dict);
  std::vector<cv::Point2f> chess;
  std::vector<int> chess_ids;
  cv::aruco::interpolateCornersCharuco(corners, ids, res.image, cvb, chess, chess_ids);
  ASSERT_EQ(chess_ids.size(), 12u);
  Eigen::Vector2d offset(0, 0);
  for (size_t k = 0; k < chess_ids.size(); ++k) {
    const auto px = *rv::project(cam, pose * *rv::corner_point(board, chess_ids[k]));
    offset += Eigen::Vector2d(chess[k].x - px.x(), chess[k].y - px.y());
  }
  offset /= 12.0;
  EXPECT_NEAR(offset.x(), 0.5, 0.1);  // OpenCV 4.6's known +0.5 px
  EXPECT_NEAR(offset.y(), 0.5, 0.1);
}

TEST(Renderer, DeterministicWithSeed) {
  const auto cam = small_camera();
  const auto board = april_board();
  std::vector<rv::RenderTarget> targets = {{board, rt::tilted_board_pose(board, 0.3, 10, 10, 0)}};
  const auto rays = rv::precompute_rays(cam);
  rv::RenderOptions opt = noisy_blurred();
  opt.seed = 42;
  const cv::Mat a = rv::render(rays, targets, opt).image;
  const cv::Mat b = rv::render(rays, targets, opt).image;
  opt.seed = 43;
  const cv::Mat c = rv::render(rays, targets, opt).image;
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 1000.0);
}

// Bands of rows on several workers give the image of one worker, bit for bit: the scene's light
// and its edge pixels' sub-cells (their order too, which the blur sums in), and the readout.
TEST(Renderer, AnyNumberOfThreadsGivesTheSameImage) {
  const auto cam = small_camera();
  const auto board = april_board();
  const std::vector<rv::RenderTarget> targets = {
      {board, rt::tilted_board_pose(board, 0.3, 35, 20, 5)}};
  const auto rays = rv::precompute_rays(cam);
  rv::RenderOptions opt = noisy_blurred();
  opt.vignetting = 0.1;
  rv::Occluder finger;
  finger.center = Eigen::Vector2d(150.3, 118.7);
  finger.radius = 12.0;
  finger.level = 5.0;
  opt.occluders.push_back(finger);
  const rv::SceneIrradiance one = rv::render_irradiance(rays, targets, opt);
  const cv::Mat image = rv::render(rays, targets, opt).image;
  ASSERT_GT(one.edge_pixels.size(), 1000u);
  for (const int threads : {2, 3, 7}) {
    opt.threads = threads;
    const rv::SceneIrradiance many = rv::render_irradiance(rays, targets, opt);
    EXPECT_EQ(cv::norm(many.pixels, one.pixels, cv::NORM_INF), 0.0) << threads;
    EXPECT_EQ(many.edge_pixels, one.edge_pixels) << threads;
    EXPECT_EQ(many.subcell_values, one.subcell_values) << threads;
    EXPECT_EQ(cv::norm(rv::render(rays, targets, opt).image, image, cv::NORM_INF), 0.0) << threads;
  }
  // A still camera's second frame with another number of workers is the same scene.
  rv::StillSceneRenderer camera(rays);
  opt.threads = 1;
  (void)camera.render(targets, opt);
  opt.threads = 2;
  EXPECT_EQ(cv::norm(camera.render(targets, opt), image, cv::NORM_INF), 0.0);
  EXPECT_EQ(camera.reused(), 1);
  opt.threads = 0;
  EXPECT_THROW((void)rv::render(rays, targets, opt), std::invalid_argument);
}

// A still scene shot again draws only new noise: every frame equals render()'s bit for bit, and
// only a frame of the very same scene (pose and levels) reuses the last one's light.
TEST(Renderer, StillSceneRendererEqualsRenderFrameByFrame) {
  const auto cam = small_camera();
  const auto board = april_board();
  const Eigen::Isometry3d a = rt::tilted_board_pose(board, 0.3, 10, 10, 0);
  Eigen::Isometry3d b = a;
  b.translation().x() += 1e-9;  // a robot that moved by a nanometre is another scene
  // Out of view: 1 m to the side at 0.3 m (the camera's half angle is 28 degrees), then 2 m; and
  // the board turned away from the camera. All three are the same empty scene.
  Eigen::Isometry3d side = a, further = a, turned = a;
  side.translation().x() += 1.0;
  further.translation().x() += 2.0;
  turned.linear() = a.linear() * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY());
  // 1.5 m away, 30 degrees below the axis (camera y points down the image): inside the cone of the
  // rays (the image diagonal's 33.7 degrees) but beyond the bottom edge's 21.8; then at 20
  // degrees, partly in the image.
  const auto at_elevation = [&](double degrees) {
    Eigen::Isometry3d pose = rt::centred_board_pose(board, Eigen::Matrix3d::Identity(), 1.5);
    pose.translation().y() += 1.5 * std::tan(degrees * M_PI / 180.0);
    return pose;
  };
  const Eigen::Isometry3d below = at_elevation(30.0), at_edge = at_elevation(20.0);
  rv::RenderOptions opt = noisy_blurred();
  rv::StillSceneRenderer camera(rv::precompute_rays(cam));
  struct Frame {
    Eigen::Isometry3d pose;
    double white;
    std::uint64_t seed;
    int bit_depth;
    long reused_after;
  };
  const std::vector<Frame> frames = {
      {a, 220.0, 1, 8, 0},       {a, 220.0, 2, 8, 1},       {a, 220.0, 3, 16, 2},
      {b, 220.0, 4, 8, 2},       {b, 200.0, 5, 8, 2},       {b, 200.0, 6, 8, 3},
      {side, 200.0, 7, 8, 3},    {further, 200.0, 8, 8, 4}, {turned, 200.0, 9, 8, 5},
      {turned, 220.0, 10, 8, 5}, {below, 220.0, 11, 8, 6},  {at_edge, 220.0, 12, 8, 6}};
  for (const Frame& f : frames) {
    opt.white_level = f.white;
    opt.seed = f.seed;
    opt.bit_depth = f.bit_depth;
    const std::vector<rv::RenderTarget> targets = {{board, f.pose}};
    const cv::Mat expected = rv::render(camera.rays(), targets, opt).image;
    const cv::Mat got = camera.render(targets, opt);
    ASSERT_EQ(got.type(), expected.type()) << "frame " << f.seed;
    EXPECT_EQ(cv::norm(got, expected, cv::NORM_INF), 0.0) << "frame " << f.seed;
    EXPECT_EQ(camera.reused(), f.reused_after) << "frame " << f.seed;
    if (f.seed == 12) {  // part of the board in the image's bottom rows: not an empty scene
      double lo = 0, hi = 0;
      cv::minMaxLoc(expected.rowRange(expected.rows - 20, expected.rows), &lo, &hi);
      EXPECT_GT(hi - lo, 100.0);
    }
  }
}

// A camera keeps the light where no target is seen from frame to frame: only the pixels around
// the board are rendered and blurred again. Every frame is still render()'s, bit for bit, as the
// board moves (near the image border too) and as the background's level changes (an exposure).
TEST(Renderer, StillSceneRendererKeepsTheBackgroundOnlyWhileItIsTheSame) {
  const auto cam = small_camera();
  const auto board = april_board();
  rv::RenderOptions opt;
  opt.read_noise = 2.0;
  opt.blur_sigma = 0.8;
  opt.vignetting = 0.15;
  opt.lighting_gradient = Eigen::Vector2d(0.05, -0.03);
  rv::StillSceneRenderer camera(rv::precompute_rays(cam));
  for (int k = 0; k < 8; ++k) {
    // The board 0.5 m away, moving right and down until it leaves the image's corner.
    Eigen::Isometry3d pose = rt::tilted_board_pose(board, 0.5, 20, 10 * k, 0);
    pose.translation() += Eigen::Vector3d(0.04 * k, 0.03 * k, 0.0);
    opt.background_level = k < 5 ? 60.0 : 45.0;
    opt.seed = static_cast<std::uint64_t>(k + 1);
    const std::vector<rv::RenderTarget> targets = {{board, pose}};
    const cv::Mat expected = rv::render(camera.rays(), targets, opt).image;
    EXPECT_EQ(cv::norm(camera.render(targets, opt), expected, cv::NORM_INF), 0.0) << "frame " << k;
  }
  EXPECT_EQ(camera.reused(), 0);
}

// The readout rounds half away from zero and clamps to the sensor's range, as std::round would.
TEST(Renderer, ReadoutRoundsHalfAwayFromZeroAndClamps) {
  const std::vector<float> light = {-3.0f, -0.5f,      0.0f,   0.49999997f, 0.5f,   1.5f,
                                    2.5f,  127.49998f, 127.5f, 254.5f,      255.0f, 300.0f};
  const cv::Mat irradiance(1, static_cast<int>(light.size()), CV_32F,
                           const_cast<float*>(light.data()));
  for (const int depth : {8, 16}) {
    rv::RenderOptions opt;  // no noise
    opt.bit_depth = depth;
    const cv::Mat out = rv::sensor_readout(irradiance, opt);
    const double scale = depth == 16 ? 257.0 : 1.0, top = depth == 16 ? 65535.0 : 255.0;
    for (std::size_t i = 0; i < light.size(); ++i) {
      const double expected = std::clamp(std::round(double(light[i]) * scale), 0.0, top);
      const double got = depth == 16 ? out.at<std::uint16_t>(0, static_cast<int>(i))
                                     : out.at<std::uint8_t>(0, static_cast<int>(i));
      EXPECT_EQ(got, expected) << light[i] << " at " << depth << " bit";
    }
  }
}

TEST(Renderer, NoiseStatistics) {
  const auto cam =
      rv::make_camera(rv::CameraKind::kPinholeRadtan, 300, 300, 300, 300, 149.5, 149.5);
  rv::RenderOptions opt;
  opt.background_level = 100.0;
  opt.read_noise = 2.0;
  opt.shot_noise_gain = 4.0;  // shot variance 100 / 4 = 25 DN^2
  opt.bit_depth = 16;
  const cv::Mat img = rv::render(rv::precompute_rays(cam), {}, opt).image;
  cv::Mat dn;
  img.convertTo(dn, CV_64F, 1.0 / 257.0);
  cv::Scalar mean, stddev;
  cv::meanStdDev(dn, mean, stddev);
  EXPECT_NEAR(mean[0], 100.0, 0.1);
  EXPECT_NEAR(stddev[0] * stddev[0], 29.0, 29.0 * 0.03);
  // Neighbouring pixels are uncorrelated.
  double cov = 0;
  for (int v = 0; v < dn.rows; ++v)
    for (int u = 0; u + 1 < dn.cols; ++u)
      cov += (dn.at<double>(v, u) - mean[0]) * (dn.at<double>(v, u + 1) - mean[0]);
  cov /= dn.rows * (dn.cols - 1);
  EXPECT_LT(std::abs(cov) / 29.0, 0.02);
}

// The read noise is normal into its tails: counts in half-sigma bins out to 4.5 sigma and beyond
// match the normal distribution's (chi-square, 19 degrees of freedom), on a full-size frame.
TEST(Renderer, ReadNoiseIsNormalIntoTheTails) {
  constexpr double level = 128.0, sigma = 8.0, scale = 257.0;  // 16 bit: 1/257 DN per step
  const cv::Mat flat(1200, 1600, CV_32F, cv::Scalar(level));
  rv::RenderOptions opt;
  opt.read_noise = sigma;
  opt.bit_depth = 16;
  opt.seed = 11;
  const cv::Mat out = rv::sensor_readout(flat, opt);
  // Bin edges halfway between readout steps, so rounding never moves a value across one.
  std::vector<double> edges;
  for (int j = -9; j <= 9; ++j)
    edges.push_back((std::round((level + 0.5 * j * sigma) * scale) + 0.5) / scale);
  std::vector<double> count(edges.size() + 1, 0.0);
  for (int v = 0; v < out.rows; ++v)
    for (int u = 0; u < out.cols; ++u) {
      const double dn = out.at<std::uint16_t>(v, u) / scale;
      count[std::upper_bound(edges.begin(), edges.end(), dn) - edges.begin()] += 1.0;
    }
  const double n = static_cast<double>(out.total());
  const auto cdf = [&](double dn) {
    return 0.5 * std::erfc(-(dn - level) / sigma / std::sqrt(2.0));
  };
  double chi2 = 0.0;
  for (std::size_t b = 0; b < count.size(); ++b) {
    const double lo = b == 0 ? 0.0 : cdf(edges[b - 1]);
    const double hi = b == edges.size() ? 1.0 : cdf(edges[b]);
    const double expected = n * (hi - lo);
    chi2 += (count[b] - expected) * (count[b] - expected) / expected;
  }
  EXPECT_LT(chi2, 43.8) << "chi-square, 19 degrees of freedom (0.1 % level)";
  // Beyond 4.5 sigma each side: about 6.5 expected; a generator with clipped tails has none.
  EXPECT_GT(count.front(), 0.0);
  EXPECT_GT(count.back(), 0.0);
  // Pixels a row apart are as uncorrelated as neighbours in a row.
  double cov = 0.0;
  for (int v = 0; v + 1 < out.rows; ++v)
    for (int u = 0; u < out.cols; ++u)
      cov += (out.at<std::uint16_t>(v, u) / scale - level) *
             (out.at<std::uint16_t>(v + 1, u) / scale - level);
  cov /= (out.rows - 1) * out.cols;
  EXPECT_LT(std::abs(cov) / (sigma * sigma), 5.0 / std::sqrt(n));
}

TEST(Renderer, LevelsLightingAndVignetting) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRadtan, 101, 81, 100, 100, 50, 40);
  rv::RenderOptions opt;
  opt.background_level = 100.0;
  opt.vignetting = 0.3;
  opt.lighting_gradient = Eigen::Vector2d(0.2, 0.0);
  const cv::Mat img = rv::render_ideal(rv::precompute_rays(cam), {}, opt);
  EXPECT_NEAR(img.at<float>(40, 50), 100.0, 1e-3);  // centre
  // Top-left pixel: vignetting 1 - 0.3 (r = r_corner), gradient 1 + 0.2 (0.5/101 - 0.5).
  const double g = 1.0 + 0.2 * (0.5 / 101 - 0.5);
  EXPECT_NEAR(img.at<float>(0, 0), 100.0 * g * 0.7, 1e-3);
}

TEST(Renderer, OcclusionAndVisibility) {
  const auto cam =
      rv::make_camera(rv::CameraKind::kPinholeRadtan, 640, 480, 600, 600, 319.5, 239.5);
  const auto board = april_board();
  const auto pose = rt::tilted_board_pose(board, 0.25, 0, 0, 0);
  rv::RenderOptions opt;
  rv::Occluder occ;
  const int hidden_id = 25 * 4 + 2;
  occ.center = *rv::project(cam, pose * *rv::corner_point(board, hidden_id));
  occ.radius = 10;
  occ.level = 5;
  opt.occluders = {occ};
  // A second board in front covering the left part of the first.
  const auto front = rt::chessboard_board(3, 3, 0.01);
  Eigen::Isometry3d front_pose = Eigen::Isometry3d::Identity();
  front_pose.translation() = Eigen::Vector3d(-0.08, -0.03, 0.2);
  const std::vector<rv::RenderTarget> targets = {{board, pose}, {front, front_pose}};
  const auto rays = rv::precompute_rays(cam);
  const auto res = rv::render(rays, targets, opt);
  const cv::Mat ideal = rv::render_ideal(rays, targets, opt);
  int occluded_by_target = 0;
  for (const auto& c : res.corners) {
    if (c.target != 0) continue;
    if (c.id == hidden_id) {
      EXPECT_TRUE(c.occluded);
      EXPECT_FALSE(c.visible);
      EXPECT_NEAR(ideal.at<float>(static_cast<int>(std::lround(c.pixel.y())),
                                  static_cast<int>(std::lround(c.pixel.x()))),
                  5.0, 1e-4);
    } else if (c.occluded) {
      ++occluded_by_target;
      // The front board is what the image shows there: its paper or print, never the tag below.
      const Eigen::Vector3d ray = rv::unproject(cam, c.pixel)->normalized();
      const double t = front_pose.translation().z() / ray.z();
      const Eigen::Vector3d hit = ray * t - front_pose.translation();
      EXPECT_TRUE(rv::on_board(front, hit.x(), hit.y()));
    }
  }
  EXPECT_GT(occluded_by_target, 0);
  // Corners outside the image are not visible.
  const auto far =
      rv::corner_truth(cam, {{board, rt::tilted_board_pose(board, 0.05, 0, 0, 0)}}, opt);
  int outside = 0;
  for (const auto& c : far) outside += !rv::in_image(cam, c.pixel) && !c.visible;
  EXPECT_GT(outside, 0);
}

TEST(Renderer, CornersLieWhereTheModelProjectsThem_SteepTilt) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRational, 800, 600, 820.0, 818.0, 401.3,
                                   297.8, {0.3, -0.1, 0.0008, -0.0005, 0.02, 0.6, -0.05, 0.04});
  const auto board = rt::chessboard_board(9, 7, 0.03);
  const CornerCheck r = check_chessboard_corners(cam, rt::tilted_board_pose(board, 0.40, 5, 58, 2));
  EXPECT_GE(r.measured, 30);
  EXPECT_LT(r.worst, 0.002) << "rms " << r.rms;
  RecordProperty("worst_px", std::to_string(r.worst));
  RecordProperty("rms_px", std::to_string(r.rms));
  RecordProperty("corners", std::to_string(r.measured));
}

namespace {

// Largest error of the edge fit's line against the true edge (x = the inner corner's projection)
// over 20 sub-pixel phases of a vertical edge, blur sigma 0.8, 16 bit, no noise. `subcells`
// selects the renderer's sub-cells (true) or an image of pixel means alone (false).
double worst_edge_phase_error(bool subcells) {
  const auto board = rt::chessboard_board(2, 2, 0.2);
  const Eigen::Isometry3d pose = rt::tilted_board_pose(board, 1.0, 0, 0, 0);
  rv::RenderOptions opt;
  opt.blur_sigma = 0.8;
  opt.bit_depth = 16;
  double worst = 0.0;
  for (int k = 0; k < 20; ++k) {
    const auto cam =
        rv::make_camera(rv::CameraKind::kPinholeRadtan, 200, 120, 300, 300, 99.0 + k / 20.0, 59.5);
    const std::vector<rv::RenderTarget> targets = {{board, pose}};
    const auto rays = rv::precompute_rays(cam);
    const cv::Mat img = subcells ? rv::apply_sensor(rv::render_irradiance(rays, targets, opt), opt)
                                 : rv::apply_sensor(rv::render_ideal(rays, targets, opt), opt);
    const auto truth = rv::corner_truth(cam, targets, opt);
    const Eigen::Vector2d corner = truth.at(0).pixel;  // the 2x2 board's one inner corner
    // The vertical edge above the corner, away from the corner and the board's outer edges.
    std::vector<rv::EdgeSample> samples;
    const int u0 = static_cast<int>(std::lround(corner.x()));
    for (int v = 10; v <= 50; ++v)
      for (int u = u0 - 7; u <= u0 + 7; ++u)
        samples.push_back({Eigen::Vector2d(u, v), img.at<std::uint16_t>(v, u) / 257.0});
    const auto fit = rv::fit_edge_line(samples, Eigen::Vector2d(corner.x(), 10),
                                       Eigen::Vector2d(corner.x(), 50));
    if (!fit) return 1.0;
    worst = std::max(worst, std::abs(fit->point().x() - corner.x()));
  }
  return worst;
}

}  // namespace

// A lens blurs the light before the pixel integrates it. Blurring the pixel means instead leaves
// an error on near-axis-aligned edges that depends on where the edge falls inside the pixel
// (0.013 px RMS at sigma 0.8); the renderer's sub-cells must remove it, measured by an edge fit
// that is unbiased on the exact profile (EdgeFit.UnbiasedAtEverySubPixelPhase...).
TEST(Renderer, BlurActsBeforeThePixelsIntegrate) {
  const double with_subcells = worst_edge_phase_error(true);
  const double pixel_means_only = worst_edge_phase_error(false);
  RecordProperty("worst_px_subcells", std::to_string(with_subcells));
  RecordProperty("worst_px_pixel_means", std::to_string(pixel_means_only));
  EXPECT_LT(with_subcells, 1e-3);
  // The check is sensitive: the same images from pixel means alone show the aliasing.
  EXPECT_GT(pixel_means_only, 5e-3);
}

namespace {

// What the camera sees along pixel point `px`, from the test's own ray casting and the board's
// printed modules: 0 black module, 1 white (module or paper), 2 no paper (background).
int seen_at(const rv::CameraModel& cam, const rv::TargetBoard& board,
            const Eigen::Isometry3d& camera_T_board, const Eigen::Vector2d& px) {
  const auto ray = rv::unproject(cam, px);
  if (!ray) return 2;
  const Eigen::Isometry3d board_T_camera = camera_T_board.inverse();
  const Eigen::Vector3d o = board_T_camera.translation();
  const Eigen::Vector3d d = board_T_camera.linear() * *ray;
  if (!(o.z() < 0.0) || !(d.z() > 0.0)) return 2;  // printed side faces -z
  const Eigen::Vector3d p = o + (-o.z() / d.z()) * d;
  if (p.x() < board.extent_min.x() || p.y() < board.extent_min.y() ||
      p.x() > board.extent_max.x() || p.y() > board.extent_max.y())
    return 2;
  for (const rv::PatternPatch& patch : board.patches) {
    const double u = (p.x() - patch.x0) / patch.module, v = (p.y() - patch.y0) / patch.module;
    if (u < 0 || v < 0 || u >= patch.nx || v >= patch.ny) continue;
    if (patch.black[static_cast<size_t>(static_cast<int>(v) * patch.nx + static_cast<int>(u))])
      return 0;
  }
  return 1;
}

}  // namespace

// Every pixel against 12 x 12 rays of its own: a pixel all of whose rays see one thing has that
// level (to the share a sliver between the rays can hold), a pixel that sees black and white
// lies between them as the share of its rays says. A board crossing the image border: the
// renderer traces only the rays near the paper, and a pixel off it must read the background.
TEST(Renderer, EveryPixelIsTheShareOfWhatItsFootprintSees) {
  const auto cam = rv::make_camera(rv::CameraKind::kPinholeRadtan, 240, 180, 260, 260, 119.5, 89.5,
                                   {-0.08, 0.02, 0.0005, -0.0003, 0.0});
  const rv::TargetBoard board = rt::apriltag_grid_board(4, 3, 0.05);
  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitX()))
                                   .toRotationMatrix();
  for (const double shift : {0.0, 0.12}) {  // whole, then cut by the image's right border
    Eigen::Isometry3d pose = rt::centred_board_pose(board, tilt, 0.6);
    pose.translation().x() += shift;
    rv::RenderOptions opt;
    const cv::Mat img = rv::render_ideal(rv::precompute_rays(cam), {{board, pose}}, opt);
    const double level[3] = {opt.black_level, opt.white_level, opt.background_level};
    constexpr int kRays = 12;
    int uniform = 0, mixed = 0, background = 0;
    for (int v = 0; v < cam.height; ++v)
      for (int u = 0; u < cam.width; ++u) {
        int count[3] = {0, 0, 0};
        for (int b = 0; b < kRays; ++b)
          for (int a = 0; a < kRays; ++a)
            ++count[seen_at(
                cam, board, pose,
                Eigen::Vector2d(u - 0.5 + (a + 0.5) / kRays, v - 0.5 + (b + 0.5) / kRays))];
        const double value = img.at<float>(v, u);
        SCOPED_TRACE(testing::Message()
                     << "shift " << shift << ", pixel (" << u << ", " << v << "): black "
                     << count[0] << ", white " << count[1] << ", off the paper " << count[2]);
        const int all = kRays * kRays;
        for (int k = 0; k < 3; ++k)
          if (count[k] == all) {
            // A sliver between two rows of rays holds at most a twelfth of the pixel.
            EXPECT_NEAR(value, level[k], std::abs(level[1] - level[0]) / kRays);
            ++(k == 2 ? background : uniform);
          }
        if (count[2] == 0 && count[0] > 0 && count[1] > 0) {
          const double expected = level[1] - (level[1] - level[0]) * count[0] / double(all);
          EXPECT_NEAR(value, expected, 2.0 * (level[1] - level[0]) / kRays);
          EXPECT_GT(value, level[0]);
          EXPECT_LT(value, level[1]);
          ++mixed;
        }
      }
    EXPECT_GT(uniform, 5000);
    EXPECT_GT(mixed, 1000);
    EXPECT_GT(background, 1000);
  }
}
