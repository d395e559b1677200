// Vision accuracy and speed bench: prints one JSON document.
//   corner_accuracy: rendered boards over tilt / blur / noise, RMS, mean (dx, dy) and radial bias
//     for AprilTag with our refinement, AprilTag 3.3 alone (same detections), chessboard
//     (findChessboardCorners + cornerSubPix) and ChArUco (our corrected pipeline).
//   detection_time: 2448x2048, 60 tags: ours vs bare apriltag_detector_detect (same options).
//   intrinsics: 30 rendered views x trials: ours vs cv::calibrateCamera on the same detections.
//   real_rct_charuco: ours vs OpenCV's own ChArUco calibration on the real images (informative).
// Usage: bench_vision_accuracy [--trials N] [--quick] [--only nominal|sweep|timing|intrinsics|real]
//                              [--corners detected|detected_unweighted|truth_iid]
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <random>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "board_views.hpp"
#include "robocal/core/random_draws.hpp"
#include "robocal/vision/camera_io.hpp"
#include "robocal/vision/intrinsic_calibration.hpp"
#include "robocal/vision/target_detection.hpp"
#include "synthetic_tags.hpp"

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}

namespace rv = robocal::vision;
namespace rt = robocal::testing;
using nlohmann::json;

namespace {

struct Accumulator {
  double sq = 0.0;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  double radial = 0.0;
  long n = 0;
  long expected = 0;

  void add(const Eigen::Vector2d& e, const Eigen::Vector2d& outward) {
    sq += e.squaredNorm();
    sum += e;
    radial += e.dot(outward);
    ++n;
  }
  [[nodiscard]] json to_json() const {
    if (n == 0) return {{"corners", 0}, {"expected_corners", expected}};
    return {{"corners", n},
            {"expected_corners", expected},
            {"rms_px", std::sqrt(sq / static_cast<double>(n))},
            {"bias_dx_px", sum.x() / static_cast<double>(n)},
            {"bias_dy_px", sum.y() / static_cast<double>(n)},
            {"radial_bias_px", radial / static_cast<double>(n)}};
  }
};

// Outward direction of a corner from its tag / square centre (board frame, mapped to image).
Eigen::Vector2d outward(const rv::TargetBoard& board, const Eigen::Matrix3d& h, int id,
                        const Eigen::Vector3d& p) {
  Eigen::Vector2d centre;
  if (board.spec.kind == rv::TargetKind::kAprilTagGrid) {
    const rv::TargetMarker* m = nullptr;
    for (const auto& mk : board.markers)
      if (mk.id == id / 4) m = &mk;
    centre = ((m->corners[0] + m->corners[1] + m->corners[2] + m->corners[3]) / 4).head<2>();
  } else {
    // Inner chessboard corners: "radial" is away from the board centre.
    centre = (board.extent_min + board.extent_max) / 2;
  }
  const Eigen::Vector2d a = rt::apply_h(h, p.head<2>());
  const Eigen::Vector2d c = rt::apply_h(h, centre);
  return (a - c).normalized();
}

void accumulate(const rv::TargetBoard& board, const rt::BoardView& v,
                const rv::TargetDetection& det, Accumulator& acc) {
  for (size_t i = 0; i < det.pixels.size(); ++i) {
    const Eigen::Vector2d truth = rt::apply_h(v.h, det.board_points[i].head<2>());
    acc.add(det.pixels[i] - truth, outward(board, v.h, det.corner_ids[i], det.board_points[i]));
  }
}

int visible_corners(const rv::TargetBoard& board, const rt::SyntheticCamera& cam,
                    const Eigen::Matrix3d& h) {
  int n = 0;
  for (const auto& c : board.corners) {
    const Eigen::Vector2d p = rt::apply_h(h, c.point.head<2>());
    n += (p.x() > 10 && p.y() > 10 && p.x() < cam.width - 10 && p.y() < cam.height - 10) ? 1 : 0;
  }
  return n;
}

struct Methods {
  Accumulator ours, library, chess, charuco;
};

// One condition: AprilTag board, chessboard and ChArUco rendered with the same pose and image
// settings; AprilTag-3.3-alone uses the library corners of the same detections.
void run_condition(const rt::SyntheticCamera& cam, double dist, double tilt, double blur,
                   double noise, int views, unsigned seed, const rv::TargetBoard& tags,
                   const rv::TargetBoard& chess, const rv::TargetBoard& charuco,
                   rv::AprilTagDetector& detector, Methods& m) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < views; ++k) {
    const double axis = 180.0 * u(rng);
    const double roll = 15.0 * u(rng);
    const double cu = cam.cx + 0.05 * cam.width * u(rng);
    const double cv_ = cam.cy + 0.05 * cam.height * u(rng);
    const unsigned s = seed * 100 + static_cast<unsigned>(k);
    {
      const rt::BoardView v =
          rt::render_board_view(tags, cam, dist, tilt, axis, roll, cu, cv_, blur, noise, s);
      const auto det = rv::detect_apriltag_board(v.image, tags, detector);
      m.ours.expected += visible_corners(tags, cam, v.h);
      m.library.expected += visible_corners(tags, cam, v.h);
      accumulate(tags, v, det, m.ours);
      // Same detections, the library's corners.
      const auto lib = detector.detect_library_only(v.image);
      rv::TargetDetection libdet;
      for (const auto& t : lib) {
        for (size_t c = 0; c < 4; ++c) {
          const auto p = rv::corner_point(tags, t.id * 4 + static_cast<int>(c));
          if (!p) continue;
          libdet.corner_ids.push_back(t.id * 4 + static_cast<int>(c));
          libdet.board_points.push_back(*p);
          libdet.pixels.push_back(t.corners[c]);
        }
      }
      accumulate(tags, v, libdet, m.library);
    }
    {
      const rt::BoardView v =
          rt::render_board_view(chess, cam, dist, tilt, axis, roll, cu, cv_, blur, noise, s + 7);
      m.chess.expected += visible_corners(chess, cam, v.h);
      accumulate(chess, v, rv::detect_chessboard_board(v.image, chess), m.chess);
    }
    {
      const rt::BoardView v =
          rt::render_board_view(charuco, cam, dist, tilt, axis, roll, cu, cv_, blur, noise, s + 13);
      m.charuco.expected += visible_corners(charuco, cam, v.h);
      accumulate(charuco, v, rv::detect_charuco_board(v.image, charuco), m.charuco);
    }
  }
}

