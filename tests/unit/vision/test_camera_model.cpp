// Camera models: agreement with OpenCV, unprojection round trips, Jacobians, camera files.
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/camera_model.hpp"

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include <filesystem>
#include <random>

namespace rv = robocal::vision;

namespace {

rv::CameraModel radtan_camera() {
  return rv::make_camera(rv::CameraKind::kPinholeRadtan, 1280, 1024, 1210.5, 1208.25, 641.3, 509.7,
                         {-0.23, 0.11, 0.0007, -0.0004, -0.031});
}
rv::CameraModel rational_camera() {
  return rv::make_camera(rv::CameraKind::kPinholeRational, 2448, 2048, 2405.0, 2402.0, 1221.0,
                         1027.5, {0.61, -0.35, 0.0005, 0.0009, 0.08, 0.95, -0.21, 0.17});
}
rv::CameraModel fisheye_camera() {
  return rv::make_camera(rv::CameraKind::kFisheyeKB4, 1600, 1200, 520.0, 519.0, 799.2, 601.9,
                         {0.021, -0.0093, 0.0031, -0.0006});
}

// Points in front of the camera within a cone of half-angle `max_angle` (radians).
std::vector<Eigen::Vector3d> random_points(double max_angle, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    const double theta = max_angle * std::sqrt(u(rng));
    const double phi = 2 * M_PI * u(rng);
    const double depth = 0.2 + 3.0 * u(rng);
    pts.emplace_back(depth * std::sin(theta) * std::cos(phi),
                     depth * std::sin(theta) * std::sin(phi), depth * std::cos(theta));
  }
  return pts;
}

std::vector<cv::Point2d> opencv_project(const rv::CameraModel& cam,
                                        const std::vector<Eigen::Vector3d>& pts) {
  std::vector<cv::Point3d> obj;
  for (const auto& p : pts) obj.emplace_back(p.x(), p.y(), p.z());
  const cv::Matx33d K(cam.params[0], 0, cam.params[2], 0, cam.params[1], cam.params[3], 0, 0, 1);
  std::vector<double> dist(cam.params.begin() + 4, cam.params.end());
  const cv::Vec3d zero(0, 0, 0);
  std::vector<cv::Point2d> out;
  if (cam.kind == rv::CameraKind::kFisheyeKB4) {
    cv::fisheye::projectPoints(obj, out, zero, zero, K, dist);
  } else {
    cv::projectPoints(obj, zero, zero, K, dist, out);
  }
  return out;
}

void expect_matches_opencv(const rv::CameraModel& cam, double max_angle) {
  const auto pts = random_points(max_angle, 500, 7);
  const auto cv_px = opencv_project(cam, pts);
  double worst = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const auto px = rv::project(cam, pts[i]);
    ASSERT_TRUE(px.has_value());
    worst = std::max(worst, (*px - Eigen::Vector2d(cv_px[i].x, cv_px[i].y)).norm());
  }
  EXPECT_LT(worst, 1e-9) << rv::kind_name(cam.kind);
}

void expect_round_trip(const rv::CameraModel& cam) {
  double worst = 0;
  int checked = 0;
  for (double v = -0.5; v <= cam.height - 0.5; v += cam.height / 23.0) {
    for (double u = -0.5; u <= cam.width - 0.5; u += cam.width / 31.0) {
      const Eigen::Vector2d px(u, v);
      const auto ray = rv::unproject(cam, px);
      ASSERT_TRUE(ray.has_value()) << u << " " << v;
      EXPECT_NEAR(ray->norm(), 1.0, 1e-14);
      const auto back = rv::project(cam, *ray * 1.7);
      ASSERT_TRUE(back.has_value());
      worst = std::max(worst, (*back - px).norm());
      ++checked;
    }
  }
  EXPECT_GT(checked, 500);
  EXPECT_LT(worst, 1e-9) << rv::kind_name(cam.kind);
  // And the other way round: point -> pixel -> ray is parallel to the point.
  for (const auto& p : random_points(0.6, 200, 3)) {
    const auto px = rv::project(cam, p);
    ASSERT_TRUE(px.has_value());
    const auto ray = rv::unproject(cam, *px);
    ASSERT_TRUE(ray.has_value());
    EXPECT_LT((*ray - p.normalized()).norm(), 1e-11);
  }
}

