#include "robocal/vision/rig_calibration.hpp"

#include "calibrate/rig_starts.hpp"
#include "fit/board_pose.hpp"
#include "fit/corner_noise.hpp"
#include "fit/outlier_rounds.hpp"
#include "fit/reprojection_cost.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>

namespace robocal::vision {

namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using detail::Extrinsics;
using detail::PlanarStarts;
using detail::Pose6;
using detail::Views;
// [view][camera][corner]
using CornerFlags = std::vector<std::vector<std::vector<bool>>>;

// Rig calibration's way from the board to a camera: blocks (camera_T_rig, rig_T_board,
// intrinsics).
struct BoardInRigCamera {
  Eigen::Vector3d board_point;

  template <class T, class Project>
  bool operator()(const T* camera_T_rig, const T* rig_T_board, const T* intrinsics,
                  Project project) const {
    const T p[3] = {T(board_point[0]), T(board_point[1]), T(board_point[2])};
    T p_rig[3];
    detail::transform_point(rig_T_board, p, p_rig);
    T p_cam[3];
    detail::transform_point(camera_T_rig, p_rig, p_cam);
    return project(intrinsics, p_cam);
  }
};

ceres::CostFunction* make_board_cost(CameraKind kind, const Eigen::Vector3d& point,
                                     const Eigen::Vector2d& pixel, double sigma) {
  // sigma <= 0: unwhitened pixel residuals (whitened later as a CornerGroup).
  return visit_camera_kind(kind, [&](auto model) -> ceres::CostFunction* {
    using M = decltype(model);
    using Cost = detail::ReprojectionCost<M, BoardInRigCamera>;
    auto* f = new Cost{BoardInRigCamera{point}, pixel, sigma > 0.0 ? 1.0 / sigma : 1.0};
    return new ceres::AutoDiffCostFunction<Cost, 2, 6, 6, M::kNumParams>(f);
  });
}

// d_theta (left perturbation) per unit change of the rotation vector `aa`, numerically.
Eigen::Matrix3d left_jacobian_of_rvec(const Eigen::Vector3d& aa) {
  const Eigen::Matrix3d R = detail::exp_so3(aa);
  Eigen::Matrix3d J;
  const double h = 1e-7;
  for (int i = 0; i < 3; ++i) {
    Eigen::Vector3d a1 = aa, a0 = aa;
    a1[i] += h;
    a0[i] -= h;
    J.col(i) = (detail::log_so3(detail::exp_so3(a1) * R.transpose()) -
                detail::log_so3(detail::exp_so3(a0) * R.transpose())) /
               (2 * h);
  }
  return J;
}

Eigen::Vector3d centre_of(const double* v) {
  const Eigen::Isometry3d pose = detail::pose_from_vec6(v);
  return -(pose.linear().transpose() * pose.translation());
}

// What makes the inputs unusable (no cameras, a reference camera that does not exist, an invalid
// model), or "". A view without one frame per camera is the caller's bug: it throws.
std::string input_problem(const std::vector<RigCamera>& cameras, const Views& views,
                          const RigCalibrationOptions& options) {
  const size_t nc = cameras.size();
  for (size_t v = 0; v < views.size(); ++v)
    if (views[v].size() != nc)
      throw std::invalid_argument(
          fmt::format("rig calibration: view {} has {} camera frames, the "
                      "rig has {} cameras",
                      v, views[v].size(), nc));
  if (nc == 0) return "rig calibration: no cameras";
  if (options.reference_camera < 0 || static_cast<size_t>(options.reference_camera) >= nc)
    return fmt::format("rig calibration: reference camera {} does not exist ({} cameras)",
                       options.reference_camera, nc);
  for (size_t c = 0; c < nc; ++c) {
    const std::string problem = validate_camera(cameras[c].model);
    if (!problem.empty())
      return fmt::format("rig calibration: {}: {}", detail::camera_label(cameras, c), problem);
  }
  return "";
}

// The bundle adjustment's unknowns, the corners it uses and its last solve.
struct RigBundle {
  std::vector<Pose6> camera_T_rig;
  std::vector<std::vector<double>> intrinsics;
  std::vector<Pose6> rig_T_board;
  std::vector<bool> view_used;  // some located camera saw the view
  CornerFlags usable;           // known id, finite pixel
  CornerFlags outlier;
  std::unique_ptr<ceres::Problem> problem;
  int residual_count = 0;
  ceres::Solver::Summary summary;
  int iterations = 0;
};

void start_bundle(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                  const Views& views, const Extrinsics& located, RigBundle& bundle) {
  const size_t nc = cameras.size();
  bundle.camera_T_rig.resize(nc);
  bundle.intrinsics.resize(nc);
  for (size_t c = 0; c < nc; ++c) {
    detail::pose_to_vec6(*located[c], bundle.camera_T_rig[c].data());
    bundle.intrinsics[c] = cameras[c].model.params;
  }
  bundle.outlier.resize(views.size());
  bundle.usable.resize(views.size());
  for (size_t v = 0; v < views.size(); ++v) {
    bundle.outlier[v].resize(nc);
    bundle.usable[v].resize(nc);
    for (size_t c = 0; c < nc; ++c) {
      bundle.outlier[v][c].assign(views[v][c].corners.size(), false);
      for (const CornerObservation& o : views[v][c].corners)
        bundle.usable[v][c].push_back(board.count(o.id) != 0 && o.pixel.allFinite());
    }
  }
}

// The residual blocks of camera c in view v: its corner groups whitened together, the others
// by their own sigma.
void add_frame_residuals(const RigCamera& camera, const BoardPoints& board,
                         const CameraFrame& frame, size_t v, size_t c, double huber,
                         const RigCalibrationOptions& options, RigBundle& bundle) {
  const auto& corners = frame.corners;
  std::vector<int> ids;
  std::vector<bool> use;
  for (size_t k = 0; k < corners.size(); ++k) {
    ids.push_back(corners[k].id);
    use.push_back(bundle.usable[v][c][k] && !bundle.outlier[v][c][k]);
  }
  const detail::CornerGrouping grouping = detail::group_corners(ids, use, frame.corner_groups);
  const auto cost_of = [&](size_t k, double sigma) {
    return make_board_cost(camera.model.kind, board.at(corners[k].id), corners[k].pixel, sigma);
  };
  const auto add = [&](ceres::CostFunction* cost, int residuals) {
    bundle.problem->AddResidualBlock(cost, huber > 0.0 ? new ceres::HuberLoss(huber) : nullptr,
                                     bundle.camera_T_rig[c].data(), bundle.rig_T_board[v].data(),
                                     bundle.intrinsics[c].data());
    bundle.residual_count += residuals;
  };
  for (size_t g = 0; g < grouping.groups.size(); ++g) {
    std::vector<std::unique_ptr<ceres::CostFunction>> members;
    for (size_t k : grouping.groups[g]) members.emplace_back(cost_of(k, 0.0));
    const int n = 2 * static_cast<int>(members.size());
    add(new detail::WhitenedGroupCost(std::move(members), grouping.whitening[g]), n);
  }
  for (size_t k : grouping.singles)
    add(cost_of(k, detail::sigma_or(corners[k].sigma_px, options.default_sigma_px)), 2);
}

// One solve over the inliers (Huber loss of scale `huber` in sigmas; <= 0: plain least squares).
bool solve_bundle(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                  const Views& views, const PlanarStarts& starts,
                  const RigCalibrationOptions& options, double huber, RigBundle& bundle) {
  bundle.problem = std::make_unique<ceres::Problem>();
  bundle.residual_count = 0;
  for (size_t v = 0; v < views.size(); ++v) {
    if (!bundle.view_used[v]) continue;
    for (size_t c = 0; c < cameras.size(); ++c)
      if (!starts[v][c].empty())
        add_frame_residuals(cameras[c], board, views[v][c], v, c, huber, options, bundle);
  }
  for (size_t c = 0; c < cameras.size(); ++c) {
    if (!bundle.problem->HasParameterBlock(bundle.camera_T_rig[c].data())) continue;
    // The reference camera is the gauge: the rig frame is its frame.
    if (static_cast<int>(c) == options.reference_camera)
      bundle.problem->SetParameterBlockConstant(bundle.camera_T_rig[c].data());
    if (!options.refine_intrinsics)
      bundle.problem->SetParameterBlockConstant(bundle.intrinsics[c].data());
  }
  ceres::Solver::Options sopts;
  sopts.linear_solver_type = ceres::SPARSE_SCHUR;
  sopts.max_num_iterations = options.max_iterations;
  sopts.function_tolerance = 1e-14;
  sopts.gradient_tolerance = 1e-14;
  sopts.parameter_tolerance = 1e-14;
  sopts.logging_type = ceres::SILENT;
  ceres::Solve(sopts, bundle.problem.get(), &bundle.summary);
  bundle.iterations += static_cast<int>(bundle.summary.iterations.size());
  return bundle.summary.IsSolutionUsable();
}

// Squared Mahalanobis distance of a corner's residual under its own 2x2 covariance.
double corner_d2(const RigCamera& camera, const BoardPoints& board, const CameraFrame& frame,
                 size_t v, size_t c, size_t k, const RigCalibrationOptions& options,
                 const RigBundle& bundle) {
  const CornerObservation& o = frame.corners[k];
  const Eigen::Isometry3d cam_T_board = detail::pose_from_vec6(bundle.camera_T_rig[c].data()) *
                                        detail::pose_from_vec6(bundle.rig_T_board[v].data());
  CameraModel model = camera.model;
  model.params = bundle.intrinsics[c];
  const auto px = project(model, cam_T_board * board.at(o.id));
  if (!px) return std::numeric_limits<double>::infinity();
  const Eigen::Vector2d r = *px - o.pixel;
  for (const CornerGroup& g : frame.corner_groups) {
    for (size_t i = 0; i < g.corner_ids.size(); ++i) {
      if (g.corner_ids[i] != o.id ||
          g.covariance.rows() != static_cast<Eigen::Index>(2 * g.corner_ids.size()))
        continue;
      const Eigen::Matrix2d m = g.covariance.block<2, 2>(static_cast<Eigen::Index>(2 * i),
                                                         static_cast<Eigen::Index>(2 * i));
      if (m.allFinite() && m.determinant() > 0.0) return r.dot(m.inverse() * r);
    }
  }
  const double s = detail::sigma_or(o.sigma_px, options.default_sigma_px);
  return r.squaredNorm() / (s * s);
}

// Step 4: robust (Huber) solves with outlier rounds, then a plain least-squares solve on the
// inliers (its Jacobian gives the covariance).
bool adjust_bundle(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                   const Views& views, const PlanarStarts& starts,
                   const RigCalibrationOptions& options, RigBundle& bundle) {
  const auto robust_solve = [&] {
    return solve_bundle(cameras, board, views, starts, options, options.huber_sigmas, bundle);
  };
  if (options.outlier_sigmas > 0.0 && options.max_outlier_rounds > 0 && robust_solve()) {
    // The current inliers in a fixed order, as (view, camera, corner).
    std::vector<std::array<size_t, 3>> inliers;
    const auto inlier_d2 = [&] {
      inliers.clear();
      std::vector<double> d2;
      for (size_t v = 0; v < views.size(); ++v)
        for (size_t c = 0; c < cameras.size(); ++c)
          if (bundle.view_used[v] && !starts[v][c].empty())
            for (size_t k = 0; k < views[v][c].corners.size(); ++k)
              if (bundle.usable[v][c][k] && !bundle.outlier[v][c][k]) {
                inliers.push_back({v, c, k});
                d2.push_back(corner_d2(cameras[c], board, views[v][c], v, c, k, options, bundle));
              }
      return d2;
    };
    const auto reject = [&](size_t i) {
      const auto [v, c, k] = inliers[i];
      bundle.outlier[v][c][k] = true;
    };
    // After the last round the plain solve below follows anyway.
    const auto refit = [&](int round) {
      return round + 1 < options.max_outlier_rounds && robust_solve();
    };
    detail::run_outlier_rounds(
        detail::OutlierRule{options.outlier_sigmas, options.max_outlier_rounds, 0}, inlier_d2,
        reject, refit);
  }
  return solve_bundle(cameras, board, views, starts, options, 0.0, bundle);
}

// The free parameter blocks (every camera pose but the reference's, the intrinsics when
// refined, the board poses) and where each starts in the covariance.
struct FreeBlocks {
  std::vector<double*> blocks;
  std::map<const double*, int> offset;
  int size = 0;
};

FreeBlocks free_blocks(const RigCalibrationOptions& options, RigBundle& bundle) {
  FreeBlocks free;
  for (size_t c = 0; c < bundle.camera_T_rig.size(); ++c) {
    if (!bundle.problem->HasParameterBlock(bundle.camera_T_rig[c].data())) continue;
    if (static_cast<int>(c) != options.reference_camera)
      free.blocks.push_back(bundle.camera_T_rig[c].data());
    if (options.refine_intrinsics) free.blocks.push_back(bundle.intrinsics[c].data());
  }
  for (size_t v = 0; v < bundle.rig_T_board.size(); ++v)
    if (bundle.view_used[v] && bundle.problem->HasParameterBlock(bundle.rig_T_board[v].data()))
      free.blocks.push_back(bundle.rig_T_board[v].data());
  for (double* blk : free.blocks) {
    free.offset[blk] = free.size;
    free.size += bundle.problem->ParameterBlockSize(blk);
  }
  return free;
}

// Step 5: the covariance of every free parameter, (J^T J)^-1 at the solution (the residuals are
// whitened). The gauge is fixed by the constant reference camera, so J^T J is regular.
std::optional<Eigen::MatrixXd> bundle_covariance(const FreeBlocks& free, RigBundle& bundle) {
  ceres::Problem::EvaluateOptions eopts;
  eopts.parameter_blocks = free.blocks;
  ceres::CRSMatrix J;
  const int n = free.size;
  if (n == 0 || !bundle.problem->Evaluate(eopts, nullptr, nullptr, nullptr, &J))
    return std::nullopt;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  for (int r = 0; r < J.num_rows; ++r) {
    const int b0 = J.rows[static_cast<size_t>(r)], b1 = J.rows[static_cast<size_t>(r) + 1];
    for (int i = b0; i < b1; ++i)
      for (int j = b0; j < b1; ++j)
        H(J.cols[static_cast<size_t>(i)], J.cols[static_cast<size_t>(j)]) +=
            J.values[static_cast<size_t>(i)] * J.values[static_cast<size_t>(j)];
  }
  // Jacobi scaling first: parameters span focal lengths in px to distortion coefficients.
  const Eigen::VectorXd scale = H.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd Hs = scale.asDiagonal() * H * scale.asDiagonal();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(Hs);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() ||
      !(ldlt.vectorD().minCoeff() > 1e-12 * ldlt.vectorD().maxCoeff()))
    return std::nullopt;
  return Eigen::MatrixXd(scale.asDiagonal() * ldlt.solve(Eigen::MatrixXd::Identity(n, n)) *
                         scale.asDiagonal());
}