json methods_json(const Methods& m) {
  return {{"apriltag_ours", m.ours.to_json()},
          {"apriltag_3.3_alone", m.library.to_json()},
          {"chessboard_cornersubpix", m.chess.to_json()},
          {"charuco_ours", m.charuco.to_json()}};
}

double min_ms(const std::function<void()>& f, int reps) {
  std::vector<double> t;
  for (int i = 0; i < reps; ++i) {
    const auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
  }
  // The minimum: the machine is shared, and load only ever adds time.
  return *std::min_element(t.begin(), t.end());
}

json detection_time() {
  const rt::SyntheticCamera cam{2448, 2048, 2300.0, 1223.5, 1023.5};
  const auto board = rt::apriltag_grid_board(10, 6, 0.03);  // 60 tags, ~70 px at 0.9 m
  const rt::BoardView v =
      rt::render_board_view(board, cam, 0.9, 25.0, 30.0, 5.0, cam.cx, cam.cy, 0.8, 2.0, 5);
  json out = json::array();
  for (int threads : {1, 2}) {
    rv::AprilTagDetectorOptions opt;
    opt.threads = threads;
    rv::AprilTagDetector detector(opt);
    size_t found = 0;
    const double ours = min_ms([&] { found = detector.detect(v.image).size(); }, 7);
    // Bare library call with identical settings on the same image.
    apriltag_family_t* fam = tag36h11_create();
    apriltag_detector_t* td = apriltag_detector_create();
    apriltag_detector_add_family_bits(td, fam, opt.max_hamming);
    td->quad_decimate = opt.quad_decimate;
    td->nthreads = threads;
    td->refine_edges = opt.refine_edges;
    td->decode_sharpening = opt.decode_sharpening;
    image_u8_t im{v.image.cols, v.image.rows, static_cast<int32_t>(v.image.step[0]), v.image.data};
    // The bare call's best time of 7 and the tags it found.
    const auto bare_call = [&](int& tags) {
      return min_ms(
          [&] {
            zarray_t* d = apriltag_detector_detect(td, &im);
            tags = zarray_size(d);
            apriltag_detections_destroy(d);
          },
          7);
    };
    int bare_found = 0;
    const double bare = bare_call(bare_found);
    // The same bare call with the quad-search threshold ours takes from the image's noise.
    td->qtp.min_white_black_diff =
        rv::min_white_black_diff_for(rv::pixel_noise_sigma(v.image), opt.min_decision_margin);
    int noise_found = 0;
    const double bare_noise = bare_call(noise_found);
    apriltag_detector_destroy(td);
    tag36h11_destroy(fam);
    out.push_back({{"image", "2448x2048"},
                   {"tags", found},
                   {"bare_tags", bare_found},
                   {"decimate", opt.quad_decimate},
                   {"threads", threads},
                   {"ours_ms", ours},
                   {"bare_apriltag_ms", bare},
                   {"bare_apriltag_noise_threshold_ms", bare_noise},
                   {"bare_noise_threshold_tags", noise_found},
                   {"quad_search_ratio_noise_threshold_vs_library_default", bare_noise / bare},
                   {"ours_vs_bare_library_default", ours / bare}});
  }
  return out;
}

