#include "robocal/vision/intrinsic_calibration.hpp"

#include "robocal/vision/camera_parameter_names.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "fit/corner_noise.hpp"
#include "robocal/vision/pose.hpp"

namespace robocal::vision {
namespace {

// Reprojection residual of one board point: projected - observed (px).
template <class Model>
struct ReprojectionCost {
  Eigen::Vector3d board;
  Eigen::Vector2d observed;
  double inv_sigma = 1.0;  // 1: pixel residuals (whitened later as a group)

  template <class T>
  bool operator()(const T* intrinsics, const T* pose, T* residual) const {
    const T p[3] = {T(board.x()), T(board.y()), T(board.z())};
    T q[3];
    ceres::AngleAxisRotatePoint(pose, p, q);
    q[0] += pose[3];
    q[1] += pose[4];
    q[2] += pose[5];
    T pixel[2];
    if (!Model::project(intrinsics, q, pixel)) return false;
    residual[0] = (pixel[0] - T(observed.x())) * T(inv_sigma);
    residual[1] = (pixel[1] - T(observed.y())) * T(inv_sigma);
    return true;
  }
};

using Pose6 = std::array<double, 6>;  // angle-axis, translation

Eigen::Isometry3d to_isometry(const Pose6& p) {
  return pose_from_rvec_tvec({p[0], p[1], p[2]}, {p[3], p[4], p[5]});
}
Pose6 from_isometry(const Eigen::Isometry3d& t) {
  const Eigen::Vector3d r = rvec_of(t);
  return {r.x(), r.y(), r.z(), t.translation().x(), t.translation().y(), t.translation().z()};
}

// Homography board (x, y) -> pixel by normalised DLT (OpenCV, all points, no RANSAC: the
// detections are already verified).
std::optional<Eigen::Matrix3d> view_homography(const CalibrationView& v) {
  std::vector<cv::Point2d> src;
  std::vector<cv::Point2d> dst;
  for (size_t i = 0; i < v.pixels.size(); ++i) {
    src.emplace_back(v.board_points[i].x(), v.board_points[i].y());
    dst.emplace_back(v.pixels[i].x(), v.pixels[i].y());
  }
  const cv::Mat h = cv::findHomography(src, dst, 0);
  if (h.empty()) return std::nullopt;
  Eigen::Matrix3d out;
  cv::cv2eigen(h, out);
  if (!out.allFinite()) return std::nullopt;
  return out;
}

// Zhang's constraints with the principal point fixed at (cx, cy) and zero skew: linear in
// (1/fx^2, 1/fy^2) (the same simplification as OpenCV's initialisation).
std::optional<Eigen::Vector2d> init_focal(const std::vector<Eigen::Matrix3d>& hs, double cx,
                                          double cy) {
  Eigen::MatrixXd a(2 * hs.size(), 2);
  Eigen::VectorXd b(2 * hs.size());
  Eigen::Matrix3d shift;
  shift << 1, 0, -cx, 0, 1, -cy, 0, 0, 1;
  for (size_t i = 0; i < hs.size(); ++i) {
    const Eigen::Matrix3d h = shift * hs[i];
    const Eigen::Vector3d h1 = h.col(0) / h.col(0).norm();
    const Eigen::Vector3d h2 = h.col(1) / h.col(0).norm();
    a.row(static_cast<Eigen::Index>(2 * i)) << h1.x() * h2.x(), h1.y() * h2.y();
    b(static_cast<Eigen::Index>(2 * i)) = -h1.z() * h2.z();
    a.row(static_cast<Eigen::Index>(2 * i + 1)) << h1.x() * h1.x() - h2.x() * h2.x(),
        h1.y() * h1.y() - h2.y() * h2.y();
    b(static_cast<Eigen::Index>(2 * i + 1)) = -(h1.z() * h1.z() - h2.z() * h2.z());
  }
  const Eigen::Vector2d x = a.colPivHouseholderQr().solve(b);
  if (!(x.x() > 0.0) || !(x.y() > 0.0)) return std::nullopt;
  return Eigen::Vector2d(1.0 / std::sqrt(x.x()), 1.0 / std::sqrt(x.y()));
}

// Board pose from a pinhole K without distortion (IPPE: exact for planar targets).
std::optional<Eigen::Isometry3d> init_pose(const CalibrationView& v, double fx, double fy,
                                           double cx, double cy) {
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (size_t i = 0; i < v.pixels.size(); ++i) {
    obj.emplace_back(v.board_points[i].x(), v.board_points[i].y(), 0.0);
    img.emplace_back(v.pixels[i].x(), v.pixels[i].y());
  }
  const cv::Matx33d k(fx, 0, cx, 0, fy, cy, 0, 0, 1);
  cv::Vec3d rvec;
  cv::Vec3d tvec;
  if (!cv::solvePnP(obj, img, k, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE)) {
    return std::nullopt;
  }
  return pose_from_rvec_tvec({rvec[0], rvec[1], rvec[2]}, {tvec[0], tvec[1], tvec[2]});
}

// Angle between the board normal and the line of sight to the board's observed centre.
double view_tilt_deg(const CalibrationView& v, const Eigen::Isometry3d& camera_T_board) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : v.board_points) centre += p;
  centre /= static_cast<double>(v.board_points.size());
  const Eigen::Vector3d c = camera_T_board * centre;
  const Eigen::Vector3d normal = camera_T_board.rotation().col(2);
  return std::acos(std::clamp(std::abs(normal.dot(c.normalized())), 0.0, 1.0)) * 180.0 / M_PI;
}