// The camera's extrinsic covariance in RigCamera's convention, its centre's and its baseline's,
// from the 6x6 covariance P of its parameter vector.
void extrinsic_uncertainty(const Pose6& camera_T_rig, const Matrix6d& P,
                           const Eigen::Vector3d& ref_centre, CameraCalibration& cc) {
  Matrix6d A = Matrix6d::Identity();
  A.topLeftCorner<3, 3>() =
      left_jacobian_of_rvec(Eigen::Vector3d(camera_T_rig[0], camera_T_rig[1], camera_T_rig[2]));
  cc.extrinsic_covariance = A * P * A.transpose();
  // Centre and baseline by numerical Jacobians of the parameter vector.
  Eigen::Matrix<double, 3, 6> Jc;
  for (int i = 0; i < 6; ++i) {
    Pose6 hi = camera_T_rig, lo = camera_T_rig;
    const double h = 1e-7 * std::max(1.0, std::abs(camera_T_rig[static_cast<size_t>(i)]));
    hi[static_cast<size_t>(i)] += h;
    lo[static_cast<size_t>(i)] -= h;
    Jc.col(i) = (centre_of(hi.data()) - centre_of(lo.data())) / (2 * h);
  }
  cc.position_covariance = Jc * P * Jc.transpose();
  const Eigen::Vector3d dir = (cc.position - ref_centre).normalized();
  cc.baseline_sigma_m = std::sqrt(std::max(0.0, dir.dot(cc.position_covariance * dir)));
}