// Error statistics of detected corners against the truth, per tag: the mean and radial bias,
// and how the errors of a tag's four corners are correlated. Corners k and k+1 of a tag lie on
// the same fitted edge; the components of their errors along that edge's normal are compared.
// `centroid_variance_ratio` is var(tag centroid error) / (var(corner error) / 4): 1 for
// independent corners, larger when corners of one tag move together.
struct CornerErrorStats {
  Accumulator all;
  double edge_nn = 0.0, edge_n1 = 0.0, edge_n2 = 0.0;  // sum e_k.n e_{k+1}.n, e_k.n ^2, ...
  double opposite = 0.0;  // sum of products of the normal components of opposite corners
  double centroid_sq = 0.0, corner_sq = 0.0;
  long tags = 0;
  long gross_tags = 0;  // tags with a corner error > 0.1 px (left out of the statistics above)
  double predicted_sq = 0.0;  // trace of the predicted corner covariance (refined tags)
  double whitened_sq = 0.0;   // e^T C^-1 e over tags with a predicted covariance
  long predicted_tags = 0;

  void add_tag(const std::array<Eigen::Vector2d, 4>& err, const std::array<Eigen::Vector2d, 4>& px,
               const std::array<Eigen::Vector2d, 4>& outward, const Eigen::MatrixXd* cov) {
    for (const auto& e : err) {
      if (e.norm() > 0.1) {
        ++gross_tags;
        return;
      }
    }
    if (cov != nullptr && cov->rows() == 8) {
      Eigen::Matrix<double, 8, 1> e8;
      for (int k = 0; k < 4; ++k) e8.segment<2>(2 * k) = err[static_cast<size_t>(k)];
      predicted_sq += cov->trace();
      whitened_sq += e8.dot(cov->ldlt().solve(e8));
      ++predicted_tags;
    }
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (size_t k = 0; k < 4; ++k) {
      all.add(err[k], outward[k]);
      mean += err[k] / 4.0;
      corner_sq += err[k].squaredNorm();
    }
    centroid_sq += mean.squaredNorm();
    for (size_t k = 0; k < 4; ++k) {
      const Eigen::Vector2d d = (px[(k + 1) % 4] - px[k]).normalized();
      const Eigen::Vector2d n(-d.y(), d.x());
      const double a = err[k].dot(n);
      const double b = err[(k + 1) % 4].dot(n);
      edge_nn += a * b;
      edge_n1 += a * a;
      edge_n2 += b * b;
      opposite += err[k].dot(err[(k + 2) % 4]) / 2.0;
    }
    ++tags;
  }
  [[nodiscard]] json to_json() const {
    json j = all.to_json();
    j["tags"] = tags;
    j["tags_with_a_corner_error_over_0.1px"] = gross_tags;
    if (predicted_tags > 0) {
      // Predicted (edge-fit propagation) vs actual per-axis corner RMS, and the mean whitened
      // squared error per tag (expectation 8 when the predicted covariance is right).
      j["predicted_corner_rms_px"] = std::sqrt(predicted_sq / (8.0 * predicted_tags));
      j["whitened_tag_error_sq_mean"] = whitened_sq / static_cast<double>(predicted_tags);
    }
    j["same_edge_normal_correlation"] = edge_nn / std::sqrt(edge_n1 * edge_n2);
    j["opposite_corner_correlation"] = opposite / (corner_sq / 4.0 * 2.0) * 2.0 / 2.0;
    j["centroid_variance_ratio"] =
        (centroid_sq / static_cast<double>(tags)) / (corner_sq / (4.0 * tags) / 4.0);
    return j;
  }
};

