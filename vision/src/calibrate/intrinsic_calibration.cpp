#include "robocal/vision/intrinsic_calibration.hpp"

#include "robocal/vision/camera_parameter_names.hpp"

#include "calibrate/intrinsic_views.hpp"
#include "fit/corner_noise.hpp"
#include "fit/reprojection_cost.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>

namespace robocal::vision {
namespace {

using detail::Pose6;
using detail::UsedViews;

// Intrinsic calibration's way from the board to the camera: blocks (intrinsics,
// camera_T_board).
struct BoardInCamera {
  Eigen::Vector3d board_point;

  template <class T, class Project>
  bool operator()(const T* intrinsics, const T* camera_T_board, Project project) const {
    const T p[3] = {T(board_point.x()), T(board_point.y()), T(board_point.z())};
    T q[3];
    detail::transform_point(camera_T_board, p, q);
    return project(intrinsics, q);
  }
};

struct Observation {
  int view = 0;      // index into the used views
  size_t index = 0;  // index into the view's points
  bool outlier = false;
};

// The bundle adjustment's unknowns and observations.
struct IntrinsicFit {
  CameraModel start;  // the model the intrinsics started from
  std::vector<double> intrinsics;
  std::vector<Observation> obs;
  double single_sigma = 1.0;  // the weight of corners in no CornerGroup
};

void check_options(const IntrinsicCalibrationOptions& options) {
  if (options.width <= 0 || options.height <= 0) {
    throw std::invalid_argument("calibrate_intrinsics: image width and height must be positive");
  }
  if (!options.initial_params.empty() &&
      static_cast<int>(options.initial_params.size()) != num_params(options.kind)) {
    throw std::invalid_argument("calibrate_intrinsics: initial_params has the wrong size");
  }
}

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
ceres::Solver::Summary solve(UsedViews& used, IntrinsicFit& fit, CameraKind kind, double huber_px,
                             int max_iterations, std::unique_ptr<ceres::Problem>* keep) {
  auto problem = std::make_unique<ceres::Problem>();
  std::vector<std::vector<bool>> use(used.views.size());
  for (size_t vi = 0; vi < used.views.size(); ++vi)
    use[vi].assign(used.views[vi]->pixels.size(), false);
  for (const auto& o : fit.obs)
    if (!o.outlier) use[static_cast<size_t>(o.view)][o.index] = true;
  const double single_sigma = fit.single_sigma;
  visit_camera_kind(kind, [&](auto model) {
    using M = decltype(model);
    using Residual = detail::ReprojectionCost<M, BoardInCamera>;
    using Cost = ceres::AutoDiffCostFunction<Residual, 2, M::kNumParams, 6>;
    auto loss = [&] {
      return huber_px > 0.0 ? new ceres::HuberLoss(huber_px / single_sigma) : nullptr;
    };
    for (size_t vi = 0; vi < used.views.size(); ++vi) {
      const CalibrationView& v = *used.views[vi];
      const detail::CornerGrouping grouping =
          detail::group_corners(v.corner_ids, use[vi], v.corner_groups);
      for (size_t g = 0; g < grouping.groups.size(); ++g) {
        std::vector<std::unique_ptr<ceres::CostFunction>> corners;
        for (size_t i : grouping.groups[g])
          corners.push_back(
              std::make_unique<Cost>(new Residual{BoardInCamera{v.board_points[i]}, v.pixels[i]}));
        problem->AddResidualBlock(
            new detail::WhitenedGroupCost(std::move(corners), grouping.whitening[g]), loss(),
            fit.intrinsics.data(), used.poses[vi].data());
      }
      for (size_t i : grouping.singles) {
        problem->AddResidualBlock(new Cost(new Residual{BoardInCamera{v.board_points[i]},
                                                        v.pixels[i], 1.0 / single_sigma}),
                                  loss(), fit.intrinsics.data(), used.poses[vi].data());
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
  ceres::Solve(options, problem.get(), &summary);
  if (keep != nullptr) *keep = std::move(problem);
  return summary;
}

// projected - observed (px) of an observation at the current fit.
std::optional<Eigen::Vector2d> residual_of(const UsedViews& used, const IntrinsicFit& fit,
                                           const Observation& o) {
  const CalibrationView& v = *used.views[static_cast<size_t>(o.view)];
  CameraModel cam = fit.start;
  cam.params = fit.intrinsics;
  const auto px = project(
      cam, detail::to_isometry(used.poses[static_cast<size_t>(o.view)]) * v.board_points[o.index]);
  if (!px) return std::nullopt;
  return Eigen::Vector2d(*px - v.pixels[o.index]);
}

// Refuses (with reason and advice) when the posed views cannot determine the intrinsics;
// otherwise adds the warnings about what they determine weakly. False: refused.
bool judge_view_set(const UsedViews& used, const detail::ViewTilts& tilts,
                    const IntrinsicCalibrationOptions& options,
                    IntrinsicCalibrationResult& result) {
  const auto refuse = [&](std::string reason) {
    result.status = CalibrationStatus::kRefused;
    result.reason = std::move(reason);
    return false;
  };
  if (static_cast<int>(used.views.size()) < options.min_views) {
    return refuse(fmt::format("{} usable views after pose checks; at least {} are needed",
                              used.views.size(), options.min_views));
  }
  if (tilts.max_tilt_deg < options.min_max_tilt_deg) {
    result.advice.emplace_back("tilt the board by 30-45 deg about different axes");
    return refuse(fmt::format(
        "all views are nearly fronto-parallel (largest tilt {:.1f} deg < {:.0f}): the focal length "
        "is not observable",
        tilts.max_tilt_deg, options.min_max_tilt_deg));
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
  if (static_cast<int>(used.views.size()) < options.recommended_views) {
    result.warnings.push_back(fmt::format("only {} usable views (recommended {}+)",
                                          used.views.size(), options.recommended_views));
  }
  if (tilts.tilted < 3) {
    result.warnings.push_back(fmt::format(
        "only {} views tilted by {:.0f} deg or more: the focal length is weakly determined",
        tilts.tilted, options.good_tilt_deg));
    result.advice.emplace_back("add views with the board tilted ~45 deg");
  }
  return true;
}

// Outlier rounds with intrinsic calibration's own rule. The camera is what is being calibrated:
// until it is, a corner's own sigma says little about its residual (a lens model still wrong
// at the image edge inflates every residual there), so each round judges residuals in pixels
// against their robust spread (MAD), never below min_outlier_px. The rig and pose fits, which
// start from calibrated cameras, judge each corner by its own covariance (fit/outlier_rounds.hpp).
// False: a solve failed (the result says so).
bool reject_outliers(UsedViews& used, IntrinsicFit& fit, const IntrinsicCalibrationOptions& options,
                     IntrinsicCalibrationResult& result) {
  for (int round = 0; round < options.max_outlier_rounds; ++round) {
    const auto summary =
        solve(used, fit, options.kind, options.huber_px, options.max_iterations, nullptr);
    result.iterations += static_cast<int>(summary.iterations.size());
    if (summary.termination_type == ceres::FAILURE) {
      result.status = CalibrationStatus::kFailed;
      result.reason = "bundle adjustment failed: " + summary.message;
      return false;
    }
    // Robust sigma of the residual components of the current inliers (MAD).
    std::vector<double> comps;
    for (const auto& o : fit.obs) {
      if (o.outlier) continue;
      if (const auto r = residual_of(used, fit, o)) {
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
    for (auto& o : fit.obs) {
      if (o.outlier) continue;
      const auto r = residual_of(used, fit, o);
      if (!r || r->norm() > limit) {
        o.outlier = true;
        ++newly;
      }
    }
    if (newly == 0) break;
  }
  return true;
}

// Every corner's residual, the RMS over the inliers (all, per view), the dof-corrected sigma and
// the variance factor of the weighted fit.
void residual_statistics(const UsedViews& used, const IntrinsicFit& fit, double final_cost,
                         IntrinsicCalibrationResult& result) {
  int inliers = 0;
  double sq = 0.0;
  std::vector<double> view_sq(used.views.size(), 0.0);
  std::vector<int> view_n(used.views.size(), 0);
  for (const auto& o : fit.obs) {
    CornerResidual cr;
    cr.view = static_cast<int>(used.report[static_cast<size_t>(o.view)]);
    const CalibrationView& v = *used.views[static_cast<size_t>(o.view)];
    cr.corner_id = v.corner_ids[o.index];
    cr.pixel = v.pixels[o.index];
    const auto r = residual_of(used, fit, o);
    cr.residual = r ? *r : Eigen::Vector2d(NAN, NAN);
    cr.outlier = o.outlier;
    result.residuals.push_back(cr);
    ViewReport& rep = result.views[used.report[static_cast<size_t>(o.view)]];
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
  const int n_params =
      static_cast<int>(fit.intrinsics.size()) + 6 * static_cast<int>(used.views.size());
  const int dof = 2 * inliers - n_params;
  result.residual_sigma_px = dof > 0 ? std::sqrt(sq / dof) : 0.0;
  // chi2 / dof of the weighted fit (whitened residuals): 1 when the corner covariances are
  // right; the parameter covariance is scaled by it (a-posteriori variance factor).
  result.variance_factor = dof > 0 ? 2.0 * final_cost / dof : 1.0;
  for (size_t vi = 0; vi < used.views.size(); ++vi) {
    ViewReport& rep = result.views[used.report[vi]];
    rep.camera_T_board = detail::to_isometry(used.poses[vi]);
    rep.tilt_deg = detail::view_tilt_deg(*used.views[vi], rep.camera_T_board);
    rep.rms_px = std::sqrt(view_sq[vi] / std::max(1, view_n[vi]));
  }
}

// Warnings about the fit: views that fit far worse than the others, a high RMS, many outliers.
void fit_warnings(const UsedViews& used, const IntrinsicCalibrationOptions& options,
                  size_t observations, IntrinsicCalibrationResult& result) {
  std::vector<double> view_rms;
  for (size_t i : used.report) view_rms.push_back(result.views[i].rms_px);
  std::sort(view_rms.begin(), view_rms.end());
  const double median_view_rms = view_rms[view_rms.size() / 2];
  for (size_t i : used.report) {
    const ViewReport& rep = result.views[i];
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
  if (result.corners_rejected > 0.05 * static_cast<double>(observations)) {
    result.warnings.push_back(fmt::format("{} of {} corners rejected as outliers",
                                          result.corners_rejected, observations));
  }
}

// Covariance of the intrinsics, scaled by the residual variance (Ceres assumes unit variance).
void intrinsic_covariance(ceres::Problem& problem, std::vector<double>& intrinsics,
                          IntrinsicCalibrationResult& result) {
  const size_t np = intrinsics.size();
  result.param_covariance =
      Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(np), static_cast<Eigen::Index>(np), NAN);
  result.param_stddev.assign(np, NAN);
  ceres::Covariance::Options copt;
  copt.algorithm_type = ceres::DENSE_SVD;
  copt.null_space_rank = -1;
  copt.min_reciprocal_condition_number = 1e-14;
  ceres::Covariance covariance(copt);
  std::vector<std::pair<const double*, const double*>> blocks = {
      {intrinsics.data(), intrinsics.data()}};
  if (!covariance.Compute(blocks, &problem)) {
    result.warnings.emplace_back("parameter covariance could not be computed (rank deficient)");
    return;
  }
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c(np, np);
  covariance.GetCovarianceBlock(intrinsics.data(), intrinsics.data(), c.data());
  const double var = result.variance_factor;
  result.param_covariance = c * var;
  for (size_t i = 0; i < np; ++i) {
    result.param_stddev[i] = std::sqrt(std::max(
        0.0, result.param_covariance(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(i))));
  }
}

// Corners per cell of the image and the projection uncertainty there.
void coverage_map(const IntrinsicCalibrationOptions& options, IntrinsicCalibrationResult& result) {
  const double w = options.width;
  const double h = options.height;
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
}

// The starting camera: the focal length from the views, the principal point at the image centre
// (or initial_params).
CameraModel start_camera(const Eigen::Vector2d& focal, const IntrinsicCalibrationOptions& options) {
  CameraModel start = make_camera(options.kind, options.width, options.height, focal.x(), focal.y(),
                                  (options.width - 1.0) / 2.0, (options.height - 1.0) / 2.0);
  if (!options.initial_params.empty()) start.params = options.initial_params;
  return start;
}

// The final plain least squares on the inliers, its statistics, warnings and covariance.
// False: it failed (the result says so).
bool final_fit(UsedViews& used, IntrinsicFit& fit, const IntrinsicCalibrationOptions& options,
               IntrinsicCalibrationResult& result) {
  std::unique_ptr<ceres::Problem> problem;
  const auto summary = solve(used, fit, options.kind, 0.0, options.max_iterations, &problem);
  result.iterations += static_cast<int>(summary.iterations.size());
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  if (summary.termination_type == ceres::FAILURE || !summary.IsSolutionUsable()) {
    result.status = CalibrationStatus::kFailed;
    result.reason = "bundle adjustment failed: " + summary.message;
    return false;
  }
  if (!result.converged) {
    result.warnings.push_back("bundle adjustment stopped before convergence: " + summary.message);
  }
  result.camera = fit.start;
  result.camera.params = fit.intrinsics;
  if (const std::string bad = validate_camera(result.camera); !bad.empty()) {
    result.status = CalibrationStatus::kFailed;
    result.reason = "calibration produced an invalid camera: " + bad;
    return false;
  }
  residual_statistics(used, fit, summary.final_cost, result);
  fit_warnings(used, options, fit.obs.size(), result);
  intrinsic_covariance(*problem, fit.intrinsics, result);
  return true;
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
  check_options(options);
  IntrinsicCalibrationResult result;
  result.param_names = camera_param_names(options.kind);

  // 1. The views that can be used, and the start of the focal length and the board poses.
  UsedViews used = detail::screen_views(views, options, result);
  if (static_cast<int>(used.views.size()) < options.min_views) {
    result.advice.push_back(
        fmt::format("capture at least {} views (ideally {}+) of the whole board, tilted ~45 deg "
                    "in different directions, covering the image corners",
                    options.recommended_views, 3 * options.recommended_views));
    result.status = CalibrationStatus::kRefused;
    result.reason = fmt::format("{} usable views; at least {} are needed", used.views.size(),
                                options.min_views);
    return result;
  }
  const Eigen::Vector2d focal =
      options.initial_params.empty()
          ? detail::focal_start(used, options)
          : Eigen::Vector2d(options.initial_params[0], options.initial_params[1]);
  const Eigen::Vector4d pinhole =
      options.initial_params.empty()
          ? Eigen::Vector4d(focal.x(), focal.y(), (options.width - 1.0) / 2.0,
                            (options.height - 1.0) / 2.0)
          : Eigen::Vector4d(focal.x(), focal.y(), options.initial_params[2],
                            options.initial_params[3]);
  const detail::ViewTilts tilts = detail::pose_views(used, pinhole, options, result);
  detail::find_uncovered_regions(used, options, result);
  if (!judge_view_set(used, tilts, options, result)) return result;

  // 2. Bundle adjustment with outlier rounds, then plain least squares on the inliers.
  IntrinsicFit fit;
  fit.single_sigma = single_corner_sigma(used.views);
  fit.start = start_camera(focal, options);
  fit.intrinsics = fit.start.params;
  for (size_t vi = 0; vi < used.views.size(); ++vi) {
    for (size_t k = 0; k < used.views[vi]->pixels.size(); ++k)
      fit.obs.push_back({static_cast<int>(vi), k, false});
  }
  if (!reject_outliers(used, fit, options, result)) return result;
  if (!final_fit(used, fit, options, result)) return result;

  // 3. Coverage and projection-uncertainty map.
  coverage_map(options, result);
  result.status = CalibrationStatus::kOk;
  return result;
}

}  // namespace robocal::vision