// Sum of squared pixel residuals of camera c's inliers over the views it saw, counting its
// corners, views and outliers (per camera and per view).
double camera_residuals(const BoardPoints& board, const Views& views, const PlanarStarts& starts,
                        const RigBundle& bundle, size_t c, CameraCalibration& cc,
                        RigCalibrationResult& res) {
  double sq = 0.0;
  for (size_t v = 0; v < views.size(); ++v) {
    if (!bundle.view_used[v] || starts[v][c].empty()) continue;
    const Eigen::Isometry3d cam_T_board = cc.camera_T_rig * *res.rig_T_board[v];
    double vsq = 0.0;
    int vn = 0;
    for (size_t k = 0; k < views[v][c].corners.size(); ++k) {
      const CornerObservation& o = views[v][c].corners[k];
      const auto it = board.find(o.id);
      if (it == board.end() || !o.pixel.allFinite()) continue;
      if (bundle.outlier[v][c][k]) {
        ++cc.outliers;
        ++res.view_outliers[v][c];
        continue;
      }
      const auto px = visit_camera_kind(cc.model.kind, [&](auto model) {
        Eigen::Vector2d out(std::numeric_limits<double>::quiet_NaN(), 0.0);
        const Eigen::Vector3d p = cam_T_board * it->second;
        decltype(model)::project(cc.model.params.data(), p.data(), out.data());
        return out;
      });
      vsq += (px - o.pixel).squaredNorm();
      ++vn;
    }
    if (vn > 0) {
      res.view_rms_px[v][c] = std::sqrt(vsq / (2.0 * vn));
      sq += vsq;
      cc.corners += vn;
      cc.views += 1;
    }
  }
  return sq;
}