int region_of(const Eigen::Vector2d& px, int width, int height) {
  const int c = std::clamp(static_cast<int>(3.0 * (px.x() + 0.5) / width), 0, 2);
  const int r = std::clamp(static_cast<int>(3.0 * (px.y() + 0.5) / height), 0, 2);
  return r * 3 + c;
}

struct Observation {
  int view = 0;      // index into the used views
  size_t index = 0;  // index into the view's points
  bool outlier = false;
};

// Typical corner sigma (px) of the grouped corners: the weight of corners in no group, so
// that both kinds share one scale (1 when no view carries group covariances: plain pixels).
double single_corner_sigma(const std::vector<const CalibrationView*>& used) {
  std::vector<double> s;
  for (const auto* v : used)
    for (const auto& g : v->corner_groups)
      if (g.covariance.rows() > 0 && g.covariance.allFinite())
        s.push_back(std::sqrt(std::max(0.0, g.covariance.diagonal().mean())));
  if (s.empty()) return 1.0;
  std::nth_element(s.begin(), s.begin() + static_cast<long>(s.size() / 2), s.end());
  return s[s.size() / 2] > 0.0 ? s[s.size() / 2] : 1.0;
}

// One bundle adjustment over the non-outlier observations. Corners of a CornerGroup form one
// residual block whitened by the group's covariance; other corners are whitened by
// `single_sigma`. The Huber scale is given in px and converted to those units.
ceres::Solver::Summary solve(const std::vector<const CalibrationView*>& used,
                             const std::vector<Observation>& obs, CameraKind kind,
                             std::vector<double>& intrinsics, std::vector<Pose6>& poses,
                             double huber_px, int max_iterations, double single_sigma,
                             ceres::Problem** keep) {
  auto* problem = new ceres::Problem();
  std::vector<std::vector<bool>> use(used.size());
  for (size_t vi = 0; vi < used.size(); ++vi) use[vi].assign(used[vi]->pixels.size(), false);
  for (const auto& o : obs)
    if (!o.outlier) use[static_cast<size_t>(o.view)][o.index] = true;
  visit_camera_kind(kind, [&](auto model) {
    using M = decltype(model);
    using Cost = ceres::AutoDiffCostFunction<ReprojectionCost<M>, 2, M::kNumParams, 6>;
    auto loss = [&] {
      return huber_px > 0.0 ? new ceres::HuberLoss(huber_px / single_sigma) : nullptr;
    };
    for (size_t vi = 0; vi < used.size(); ++vi) {
      const CalibrationView& v = *used[vi];
      const detail::CornerGrouping grouping =
          detail::group_corners(v.corner_ids, use[vi], v.corner_groups);
      for (size_t g = 0; g < grouping.groups.size(); ++g) {
        std::vector<std::unique_ptr<ceres::CostFunction>> corners;
        for (size_t i : grouping.groups[g])
          corners.push_back(
              std::make_unique<Cost>(new ReprojectionCost<M>{v.board_points[i], v.pixels[i]}));
        problem->AddResidualBlock(
            new detail::WhitenedGroupCost(std::move(corners), grouping.whitening[g]), loss(),
            intrinsics.data(), poses[vi].data());
      }
      for (size_t i : grouping.singles) {
        problem->AddResidualBlock(
            new Cost(new ReprojectionCost<M>{v.board_points[i], v.pixels[i], 1.0 / single_sigma}),
            loss(), intrinsics.data(), poses[vi].data());
      }
    }
  });
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_SCHUR;
  options.max_num_iterations = max_iterations;
  // Ceres' defaults (1e-6 function tolerance) stop while the focal length still moves by
  // ~1e-3 px; calibration wants the true minimum.
  options.function_tolerance = 1e-14;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(options, problem, &summary);
  if (keep != nullptr) {
    *keep = problem;
  } else {
    delete problem;
  }
  return summary;
}

}  // namespace