void expect_jacobians_match_numeric(const rv::CameraModel& cam) {
  for (const auto& p : random_points(0.6, 40, 11)) {
    Eigen::Vector2d px;
    Eigen::Matrix<double, 2, 3> d_point;
    Eigen::MatrixXd d_params;
    ASSERT_TRUE(rv::project_jacobians(cam, p, &px, &d_point, &d_params));
    EXPECT_LT((px - *rv::project(cam, p)).norm(), 1e-12);
    for (int c = 0; c < 3; ++c) {
      const double h = 1e-6 * std::max(1.0, std::abs(p[c]));
      Eigen::Vector3d a = p, b = p;
      a[c] += h;
      b[c] -= h;
      const Eigen::Vector2d num = (*rv::project(cam, a) - *rv::project(cam, b)) / (2 * h);
      EXPECT_LT((num - d_point.col(c)).norm(), 1e-5 * (1 + num.norm())) << "point " << c;
    }
    for (int c = 0; c < static_cast<int>(cam.params.size()); ++c) {
      const double h = 1e-6 * std::max(1.0, std::abs(cam.params[static_cast<size_t>(c)]));
      rv::CameraModel a = cam, b = cam;
      a.params[static_cast<size_t>(c)] += h;
      b.params[static_cast<size_t>(c)] -= h;
      const Eigen::Vector2d num = (*rv::project(a, p) - *rv::project(b, p)) / (2 * h);
      EXPECT_LT((num - d_params.col(c)).norm(), 1e-5 * (1 + num.norm())) << "param " << c;
    }
  }
}

}  // namespace

TEST(CameraModel, RadtanMatchesOpenCV) {
  expect_matches_opencv(radtan_camera(), 0.6);
}
TEST(CameraModel, RationalMatchesOpenCV) {
  expect_matches_opencv(rational_camera(), 0.6);
}
TEST(CameraModel, FisheyeMatchesOpenCV) {
  expect_matches_opencv(fisheye_camera(), 1.4);
}

TEST(CameraModel, RadtanRoundTrip) {
  expect_round_trip(radtan_camera());
}
TEST(CameraModel, RationalRoundTrip) {
  expect_round_trip(rational_camera());
}
TEST(CameraModel, FisheyeRoundTrip) {
  expect_round_trip(fisheye_camera());
}

TEST(CameraModel, FisheyeBeyondNinetyDegrees) {
  const auto cam = fisheye_camera();
  const Eigen::Vector3d p(1.0, 0.5, -0.2);  // 96 degrees off axis
  const auto px = rv::project(cam, p);
  ASSERT_TRUE(px.has_value());
  const auto ray = rv::unproject(cam, *px);
  ASSERT_TRUE(ray.has_value());
  EXPECT_LT((*ray - p.normalized()).norm(), 1e-11);
}

TEST(CameraModel, PinholeRejectsPointsBehind) {
  EXPECT_FALSE(rv::project(radtan_camera(), Eigen::Vector3d(0.1, 0.1, -1.0)).has_value());
  EXPECT_FALSE(rv::project(radtan_camera(), Eigen::Vector3d(0.1, 0.1, 0.0)).has_value());
}

TEST(CameraModel, JacobiansMatchNumeric) {
  expect_jacobians_match_numeric(radtan_camera());
  expect_jacobians_match_numeric(rational_camera());
  expect_jacobians_match_numeric(fisheye_camera());
}

TEST(CameraModel, FisheyeJacobianOnAxisIsFinite) {
  Eigen::Matrix<double, 2, 3> d_point;
  ASSERT_TRUE(rv::project_jacobians(fisheye_camera(), Eigen::Vector3d(0, 0, 2), nullptr, &d_point,
                                    nullptr));
  EXPECT_TRUE(d_point.allFinite());
  EXPECT_NEAR(d_point(0, 0), 520.0 / 2, 1e-9);
}

TEST(CameraModel, KindNamesRoundTrip) {
  for (auto k : {rv::CameraKind::kPinholeRadtan, rv::CameraKind::kPinholeRational,
                 rv::CameraKind::kFisheyeKB4})
    EXPECT_EQ(rv::kind_from_name(rv::kind_name(k)), k);
  EXPECT_FALSE(rv::kind_from_name("pinhole").has_value());
  EXPECT_EQ(rv::num_params(rv::CameraKind::kPinholeRational), 12);
}