// Step 6: every camera's calibration, its uncertainty and its residual statistics.
void camera_results(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                    const Views& views, const PlanarStarts& starts,
                    const RigCalibrationOptions& options, const RigBundle& bundle,
                    const FreeBlocks& free, const std::optional<Eigen::MatrixXd>& covariance,
                    RigCalibrationResult& res) {
  const size_t ref = static_cast<size_t>(options.reference_camera);
  const double inflate =
      options.inflate_covariance_by_residual ? std::max(1.0, res.variance_factor) : 1.0;
  const auto cov_block = [&](const double* blk, int size) -> Eigen::MatrixXd {
    const int o = free.offset.at(blk);
    return covariance->block(o, o, size, size);
  };
  double total_sq = 0.0;
  int total_n = 0;
  const Eigen::Vector3d ref_centre = centre_of(bundle.camera_T_rig[ref].data());
  for (size_t c = 0; c < cameras.size(); ++c) {
    const Pose6& pose = bundle.camera_T_rig[c];
    CameraCalibration cc;
    cc.name = cameras[c].name;
    cc.model = cameras[c].model;
    cc.model.params = bundle.intrinsics[c];
    cc.camera_T_rig = detail::pose_from_vec6(pose.data());
    cc.position = centre_of(pose.data());
    cc.baseline_m = (cc.position - ref_centre).norm();
    if (c != ref && covariance && free.offset.count(pose.data()) != 0)
      extrinsic_uncertainty(pose, inflate * cov_block(pose.data(), 6), ref_centre, cc);
    const std::vector<double>& intr = bundle.intrinsics[c];
    if (options.refine_intrinsics && covariance && free.offset.count(intr.data()) != 0) {
      const int n = static_cast<int>(intr.size());
      const Eigen::MatrixXd P = cov_block(intr.data(), n);
      for (int i = 0; i < n; ++i)
        cc.intrinsic_sigma.push_back(std::sqrt(std::max(0.0, inflate * P(i, i))));
    }
    const double sq = camera_residuals(board, views, starts, bundle, c, cc, res);
    cc.rms_px = cc.corners > 0 ? std::sqrt(sq / (2.0 * cc.corners)) : 0.0;
    total_sq += sq;
    total_n += cc.corners;
    res.cameras.push_back(cc);
  }
  res.rms_px = total_n > 0 ? std::sqrt(total_sq / (2.0 * total_n)) : 0.0;
}