json intrinsics_trials(int trials, const std::string& corner_source) {
  const rt::SyntheticCamera cam{1280, 1024, 1200.0, 639.5, 511.5};
  const auto board = rt::apriltag_grid_board(8, 6, 0.03);
  rv::AprilTagDetector detector;
  const rv::CameraModel truth = rv::make_camera(rv::CameraKind::kPinholeRadtan, cam.width,
                                                cam.height, cam.f, cam.f, cam.cx, cam.cy);
  std::vector<double> ours_f, ours_c, cv_f, cv_c, ours_proj, cv_proj, z_fx, z_fy, z_cx, z_cy;
  std::vector<double> err_fx, err_fy, err_cx, err_cy;
  json per_trial = json::array();
  CornerErrorStats corner_stats;
  // truth_iid: the detector's corners replaced by the truth plus independent Gaussian noise of
  // the detector's measured per-axis RMS error (same corner ids): the estimator alone.
  const double iid_sigma = 0.016;
  std::mt19937 noise_rng(77);
  std::normal_distribution<double> noise(0.0, iid_sigma);
  for (int trial = 0; trial < trials; ++trial) {
    std::mt19937 rng(1000 + static_cast<unsigned>(trial));
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<rv::CalibrationView> views;
    std::vector<std::vector<cv::Point3f>> obj;
    std::vector<std::vector<cv::Point2f>> img;
    for (int k = 0; k < 30; ++k) {
      const double tilt = 10.0 + 40.0 * std::abs(u(rng));
      // One draw a statement, last argument first (robocal/core/random_draws.hpp says why).
      const double aim_v = cam.cy + 0.3 * cam.height * u(rng);
      const double aim_u = cam.cx + 0.3 * cam.width * u(rng);
      const double roll_deg = 20.0 * u(rng);
      const double axis_deg = 180.0 * u(rng);
      const double dist = 0.45 + 0.15 * std::abs(u(rng));
      const rt::BoardView v =
          rt::render_board_view(board, cam, dist, tilt, axis_deg, roll_deg, aim_u, aim_v, 0.8, 2.0,
                                static_cast<unsigned>(trial * 100 + k));
      const auto det = rv::detect_apriltag_board(v.image, board, detector);
      if (det.status == rv::DetectionStatus::kRejected || det.pixels.size() < 16) continue;
      views.push_back(rv::to_calibration_view(det, fmt::format("v{}", k)));
      for (size_t i = 0; i + 3 < det.pixels.size(); i += 4) {
        std::array<Eigen::Vector2d, 4> e, px, out;
        for (size_t c = 0; c < 4; ++c) {
          const Eigen::Vector2d truth_px = rt::apply_h(v.h, det.board_points[i + c].head<2>());
          e[c] = det.pixels[i + c] - truth_px;
          px[c] = truth_px;
          out[c] = outward(board, v.h, det.corner_ids[i + c], det.board_points[i + c]);
          if (corner_source == "truth_iid")
            views.back().pixels[i + c] = truth_px + robocal::core::draw_vector2(noise, noise_rng);
        }
        const Eigen::MatrixXd* cov = nullptr;
        for (const auto& g : det.corner_groups)
          if (!g.corner_ids.empty() && g.corner_ids.front() == det.corner_ids[i])
            cov = &g.covariance;
        corner_stats.add_tag(e, px, out, cov);
      }
      // truth_iid / detected_unweighted: no corner covariances (independent, equal weights).
      if (corner_source != "detected") views.back().corner_groups.clear();
      const auto& det_px = views.back().pixels;
      std::vector<cv::Point3f> o;
      std::vector<cv::Point2f> p;
      for (size_t i = 0; i < det.pixels.size(); ++i) {
        o.emplace_back(static_cast<float>(det.board_points[i].x()),
                       static_cast<float>(det.board_points[i].y()), 0.0f);
        p.emplace_back(static_cast<float>(det_px[i].x()), static_cast<float>(det_px[i].y()));
      }
      obj.push_back(o);
      img.push_back(p);
    }
    rv::IntrinsicCalibrationOptions opt;
    opt.width = cam.width;
    opt.height = cam.height;
    const auto res = rv::calibrate_intrinsics(views, opt);
    if (res.status != rv::CalibrationStatus::kOk) continue;
    cv::Mat k;
    cv::Mat dist;
    std::vector<cv::Mat> rvecs;
    std::vector<cv::Mat> tvecs;
    const double cv_rms =
        cv::calibrateCamera(obj, img, cv::Size(cam.width, cam.height), k, dist, rvecs, tvecs);
    const rv::CameraModel cvcam =
        rv::make_camera(rv::CameraKind::kPinholeRadtan, cam.width, cam.height, k.at<double>(0, 0),
                        k.at<double>(1, 1), k.at<double>(0, 2), k.at<double>(1, 2),
                        {dist.at<double>(0), dist.at<double>(1), dist.at<double>(2),
                         dist.at<double>(3), dist.at<double>(4)});
    auto proj_rms = [&](const rv::CameraModel& m) {
      double sq = 0.0;
      int n = 0;
      for (int r = 0; r <= 8; ++r)
        for (int c = 0; c <= 10; ++c) {
          const Eigen::Vector2d px(c * (cam.width - 1) / 10.0, r * (cam.height - 1) / 8.0);
          const auto ray = rv::unproject(truth, px);
          const auto q = rv::project(m, *ray / ray->z());  // 3-D point at 1 m depth
          if (!q) continue;
          sq += (*q - px).squaredNorm();
          ++n;
        }
      return std::sqrt(sq / std::max(1, n));
    };
    const auto& p = res.camera.params;
    const double of = 0.5 * (std::abs(p[0] - cam.f) + std::abs(p[1] - cam.f));
    const double oc = 0.5 * (std::abs(p[2] - cam.cx) + std::abs(p[3] - cam.cy));
    const double cf = 0.5 * (std::abs(cvcam.params[0] - cam.f) + std::abs(cvcam.params[1] - cam.f));
    const double cc =
        0.5 * (std::abs(cvcam.params[2] - cam.cx) + std::abs(cvcam.params[3] - cam.cy));
    ours_f.push_back(of);
    ours_c.push_back(oc);
    cv_f.push_back(cf);
    cv_c.push_back(cc);
    ours_proj.push_back(proj_rms(res.camera));
    cv_proj.push_back(proj_rms(cvcam));
    z_fx.push_back((p[0] - cam.f) / res.param_stddev[0]);
    z_fy.push_back((p[1] - cam.f) / res.param_stddev[1]);
    z_cx.push_back((p[2] - cam.cx) / res.param_stddev[2]);
    z_cy.push_back((p[3] - cam.cy) / res.param_stddev[3]);
    err_fx.push_back(p[0] - cam.f);
    err_fy.push_back(p[1] - cam.f);
    err_cx.push_back(p[2] - cam.cx);
    err_cy.push_back(p[3] - cam.cy);
    per_trial.push_back({{"views", views.size()},
                         {"ours_rms_px", res.rms_px},
                         {"opencv_rms_px", cv_rms},
                         {"ours_fx", p[0]},
                         {"ours_sigma_fx", res.param_stddev[0]},
                         {"opencv_fx", cvcam.params[0]},
                         {"ours_cx", p[2]},
                         {"ours_sigma_cx", res.param_stddev[2]},
                         {"opencv_cx", cvcam.params[2]}});
  }
  auto mean = [](const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? NAN : s / static_cast<double>(v.size());
  };
  auto rms = [](const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x * x;
    return v.empty() ? NAN : std::sqrt(s / static_cast<double>(v.size()));
  };
  return {
      {"truth", {{"f", cam.f}, {"cx", cam.cx}, {"cy", cam.cy}, {"distortion", "none"}}},
      {"trials", ours_f.size()},
      {"views_per_trial", 30},
      {"ours_mean_abs_focal_error_px", mean(ours_f)},
      {"opencv_mean_abs_focal_error_px", mean(cv_f)},
      {"ours_mean_abs_principal_point_error_px", mean(ours_c)},
      {"opencv_mean_abs_principal_point_error_px", mean(cv_c)},
      {"ours_projection_rms_vs_truth_px", mean(ours_proj)},
      {"opencv_projection_rms_vs_truth_px", mean(cv_proj)},
      {"corner_source", corner_source},
      {"detected_corner_errors", corner_stats.to_json()},
      {"mean_signed_error_px",
       {{"fx", mean(err_fx)}, {"fy", mean(err_fy)}, {"cx", mean(err_cx)}, {"cy", mean(err_cy)}}},
      {"rms_error_px",
       {{"fx", rms(err_fx)}, {"fy", rms(err_fy)}, {"cx", rms(err_cx)}, {"cy", rms(err_cy)}}},
      {"fx_error_over_predicted_sigma_rms", rms(z_fx)},
      {"fy_error_over_predicted_sigma_rms", rms(z_fy)},
      {"cx_error_over_predicted_sigma_rms", rms(z_cx)},
      {"cy_error_over_predicted_sigma_rms", rms(z_cy)},
      {"per_trial", per_trial}};
}