TEST(CameraFile, SaveLoadIsExact) {
  for (const auto& cam : {radtan_camera(), rational_camera(), fisheye_camera()}) {
    const auto path = std::filesystem::temp_directory_path() / "robocal_test_camera.yaml";
    rv::save_camera_file(cam, path, "test");
    const auto back = rv::load_camera_file(path);
    EXPECT_EQ(back.kind, cam.kind);
    EXPECT_EQ(back.width, cam.width);
    EXPECT_EQ(back.height, cam.height);
    EXPECT_EQ(back.params, cam.params);
    std::filesystem::remove(path);
  }
}

namespace {
std::string error_of(const std::string& text) {
  try {
    rv::parse_camera_yaml(text, "cam.yaml");
  } catch (const rv::FileFormatError& e) {
    return e.what();
  }
  return "no error";
}
}  // namespace

TEST(CameraFile, ErrorsNameFileAndLine) {
  const std::string head = "model: pinhole_radtan\nwidth: 640\nheight: 480\n";
  EXPECT_EQ(error_of(head + "fx: 500\nfy: 500\ncx: 320\ncy: 240\ndistortion: [0, 0, 0, 0]\n"),
            "cam.yaml:8: pinhole_radtan needs 5 distortion coefficients, got 4");
  EXPECT_EQ(error_of(head + "fx: -5\nfy: 500\ncx: 320\ncy: 240\ndistortion: [0,0,0,0,0]\n"),
            "cam.yaml:4: fx must be positive");
  EXPECT_EQ(error_of(head + "fx: abc\nfy: 500\ncx: 320\ncy: 240\ndistortion: [0,0,0,0,0]\n"),
            "cam.yaml:4: 'fx' must be a number (got 'abc')");
  EXPECT_EQ(error_of("model: pinhole\n"),
            "cam.yaml:1: unknown camera model 'pinhole' (expected pinhole_radtan, "
            "pinhole_rational or fisheye_kb4)");
  EXPECT_EQ(error_of(head + "fy: 500\ncx: 320\ncy: 240\ndistortion: [0,0,0,0,0]\n"),
            "cam.yaml:1: missing required key 'fx'");
  EXPECT_EQ(error_of(head + "fx: 1\nfy: 1\ncx: 1\ncy: 1\ndistortion: [0,0,0,0,0]\nfz: 3\n"),
            "cam.yaml:9: unknown key 'fz' (allowed: model, width, height, fx, fy, cx, cy, "
            "distortion, pixel_convention, name, calibration)");
  EXPECT_NE(error_of("model: [pinhole\n").find("cam.yaml:"), std::string::npos);
  EXPECT_EQ(error_of(""), "cam.yaml: a camera file must be a YAML mapping (model, width, ...)");
  try {
    rv::load_camera_file("/nonexistent/cam.yaml");
    FAIL();
  } catch (const rv::FileFormatError& e) {
    EXPECT_EQ(std::string(e.what()),
              "/nonexistent/cam.yaml: cannot open file (No such file or directory)");
  }
}

TEST(CameraModel, WarmStartedUnprojectionAgrees) {
  const auto cam = rational_camera();
  const Eigen::Vector2d a(2000.0, 1900.0), b(2001.0, 1900.0);
  const auto ra = rv::unproject(cam, a);
  ASSERT_TRUE(ra.has_value());
  const auto cold = rv::unproject(cam, b);
  const auto warm = rv::unproject(cam, b, *ra);
  ASSERT_TRUE(cold.has_value());
  ASSERT_TRUE(warm.has_value());
  EXPECT_LT((*cold - *warm).norm(), 1e-13);
}

// Two distortion-free pinholes differing only in fx: a ray through reference pixel (u, v) lands
// at u' = cx + (fx'/fx)(u − cx), so the RMS difference over the 11 × 11 grid is
// |fx'/fx − 1| · RMS(u − cx), written out here.
TEST(CameraModel, ProjectionDifferenceOfTwoFocalLengthsIsTheClosedForm) {
  const auto reference =
      rv::make_camera(rv::CameraKind::kPinholeRadtan, 640, 480, 600.0, 600.0, 319.5, 239.5);
  auto other = reference;
  other.params[0] = 606.0;  // fx 1 % longer
  double sum = 0.0;
  for (int j = 0; j <= 10; ++j)
    for (int i = 0; i <= 10; ++i) {
      const double u = i * 639.0 / 10.0;
      sum += std::pow(0.01 * (u - 319.5), 2);
    }
  EXPECT_NEAR(rv::projection_difference_px(other, reference), std::sqrt(sum / 121.0), 1e-9);
  EXPECT_NEAR(rv::projection_difference_px(reference, reference), 0.0, 1e-9);
}