std::vector<RigRejectedCorner> rejected_corners(const BoardPoints& board, const Views& views,
                                                const RigBundle& bundle,
                                                const RigCalibrationResult& res) {
  std::vector<RigRejectedCorner> rejected;
  for (size_t v = 0; v < views.size(); ++v)
    for (size_t c = 0; c < bundle.camera_T_rig.size(); ++c)
      for (size_t k = 0; k < bundle.outlier[v][c].size(); ++k)
        if (bundle.outlier[v][c][k]) {
          const CornerObservation& o = views[v][c].corners[k];
          RigRejectedCorner rc;
          rc.view = static_cast<int>(v);
          rc.camera = static_cast<int>(c);
          rc.id = o.id;
          const CameraCalibration& cc = res.cameras[c];
          const auto px = project(cc.model, cc.camera_T_rig * *res.rig_T_board[v] * board.at(o.id));
          rc.residual_px = px ? Eigen::Vector2d(*px - o.pixel)
                              : Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
          rejected.push_back(rc);
        }
  return rejected;
}

// chi2, dof and variance factor of the final solve.
void fit_statistics(const RigCalibrationOptions& options, const RigBundle& bundle,
                    RigCalibrationResult& res) {
  const size_t nc = bundle.camera_T_rig.size();
  res.chi2 = 2.0 * bundle.summary.final_cost;
  int n_params = 6 * static_cast<int>(nc - 1);
  for (const bool used : bundle.view_used) n_params += used ? 6 : 0;
  if (options.refine_intrinsics)
    for (size_t c = 0; c < nc; ++c) n_params += static_cast<int>(bundle.intrinsics[c].size());
  res.dof = bundle.residual_count - n_params;
  res.variance_factor = res.dof > 0 ? res.chi2 / res.dof : 1.0;
}