json real_rct_charuco() {
  const std::filesystem::path dir =
      std::filesystem::path(ROBOCAL_SHARED_DATA_DIR) / "real" / "rct_charuco";
  if (!std::filesystem::exists(dir))
    return {{"skipped", fmt::format("shared data absent: {}", dir.string())}};
  const auto board = rt::rct_charuco_board();
  std::vector<rv::CalibrationView> views;
  std::vector<cv::Mat> cv_corners;
  std::vector<cv::Mat> cv_ids;
  cv::Size size;
  const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_6X6_250);
  const auto cvboard = cv::aruco::CharucoBoard::create(5, 7, 0.036195f, 0.018256f, dict);
  for (int i = 0; i < 16; ++i) {
    const auto img = rv::load_gray_image(dir / "images" / fmt::format("{}.png", i));
    if (!img.error.empty()) continue;
    size = img.gray.size();
    const auto det = rv::detect_charuco_board(img.gray, board);
    if (det.status != rv::DetectionStatus::kRejected)
      views.push_back(rv::to_calibration_view(det, fmt::format("{}", i)));
    // OpenCV's own pipeline, as a user of 4.6 would run it.
    std::vector<std::vector<cv::Point2f>> mc;
    std::vector<int> mid;
    cv::aruco::detectMarkers(img.gray, dict, mc, mid);
    if (mid.empty()) continue;
    cv::Mat cc;
    cv::Mat ci;
    cv::aruco::interpolateCornersCharuco(mc, mid, img.gray, cvboard, cc, ci);
    if (ci.total() >= 4) {
      cv_corners.push_back(cc);
      cv_ids.push_back(ci);
    }
  }
  rv::IntrinsicCalibrationOptions opt;
  opt.width = size.width;
  opt.height = size.height;
  const auto res = rv::calibrate_intrinsics(views, opt);
  json ours = {{"status", res.status == rv::CalibrationStatus::kOk ? "ok" : res.reason},
               {"views_used", std::count_if(res.views.begin(), res.views.end(),
                                            [](const auto& v) { return v.used; })},
               {"rms_px", res.rms_px},
               {"corners_used", res.corners_used},
               {"corners_rejected", res.corners_rejected},
               {"warnings", res.warnings}};
  for (size_t i = 0; i < res.param_names.size() && res.status == rv::CalibrationStatus::kOk; ++i) {
    ours[res.param_names[i]] = {res.camera.params[i], res.param_stddev[i]};
  }
  cv::Mat k;
  cv::Mat d;
  cv::Mat sd_intr;
  cv::Mat sd_extr;
  cv::Mat per_view;
  std::vector<cv::Mat> rv_;
  std::vector<cv::Mat> tv_;
  const double cv_rms = cv::aruco::calibrateCameraCharuco(cv_corners, cv_ids, cvboard, size, k, d,
                                                          rv_, tv_, sd_intr, sd_extr, per_view);
  json opencv = {{"views", cv_corners.size()},
                 {"rms_px", cv_rms},
                 {"fx", {k.at<double>(0, 0), sd_intr.at<double>(0)}},
                 {"fy", {k.at<double>(1, 1), sd_intr.at<double>(1)}},
                 {"cx", {k.at<double>(0, 2), sd_intr.at<double>(2)}},
                 {"cy", {k.at<double>(1, 2), sd_intr.at<double>(3)}},
                 {"k1", d.at<double>(0)},
                 {"k2", d.at<double>(1)},
                 {"p1", d.at<double>(2)},
                 {"p2", d.at<double>(3)},
                 {"k3", d.at<double>(4)},
                 {"note", "OpenCV 4.6 ChArUco corners carry +0.5 px; cx, cy shift by ~+0.5"}};
  return {{"ours", ours},
          {"opencv_calibrateCameraCharuco", opencv},
          {"reference_tool",
           {{"fx", 1352.02747}, {"fy", 1356.14287}, {"cx", 789.67065}, {"cy", 627.2995}}}};
}

}  // namespace