const std::vector<std::string>& image_region_names() {
  static const std::vector<std::string> names = {"top-left",    "top-centre",    "top-right",
                                                 "middle-left", "centre",        "middle-right",
                                                 "bottom-left", "bottom-centre", "bottom-right"};
  return names;
}

IntrinsicCalibrationResult calibrate_intrinsics(const std::vector<CalibrationView>& views,
                                                const IntrinsicCalibrationOptions& options) {
  if (options.width <= 0 || options.height <= 0) {
    throw std::invalid_argument("calibrate_intrinsics: image width and height must be positive");
  }
  if (!options.initial_params.empty() &&
      static_cast<int>(options.initial_params.size()) != num_params(options.kind)) {
    throw std::invalid_argument("calibrate_intrinsics: initial_params has the wrong size");
  }
  IntrinsicCalibrationResult result;
  result.param_names = camera_param_names(options.kind);
  const double w = options.width;
  const double h = options.height;

  // 1. Per-view checks.
  std::vector<const CalibrationView*> used;
  std::vector<size_t> used_index;  // into result.views
  for (const auto& v : views) {
    ViewReport rep;
    rep.name = v.name;
    rep.corners = static_cast<int>(v.pixels.size());
    if (v.pixels.size() != v.board_points.size() || v.corner_ids.size() != v.pixels.size()) {
      rep.rejection = "inconsistent observation arrays";
    } else if (static_cast<int>(v.pixels.size()) < options.min_corners_per_view) {
      rep.rejection =
          fmt::format("only {} corners (need {})", v.pixels.size(), options.min_corners_per_view);
    } else if (std::set<int>(v.corner_ids.begin(), v.corner_ids.end()).size() !=
               v.corner_ids.size()) {
      rep.rejection = "duplicate corner ids";
    } else {
      bool finite = true;
      for (size_t i = 0; i < v.pixels.size(); ++i) {
        finite = finite && v.pixels[i].allFinite() && v.board_points[i].allFinite();
      }
      if (!finite) rep.rejection = "non-finite coordinates";
    }
    result.views.push_back(rep);
    if (rep.rejection.empty()) {
      used.push_back(&v);
      used_index.push_back(result.views.size() - 1);
    }
  }
  auto refuse = [&](std::string reason) {
    result.status = CalibrationStatus::kRefused;
    result.reason = std::move(reason);
    return result;
  };
  if (static_cast<int>(used.size()) < options.min_views) {
    result.advice.push_back(
        fmt::format("capture at least {} views (ideally {}+) of the whole board, tilted ~45 deg "
                    "in different directions, covering the image corners",
                    options.recommended_views, 3 * options.recommended_views));
    return refuse(
        fmt::format("{} usable views; at least {} are needed", used.size(), options.min_views));
  }

  // 2. Initialisation.
  std::vector<Eigen::Matrix3d> hs;
  for (const auto* v : used) {
    if (auto hm = view_homography(*v)) hs.push_back(*hm);
  }
  const double cx0 = (w - 1.0) / 2.0;
  const double cy0 = (h - 1.0) / 2.0;
  double fx0 = std::max(w, h);
  double fy0 = fx0;
  if (const auto f = init_focal(hs, cx0, cy0)) {
    // Near-degenerate (all fronto-parallel) sets give wild values; keep a plausible start.
    if ((*f).minCoeff() > 0.1 * std::max(w, h) && (*f).maxCoeff() < 20.0 * std::max(w, h) &&
        (*f).maxCoeff() < 1.5 * (*f).minCoeff()) {
      fx0 = (*f).x();
      fy0 = (*f).y();
    } else {
      fx0 = fy0 = std::sqrt((*f).x() * (*f).y());
      if (!(fx0 > 0.1 * std::max(w, h)) || !(fx0 < 20.0 * std::max(w, h)))
        fx0 = fy0 = std::max(w, h);
    }
  }
  if (!options.initial_params.empty()) {
    fx0 = options.initial_params[0];
    fy0 = options.initial_params[1];
  }
  const double cx_init = options.initial_params.empty() ? cx0 : options.initial_params[2];
  const double cy_init = options.initial_params.empty() ? cy0 : options.initial_params[3];
  std::vector<Pose6> poses;
  std::vector<const CalibrationView*> posed;
  std::vector<size_t> posed_index;
  int tilted = 0;
  double max_tilt = 0.0;
  for (size_t i = 0; i < used.size(); ++i) {
    auto pose = init_pose(*used[i], fx0, fy0, cx_init, cy_init);
    ViewReport& rep = result.views[used_index[i]];
    if (!pose) {
      rep.rejection = "no pose could be computed (degenerate point layout)";
      continue;
    }
    // The board's printed face points along board -z: it must face the camera. Mirrored
    // observations (a mirror image, or a board seen from behind) fit only with it facing away.
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& p : used[i]->board_points) centre += p;
    centre /= static_cast<double>(used[i]->board_points.size());
    const Eigen::Vector3d c = *pose * centre;
    if (c.z() <= 0.0 || pose->rotation().col(2).dot(c) <= 0.0) {
      rep.rejection = "board seen mirrored or from behind (its printed face points away)";
      continue;
    }
    rep.tilt_deg = view_tilt_deg(*used[i], *pose);
    max_tilt = std::max(max_tilt, rep.tilt_deg);
    if (rep.tilt_deg >= options.good_tilt_deg) ++tilted;
    poses.push_back(from_isometry(*pose));
    posed.push_back(used[i]);
    posed_index.push_back(used_index[i]);
  }
  used = posed;
  used_index = posed_index;
  for (size_t i : used_index) result.views[i].used = true;

  // Coverage of the 3x3 image regions by observed corners.
  std::array<int, 9> region_count{};
  for (const auto* v : used) {
    for (const auto& px : v->pixels)
      ++region_count[static_cast<size_t>(region_of(px, options.width, options.height))];
  }
  for (size_t r = 0; r < 9; ++r) {
    if (region_count[r] == 0) result.uncovered_regions.push_back(image_region_names()[r]);
  }
  if (!result.uncovered_regions.empty()) {
    std::string list;
    for (const auto& n : result.uncovered_regions) list += (list.empty() ? "" : ", ") + n;
    result.advice.push_back("add views with the board in the " + list + " of the image");
  }
  if (static_cast<int>(used.size()) < options.min_views) {
    return refuse(fmt::format("{} usable views after pose checks; at least {} are needed",
                              used.size(), options.min_views));
  }
  if (max_tilt < options.min_max_tilt_deg) {
    result.advice.emplace_back("tilt the board by 30-45 deg about different axes");
    return refuse(fmt::format(
        "all views are nearly fronto-parallel (largest tilt {:.1f} deg < {:.0f}): the focal length "
        "is not observable",
        max_tilt, options.min_max_tilt_deg));
  }
  if (static_cast<int>(result.uncovered_regions.size()) > options.max_uncovered_regions) {
    return refuse(
        fmt::format("corners cover only {} of the 9 image regions: the distortion "
                    "cannot be determined",
                    9 - result.uncovered_regions.size()));
  }
  if (!result.uncovered_regions.empty()) {
    std::string list;
    for (const auto& n : result.uncovered_regions) list += (list.empty() ? "" : ", ") + n;
    result.warnings.push_back("no corners in image regions: " + list +
                              " (the distortion there is extrapolated)");
  }
  if (static_cast<int>(used.size()) < options.recommended_views) {
    result.warnings.push_back(fmt::format("only {} usable views (recommended {}+)", used.size(),
                                          options.recommended_views));
  }
  if (tilted < 3) {
    result.warnings.push_back(fmt::format(
        "only {} views tilted by {:.0f} deg or more: the focal length is weakly determined", tilted,
        options.good_tilt_deg));
    result.advice.emplace_back("add views with the board tilted ~45 deg");
  }

  // 3. Bundle adjustment with outlier rounds.
  const double single_sigma = single_corner_sigma(used);
  CameraModel init = make_camera(options.kind, options.width, options.height, fx0, fy0, cx0, cy0);
  if (!options.initial_params.empty()) init.params = options.initial_params;
  std::vector<double> intrinsics = init.params;
  std::vector<Observation> obs;
  for (size_t vi = 0; vi < used.size(); ++vi) {
    for (size_t k = 0; k < used[vi]->pixels.size(); ++k)
      obs.push_back({static_cast<int>(vi), k, false});
  }
  auto residual_of = [&](const Observation& o) -> std::optional<Eigen::Vector2d> {
    const CalibrationView& v = *used[static_cast<size_t>(o.view)];
    CameraModel cam = init;
    cam.params = intrinsics;
    const auto px =
        project(cam, to_isometry(poses[static_cast<size_t>(o.view)]) * v.board_points[o.index]);
    if (!px) return std::nullopt;
    return Eigen::Vector2d(*px - v.pixels[o.index]);
  };
  for (int round = 0; round < options.max_outlier_rounds; ++round) {
    const auto summary = solve(used, obs, options.kind, intrinsics, poses, options.huber_px,
                               options.max_iterations, single_sigma, nullptr);
    result.iterations += static_cast<int>(summary.iterations.size());
    if (summary.termination_type == ceres::FAILURE) {
      result.status = CalibrationStatus::kFailed;
      result.reason = "bundle adjustment failed: " + summary.message;
      return result;
    }
    // Robust sigma of the residual components of the current inliers (MAD).
    std::vector<double> comps;
    for (const auto& o : obs) {
      if (o.outlier) continue;
      if (const auto r = residual_of(o)) {
        comps.push_back(std::abs(r->x()));
        comps.push_back(std::abs(r->y()));
      }
    }
    if (comps.empty()) break;
    std::nth_element(comps.begin(), comps.begin() + static_cast<long>(comps.size() / 2),
                     comps.end());
    const double sigma = 1.4826 * comps[comps.size() / 2];
    const double limit = std::max(options.min_outlier_px, options.outlier_sigmas * sigma);
    int newly = 0;
    for (auto& o : obs) {
      if (o.outlier) continue;
      const auto r = residual_of(o);
      if (!r || r->norm() > limit) {
        o.outlier = true;
        ++newly;
      }
    }
    if (newly == 0) break;
  }

  // 4. Final plain least squares on the inliers; covariance from its Jacobian.
  ceres::Problem* problem = nullptr;
  const auto summary = solve(used, obs, options.kind, intrinsics, poses, 0.0,
                             options.max_iterations, single_sigma, &problem);
  std::unique_ptr<ceres::Problem> owned(problem);
  result.iterations += static_cast<int>(summary.iterations.size());
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  if (summary.termination_type == ceres::FAILURE || !summary.IsSolutionUsable()) {
    result.status = CalibrationStatus::kFailed;
    result.reason = "bundle adjustment failed: " + summary.message;
    return result;
  }
  if (!result.converged) {
    result.warnings.push_back("bundle adjustment stopped before convergence: " + summary.message);
  }
  result.camera = init;
  result.camera.params = intrinsics;
  if (const std::string bad = validate_camera(result.camera); !bad.empty()) {
    result.status = CalibrationStatus::kFailed;
    result.reason = "calibration produced an invalid camera: " + bad;
    return result;
  }

  int inliers = 0;
  double sq = 0.0;
  std::vector<double> view_sq(used.size(), 0.0);
  std::vector<int> view_n(used.size(), 0);
  for (const auto& o : obs) {
    CornerResidual cr;
    cr.view = static_cast<int>(used_index[static_cast<size_t>(o.view)]);
    const CalibrationView& v = *used[static_cast<size_t>(o.view)];
    cr.corner_id = v.corner_ids[o.index];
    cr.pixel = v.pixels[o.index];
    const auto r = residual_of(o);
    cr.residual = r ? *r : Eigen::Vector2d(NAN, NAN);
    cr.outlier = o.outlier;
    result.residuals.push_back(cr);
    ViewReport& rep = result.views[used_index[static_cast<size_t>(o.view)]];
    if (o.outlier) {
      ++rep.outliers;
      ++result.corners_rejected;
      continue;
    }
    ++inliers;
    sq += r->squaredNorm();
    view_sq[static_cast<size_t>(o.view)] += r->squaredNorm();
    ++view_n[static_cast<size_t>(o.view)];
  }
  result.corners_used = inliers;
  result.rms_px = std::sqrt(sq / std::max(1, inliers));
  const int n_params = static_cast<int>(intrinsics.size()) + 6 * static_cast<int>(used.size());
  const int dof = 2 * inliers - n_params;
  result.residual_sigma_px = dof > 0 ? std::sqrt(sq / dof) : 0.0;
  // chi2 / dof of the weighted fit (whitened residuals): 1 when the corner covariances are
  // right; the parameter covariance is scaled by it (a-posteriori variance factor).
  result.variance_factor = dof > 0 ? 2.0 * summary.final_cost / dof : 1.0;
  std::vector<double> view_rms;
  for (size_t vi = 0; vi < used.size(); ++vi) {
    ViewReport& rep = result.views[used_index[vi]];
    rep.camera_T_board = to_isometry(poses[vi]);
    rep.tilt_deg = view_tilt_deg(*used[vi], rep.camera_T_board);
    rep.rms_px = std::sqrt(view_sq[vi] / std::max(1, view_n[vi]));
    view_rms.push_back(rep.rms_px);
  }
  std::sort(view_rms.begin(), view_rms.end());
  const double median_view_rms = view_rms[view_rms.size() / 2];
  for (size_t vi = 0; vi < used.size(); ++vi) {
    const ViewReport& rep = result.views[used_index[vi]];
    if (rep.rms_px > 3.0 * median_view_rms && rep.rms_px > 0.1) {
      result.warnings.push_back(fmt::format(
          "view {} fits poorly (RMS {:.3f} px vs median {:.3f}): motion blur, a moving robot or "
          "a bent board?",
          rep.name, rep.rms_px, median_view_rms));
    }
  }
  if (result.rms_px > options.high_rms_warning_px) {
    result.warnings.push_back(fmt::format(
        "residual RMS {:.3f} px is high (sharp, flat boards give ~0.1-0.2 px): check focus, board "
        "flatness and motion, or try a richer lens model",
        result.rms_px));
  }
  if (result.corners_rejected > 0.05 * static_cast<double>(obs.size())) {
    result.warnings.push_back(
        fmt::format("{} of {} corners rejected as outliers", result.corners_rejected, obs.size()));
  }

  // Covariance of the intrinsics, scaled by the residual variance (Ceres assumes unit variance).
  const size_t np = intrinsics.size();
  result.param_covariance =
      Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(np), static_cast<Eigen::Index>(np), NAN);
  result.param_stddev.assign(np, NAN);
  {
    ceres::Covariance::Options copt;
    copt.algorithm_type = ceres::DENSE_SVD;
    copt.null_space_rank = -1;
    copt.min_reciprocal_condition_number = 1e-14;
    ceres::Covariance covariance(copt);
    std::vector<std::pair<const double*, const double*>> blocks = {
        {intrinsics.data(), intrinsics.data()}};
    if (covariance.Compute(blocks, problem)) {
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c(np, np);
      covariance.GetCovarianceBlock(intrinsics.data(), intrinsics.data(), c.data());
      const double var = result.variance_factor;
      result.param_covariance = c * var;
      for (size_t i = 0; i < np; ++i) {
        result.param_stddev[i] =
            std::sqrt(std::max(0.0, result.param_covariance(static_cast<Eigen::Index>(i),
                                                            static_cast<Eigen::Index>(i))));
      }
    } else {
      result.warnings.emplace_back("parameter covariance could not be computed (rank deficient)");
    }
  }

  // 5. Coverage and projection-uncertainty map.
  CoverageMap& map = result.coverage;
  map.cols = options.coverage_cols;
  map.rows = options.coverage_rows;
  map.corner_count.assign(static_cast<size_t>(map.cols * map.rows), 0);
  map.projection_sigma_px.assign(static_cast<size_t>(map.cols * map.rows), NAN);
  for (const auto& cr : result.residuals) {
    if (cr.outlier) continue;
    const int c =
        std::clamp(static_cast<int>((cr.pixel.x() + 0.5) / w * map.cols), 0, map.cols - 1);
    const int r =
        std::clamp(static_cast<int>((cr.pixel.y() + 0.5) / h * map.rows), 0, map.rows - 1);
    ++map.corner_count[static_cast<size_t>(r * map.cols + c)];
  }
  const bool have_cov = std::isfinite(result.param_stddev[0]);
  for (int r = 0; r < map.rows && have_cov; ++r) {
    for (int c = 0; c < map.cols; ++c) {
      const Eigen::Vector2d px((c + 0.5) * w / map.cols - 0.5, (r + 0.5) * h / map.rows - 0.5);
      const auto ray = unproject(result.camera, px);
      if (!ray || !(ray->z() > 0)) continue;
      const Eigen::Vector3d point = *ray / ray->z();  // 1 m depth
      Eigen::Vector2d proj;
      Eigen::Matrix<double, 2, 3> dp;
      Eigen::MatrixXd dk;
      if (!project_jacobians(result.camera, point, &proj, &dp, &dk)) continue;
      const Eigen::Matrix2d s = dk * result.param_covariance * dk.transpose();
      map.projection_sigma_px[static_cast<size_t>(r * map.cols + c)] = std::sqrt(s.trace() / 2.0);
    }
  }
  result.status = CalibrationStatus::kOk;
  return result;
}

}  // namespace robocal::vision