std::string result_notes(const RigCalibrationResult& res, bool have_covariance,
                         const std::vector<bool>& view_used) {
  std::vector<std::string> notes;
  if (!res.rejected.empty())
    notes.push_back(fmt::format("{} corners rejected as outliers", res.rejected.size()));
  if (!have_covariance)
    notes.emplace_back("covariance could not be computed (degenerate geometry)");
  const int unused = static_cast<int>(std::count(view_used.begin(), view_used.end(), false));
  if (unused > 0) notes.push_back(fmt::format("{} views seen by no camera were skipped", unused));
  return fmt::format("{}", fmt::join(notes, "; "));
}

}  // namespace

std::vector<RigCamera> RigCalibrationResult::rig() const {
  std::vector<RigCamera> out;
  for (const CameraCalibration& c : cameras) {
    RigCamera r;
    r.name = c.name;
    r.model = c.model;
    r.camera_T_world = c.camera_T_rig;
    r.extrinsic_covariance = c.extrinsic_covariance;
    out.push_back(r);
  }
  return out;
}

RigCalibrationResult calibrate_rig(const std::vector<RigCamera>& cameras, const BoardPoints& board,
                                   const Views& views, const RigCalibrationOptions& options) {
  RigCalibrationResult res;
  res.message = input_problem(cameras, views, options);
  if (!res.message.empty()) return res;
  const PlanarStarts starts = detail::planar_starts(cameras, board, views, options);
  res.message = detail::unseen_camera(cameras, starts, options);
  if (!res.message.empty()) return res;
  const Extrinsics located = detail::chain_extrinsics(cameras, board, views, starts, options);
  res.message =
      detail::unlinked_cameras(cameras, located, static_cast<size_t>(options.reference_camera));
  if (!res.message.empty()) return res;

  RigBundle bundle;
  detail::BoardStarts board_starts =
      detail::initial_board_poses(cameras, board, views, starts, located, options);
  bundle.rig_T_board = std::move(board_starts.rig_T_board);
  bundle.view_used = std::move(board_starts.view_used);
  start_bundle(cameras, board, views, located, bundle);
  const bool solved = adjust_bundle(cameras, board, views, starts, options, bundle);
  res.iterations = bundle.iterations;
  if (!solved) {
    res.message = "rig calibration: bundle adjustment failed: " + bundle.summary.message;
    return res;
  }
  fit_statistics(options, bundle, res);
  const FreeBlocks free = free_blocks(options, bundle);
  const std::optional<Eigen::MatrixXd> covariance = bundle_covariance(free, bundle);

  res.rig_T_board.assign(views.size(), std::nullopt);
  for (size_t v = 0; v < views.size(); ++v)
    if (bundle.view_used[v])
      res.rig_T_board[v] = detail::pose_from_vec6(bundle.rig_T_board[v].data());
  res.view_rms_px.assign(
      views.size(), std::vector<double>(cameras.size(), std::numeric_limits<double>::quiet_NaN()));
  res.view_outliers.assign(views.size(), std::vector<int>(cameras.size(), 0));
  camera_results(cameras, board, views, starts, options, bundle, free, covariance, res);
  res.rejected = rejected_corners(board, views, bundle, res);
  res.ok = true;
  res.message = result_notes(res, covariance.has_value(), bundle.view_used);
  return res;
}

}  // namespace robocal::vision