int main(int argc, char** argv) {
  int trials = 20;
  bool quick = false;
  std::string only;  // nominal | sweep | timing | intrinsics | real
  // intrinsics: detected (with the detector's corner covariances) | detected_unweighted |
  // truth_iid (truth + independent noise of the detector's RMS: the estimator alone)
  std::string corner_source = "detected";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--trials") == 0 && i + 1 < argc) trials = std::atoi(argv[++i]);
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--only") == 0 && i + 1 < argc) only = argv[++i];
    if (std::strcmp(argv[i], "--corners") == 0 && i + 1 < argc) corner_source = argv[++i];
  }
  auto want = [&](const std::string& section) { return only.empty() || only == section; };
  json doc;
  // The detector's nominal condition (blur 0.8, noise 2, tilt <= 45) aggregated per resolution.
  json nominal = json::array();
  struct Res {
    rt::SyntheticCamera cam;
    double dist;
  };
  const std::vector<Res> resolutions = {{{1280, 1024, 1200.0, 639.5, 511.5}, 0.6},
                                        {{2448, 2048, 2300.0, 1223.5, 1023.5}, 0.9}};
  const auto tags =
      rt::apriltag_grid_board(10, 8, 0.025);  // tags 50 px (1280) / 64 px (2448) across
  const auto chess = rt::chessboard_board(12, 9, 0.025);
  const auto charuco = rt::charuco_board(12, 9, 0.025, 0.6 * 0.025);
  rv::AprilTagDetector detector;
  for (const auto& r : resolutions) {
    if (!want("nominal")) break;
    Methods m;
    for (double tilt : {0.0, 15.0, 30.0, 45.0}) {
      run_condition(r.cam, r.dist, tilt, 0.8, 2.0, quick ? 1 : 3, static_cast<unsigned>(tilt) + 1,
                    tags, chess, charuco, detector, m);
    }
    json j = methods_json(m);
    j["image"] = fmt::format("{}x{}", r.cam.width, r.cam.height);
    nominal.push_back(j);
  }
  if (want("nominal")) doc["corner_accuracy_nominal"] = nominal;
  // Sweep at 1280x1024.
  json sweep = json::array();
  for (double tilt : {0.0, 30.0, 45.0, 60.0}) {
    for (double blur : {0.0, 0.5, 0.8, 1.5}) {
      for (double noise : {0.0, 2.0, 4.0}) {
        if (!want("sweep") || (quick && (noise != 2.0 || tilt == 30.0))) continue;
        Methods m;
        run_condition(resolutions[0].cam, resolutions[0].dist, tilt, blur, noise, 1,
                      static_cast<unsigned>(tilt * 100 + blur * 10 + noise), tags, chess, charuco,
                      detector, m);
        json j = methods_json(m);
        j["tilt_deg"] = tilt;
        j["blur_sigma_px"] = blur;
        j["noise_sigma_dn"] = noise;
        sweep.push_back(j);
      }
    }
  }
  if (want("sweep")) doc["corner_accuracy_sweep_1280x1024"] = sweep;
  if (want("timing")) doc["detection_time"] = detection_time();
  if (want("intrinsics"))
    doc["intrinsics_30_views"] = intrinsics_trials(quick ? 2 : trials, corner_source);
  if (want("real")) doc["real_rct_charuco"] = real_rct_charuco();
  std::printf("%s\n", doc.dump(2).c_str());
  return 0;
}
