#include "robocal/vision/rig_calibration.hpp"

#include "fit/board_pose.hpp"
#include "fit/corner_noise.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <fmt/format.h>
#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>

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
using Vector6d = Eigen::Matrix<double, 6, 1>;

// Whitened reprojection residual of one board corner: camera c, view v.
// Parameters: camera_T_rig [aa; t] (6), rig_T_board [aa; t] (6), intrinsics (kNumParams).
template <class Model>
struct BoardCornerResidual {
  Eigen::Vector3d board_point;
  Eigen::Vector2d pixel;
  double inv_sigma = 1.0;

  template <class T>
  bool operator()(const T* camera_T_rig, const T* rig_T_board, const T* intrinsics,
                  T* residual) const {
    const T X[3] = {T(board_point[0]), T(board_point[1]), T(board_point[2])};
    T p_rig[3];
    ceres::AngleAxisRotatePoint(rig_T_board, X, p_rig);
    for (int i = 0; i < 3; ++i) p_rig[i] += rig_T_board[3 + i];
    T p_cam[3];
    ceres::AngleAxisRotatePoint(camera_T_rig, p_rig, p_cam);
    for (int i = 0; i < 3; ++i) p_cam[i] += camera_T_rig[3 + i];
    T px[2];
    if (!Model::project(intrinsics, p_cam, px)) return false;
    residual[0] = (px[0] - T(pixel[0])) * T(inv_sigma);
    residual[1] = (px[1] - T(pixel[1])) * T(inv_sigma);
    return true;
  }
};

ceres::CostFunction* make_board_cost(CameraKind kind, const Eigen::Vector3d& point,
                                     const Eigen::Vector2d& pixel, double sigma) {
  // sigma <= 0: unwhitened pixel residuals (whitened later as a CornerGroup).
  return visit_camera_kind(kind, [&](auto model) -> ceres::CostFunction* {
    using M = decltype(model);
    auto* f = new BoardCornerResidual<M>{point, pixel, sigma > 0.0 ? 1.0 / sigma : 1.0};
    return new ceres::AutoDiffCostFunction<BoardCornerResidual<M>, 2, 6, 6, M::kNumParams>(f);
  });
}

int usable_corners(const BoardPoints& board, const CameraFrame& frame) {
  int n = 0;
  for (const CornerObservation& o : frame.corners)
    if (board.count(o.id) && o.pixel.allFinite()) ++n;
  return n;
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
                                   const std::vector<std::vector<CameraFrame>>& views,
                                   const RigCalibrationOptions& options) {
  RigCalibrationResult res;
  const size_t nc = cameras.size();
  const size_t nv = views.size();
  const auto cam_name = [&](size_t c) {
    return cameras[c].name.empty() ? fmt::format("camera {}", c)
                                   : fmt::format("camera {} '{}'", c, cameras[c].name);
  };
  for (size_t v = 0; v < nv; ++v)
    if (views[v].size() != nc)
      throw std::invalid_argument(
          fmt::format("rig calibration: view {} has {} camera frames, the "
                      "rig has {} cameras",
                      v, views[v].size(), nc));
  if (nc == 0) {
    res.message = "rig calibration: no cameras";
    return res;
  }
  const size_t ref = static_cast<size_t>(options.reference_camera);
  if (options.reference_camera < 0 || ref >= nc) {
    res.message = fmt::format("rig calibration: reference camera {} does not exist ({} cameras)",
                              options.reference_camera, nc);
    return res;
  }
  for (size_t c = 0; c < nc; ++c) {
    const std::string problem = validate_camera(cameras[c].model);
    if (!problem.empty()) {
      res.message = fmt::format("rig calibration: {}: {}", cam_name(c), problem);
      return res;
    }
  }

  // 1. Per camera and view: IPPE solutions (best first) where enough corners are seen.
  std::vector<std::vector<std::vector<detail::PlanarPnpSolution>>> pnp(
      nv, std::vector<std::vector<detail::PlanarPnpSolution>>(nc));
  std::vector<int> views_of(nc, 0);
  for (size_t v = 0; v < nv; ++v)
    for (size_t c = 0; c < nc; ++c)
      if (usable_corners(board, views[v][c]) >= options.min_corners_per_view) {
        pnp[v][c] = detail::planar_pnp_ippe(cameras[c].model, board, views[v][c]);
        if (!pnp[v][c].empty()) ++views_of[c];
      }
  for (size_t c = 0; c < nc; ++c) {
    if (views_of[c] == 0) {
      res.message =
          fmt::format("rig calibration: {} sees the board (>= {} corners) in none of the {} views",
                      cam_name(c), options.min_corners_per_view, nv);
      return res;
    }
  }

  // 2. Chain the extrinsics from the reference camera through shared views.
  std::vector<std::optional<Eigen::Isometry3d>> cam_T_rig(nc);
  cam_T_rig[ref] = Eigen::Isometry3d::Identity();
  bool progress = true;
  while (progress) {
    progress = false;
    for (size_t c = 0; c < nc; ++c) {
      if (cam_T_rig[c]) continue;
      // Candidates from every view shared with any located camera k.
      double best_cost = std::numeric_limits<double>::infinity();
      Eigen::Isometry3d best;
      std::vector<std::pair<size_t, size_t>> shared;  // (view, located camera)
      for (size_t v = 0; v < nv; ++v) {
        if (pnp[v][c].empty()) continue;
        for (size_t k = 0; k < nc; ++k)
          if (k != c && cam_T_rig[k] && !pnp[v][k].empty()) shared.emplace_back(v, k);
      }
      for (const auto& [v, k] : shared) {
        const Eigen::Isometry3d rig_T_board =
            cam_T_rig[k]->inverse() * pnp[v][k].front().camera_T_board;
        const Eigen::Isometry3d candidate =
            pnp[v][c].front().camera_T_board * rig_T_board.inverse();
        double cost = 0.0;
        for (const auto& [w, j] : shared) {
          const Eigen::Isometry3d board_in_rig =
              cam_T_rig[j]->inverse() * pnp[w][j].front().camera_T_board;
          cost += detail::reprojection_chi2(cameras[c].model, board, views[w][c],
                                            candidate * board_in_rig, options.default_sigma_px);
        }
        if (cost < best_cost) {
          best_cost = cost;
          best = candidate;
        }
      }
      if (!shared.empty()) {
        cam_T_rig[c] = best;
        progress = true;
      }
    }
  }
  std::vector<std::string> lost;
  for (size_t c = 0; c < nc; ++c)
    if (!cam_T_rig[c]) lost.push_back(cam_name(c));
  if (!lost.empty()) {
    res.message = fmt::format(
        "rig calibration: {} share{} no views with the reference {} (directly or through other "
        "cameras): show the board to both at once",
        fmt::join(lost, ", "), lost.size() == 1 ? "s" : "", cam_name(ref));
    return res;
  }

  // 3. Board pose per view: the (camera, IPPE branch) that best explains every camera's corners.
  std::vector<std::array<double, 6>> board_param(nv);
  std::vector<bool> view_used(nv, false);
  for (size_t v = 0; v < nv; ++v) {
    double best_cost = std::numeric_limits<double>::infinity();
    Eigen::Isometry3d best;
    for (size_t k = 0; k < nc; ++k) {
      for (const auto& sol : pnp[v][k]) {
        const Eigen::Isometry3d candidate = cam_T_rig[k]->inverse() * sol.camera_T_board;
        double cost = 0.0;
        for (size_t c = 0; c < nc; ++c)
          if (!pnp[v][c].empty())
            cost += detail::reprojection_chi2(cameras[c].model, board, views[v][c],
                                              *cam_T_rig[c] * candidate, options.default_sigma_px);
        if (cost < best_cost) {
          best_cost = cost;
          best = candidate;
        }
      }
    }
    if (std::isfinite(best_cost)) {
      detail::pose_to_vec6(best, board_param[v].data());
      view_used[v] = true;
    }
  }

  // 4. Bundle adjustment: robust (Huber) rounds rejecting corners beyond k sigma, then a plain
  //    least-squares solve on the inliers (its Jacobian gives the covariance).
  std::vector<std::array<double, 6>> cam_param(nc);
  std::vector<std::vector<double>> intr(nc);
  for (size_t c = 0; c < nc; ++c) {
    detail::pose_to_vec6(*cam_T_rig[c], cam_param[c].data());
    intr[c] = cameras[c].model.params;
  }
  // outlier[v][c][k]: corner k of views[v][c] rejected; usable[v][c][k]: known id, finite.
  std::vector<std::vector<std::vector<bool>>> outlier(nv), usable(nv);
  for (size_t v = 0; v < nv; ++v) {
    outlier[v].resize(nc);
    usable[v].resize(nc);
    for (size_t c = 0; c < nc; ++c) {
      outlier[v][c].assign(views[v][c].corners.size(), false);
      for (const CornerObservation& o : views[v][c].corners)
        usable[v][c].push_back(board.count(o.id) != 0 && o.pixel.allFinite());
    }
  }
  const auto sigma_of = [&](const CornerObservation& o) {
    return detail::sigma_or(o.sigma_px, options.default_sigma_px);
  };
  std::unique_ptr<ceres::Problem> problem;
  int residual_count = 0;
  ceres::Solver::Summary summary;
  const auto solve = [&](double huber) {
    problem = std::make_unique<ceres::Problem>();
    residual_count = 0;
    for (size_t v = 0; v < nv; ++v) {
      if (!view_used[v]) continue;
      for (size_t c = 0; c < nc; ++c) {
        if (pnp[v][c].empty()) continue;
        const auto& corners = views[v][c].corners;
        std::vector<int> ids;
        std::vector<bool> use;
        for (size_t k = 0; k < corners.size(); ++k) {
          ids.push_back(corners[k].id);
          use.push_back(usable[v][c][k] && !outlier[v][c][k]);
        }
        const detail::CornerGrouping grouping =
            detail::group_corners(ids, use, views[v][c].corner_groups);
        const auto cost_of = [&](size_t k, double sigma) {
          return make_board_cost(cameras[c].model.kind, board.at(corners[k].id), corners[k].pixel,
                                 sigma);
        };
        const auto add = [&](ceres::CostFunction* cost, int residuals) {
          problem->AddResidualBlock(cost, huber > 0.0 ? new ceres::HuberLoss(huber) : nullptr,
                                    cam_param[c].data(), board_param[v].data(), intr[c].data());
          residual_count += residuals;
        };
        for (size_t g = 0; g < grouping.groups.size(); ++g) {
          std::vector<std::unique_ptr<ceres::CostFunction>> members;
          for (size_t k : grouping.groups[g]) members.emplace_back(cost_of(k, 0.0));
          const int n = 2 * static_cast<int>(members.size());
          add(new detail::WhitenedGroupCost(std::move(members), grouping.whitening[g]), n);
        }
        for (size_t k : grouping.singles) add(cost_of(k, sigma_of(corners[k])), 2);
      }
    }
    for (size_t c = 0; c < nc; ++c) {
      if (!problem->HasParameterBlock(cam_param[c].data())) continue;
      if (c == ref) problem->SetParameterBlockConstant(cam_param[c].data());
      if (!options.refine_intrinsics) problem->SetParameterBlockConstant(intr[c].data());
    }
    ceres::Solver::Options sopts;
    sopts.linear_solver_type = ceres::SPARSE_SCHUR;
    sopts.max_num_iterations = options.max_iterations;
    sopts.function_tolerance = 1e-14;
    sopts.gradient_tolerance = 1e-14;
    sopts.parameter_tolerance = 1e-14;
    sopts.logging_type = ceres::SILENT;
    ceres::Solve(sopts, problem.get(), &summary);
    res.iterations += static_cast<int>(summary.iterations.size());
    return summary.IsSolutionUsable();
  };
  // Squared Mahalanobis distance of a corner's residual under its own 2x2 covariance.
  const auto corner_d2 = [&](size_t v, size_t c, size_t k) {
    const CornerObservation& o = views[v][c].corners[k];
    const Eigen::Isometry3d cam_T_board =
        detail::pose_from_vec6(cam_param[c].data()) * detail::pose_from_vec6(board_param[v].data());
    CameraModel model = cameras[c].model;
    model.params = intr[c];
    const auto px = project(model, cam_T_board * board.at(o.id));
    if (!px) return std::numeric_limits<double>::infinity();
    const Eigen::Vector2d r = *px - o.pixel;
    for (const CornerGroup& g : views[v][c].corner_groups) {
      for (size_t i = 0; i < g.corner_ids.size(); ++i) {
        if (g.corner_ids[i] != o.id ||
            g.covariance.rows() != static_cast<Eigen::Index>(2 * g.corner_ids.size()))
          continue;
        const Eigen::Matrix2d m = g.covariance.block<2, 2>(static_cast<Eigen::Index>(2 * i),
                                                           static_cast<Eigen::Index>(2 * i));
        if (m.allFinite() && m.determinant() > 0.0) return r.dot(m.inverse() * r);
      }
    }
    const double s = sigma_of(o);
    return r.squaredNorm() / (s * s);
  };
  if (options.outlier_sigmas > 0.0) {
    for (int round = 0; round < options.max_outlier_rounds; ++round) {
      if (!solve(options.huber_sigmas)) break;
      std::vector<double> d2s;
      for (size_t v = 0; v < nv; ++v)
        for (size_t c = 0; c < nc; ++c)
          if (view_used[v] && !pnp[v][c].empty())
            for (size_t k = 0; k < views[v][c].corners.size(); ++k)
              if (usable[v][c][k] && !outlier[v][c][k]) d2s.push_back(corner_d2(v, c, k));
      if (d2s.empty()) break;
      std::vector<double> sorted = d2s;
      std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2),
                       sorted.end());
      // The median of a chi-square with 2 dof is 2 ln 2; a larger one means optimistic sigmas.
      const double spread = std::max(1.0, sorted[sorted.size() / 2] / (2.0 * std::log(2.0)));
      const double limit = options.outlier_sigmas * options.outlier_sigmas * spread;
      int newly = 0;
      size_t i = 0;
      for (size_t v = 0; v < nv; ++v)
        for (size_t c = 0; c < nc; ++c)
          if (view_used[v] && !pnp[v][c].empty())
            for (size_t k = 0; k < views[v][c].corners.size(); ++k)
              if (usable[v][c][k] && !outlier[v][c][k]) {
                if (d2s[i++] > limit) {
                  outlier[v][c][k] = true;
                  ++newly;
                }
              }
      if (newly == 0) break;
    }
  }
  if (!solve(0.0)) {
    res.message = "rig calibration: bundle adjustment failed: " + summary.message;
    return res;
  }
  res.chi2 = 2.0 * summary.final_cost;
  int n_params = 6 * static_cast<int>(nc - 1);
  for (size_t v = 0; v < nv; ++v) n_params += view_used[v] ? 6 : 0;
  if (options.refine_intrinsics)
    for (size_t c = 0; c < nc; ++c) n_params += static_cast<int>(intr[c].size());
  res.dof = residual_count - n_params;
  res.variance_factor = res.dof > 0 ? res.chi2 / res.dof : 1.0;

  // 5. Covariance of every free parameter: (J^T J)^-1 at the solution (the residuals are
  //    whitened). The gauge is fixed by the constant reference camera, so J^T J is regular.
  std::vector<double*> free_blocks;
  for (size_t c = 0; c < nc; ++c) {
    if (!problem->HasParameterBlock(cam_param[c].data())) continue;
    if (c != ref) free_blocks.push_back(cam_param[c].data());
    if (options.refine_intrinsics) free_blocks.push_back(intr[c].data());
  }
  for (size_t v = 0; v < nv; ++v)
    if (view_used[v] && problem->HasParameterBlock(board_param[v].data()))
      free_blocks.push_back(board_param[v].data());
  std::map<const double*, int> offset;
  int n_free = 0;
  for (double* blk : free_blocks) {
    offset[blk] = n_free;
    n_free += problem->ParameterBlockSize(blk);
  }
  Eigen::MatrixXd cov_all;
  bool have_cov = false;
  {
    ceres::Problem::EvaluateOptions eopts;
    eopts.parameter_blocks = free_blocks;
    ceres::CRSMatrix J;
    if (n_free > 0 && problem->Evaluate(eopts, nullptr, nullptr, nullptr, &J)) {
      Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n_free, n_free);
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
      if (ldlt.info() == Eigen::Success && ldlt.isPositive() &&
          ldlt.vectorD().minCoeff() > 1e-12 * ldlt.vectorD().maxCoeff()) {
        cov_all = scale.asDiagonal() * ldlt.solve(Eigen::MatrixXd::Identity(n_free, n_free)) *
                  scale.asDiagonal();
        have_cov = true;
      }
    }
  }
  const auto cov_block = [&](const double* blk, int size) -> Eigen::MatrixXd {
    const int o = offset.at(blk);
    return cov_all.block(o, o, size, size);
  };
  const double inflate =
      options.inflate_covariance_by_residual ? std::max(1.0, res.variance_factor) : 1.0;

  // 6. Results and residual statistics.
  res.rig_T_board.assign(nv, std::nullopt);
  for (size_t v = 0; v < nv; ++v)
    if (view_used[v]) res.rig_T_board[v] = detail::pose_from_vec6(board_param[v].data());
  res.view_rms_px.assign(nv, std::vector<double>(nc, std::numeric_limits<double>::quiet_NaN()));
  res.view_outliers.assign(nv, std::vector<int>(nc, 0));
  double total_sq = 0.0;
  int total_n = 0;
  const Eigen::Vector3d ref_centre = centre_of(cam_param[ref].data());
  for (size_t c = 0; c < nc; ++c) {
    CameraCalibration cc;
    cc.name = cameras[c].name;
    cc.model = cameras[c].model;
    cc.model.params = intr[c];
    cc.camera_T_rig = detail::pose_from_vec6(cam_param[c].data());
    cc.position = centre_of(cam_param[c].data());
    cc.baseline_m = (cc.position - ref_centre).norm();
    if (c != ref && have_cov && offset.count(cam_param[c].data()) != 0) {
      const Matrix6d P = inflate * cov_block(cam_param[c].data(), 6);
      Matrix6d A = Matrix6d::Identity();
      A.topLeftCorner<3, 3>() =
          left_jacobian_of_rvec(Eigen::Vector3d(cam_param[c][0], cam_param[c][1], cam_param[c][2]));
      cc.extrinsic_covariance = A * P * A.transpose();
      // Centre and baseline by numerical Jacobians of the parameter vector.
      Eigen::Matrix<double, 3, 6> Jc;
      for (int i = 0; i < 6; ++i) {
        std::array<double, 6> hi = cam_param[c], lo = cam_param[c];
        const double h = 1e-7 * std::max(1.0, std::abs(cam_param[c][static_cast<size_t>(i)]));
        hi[static_cast<size_t>(i)] += h;
        lo[static_cast<size_t>(i)] -= h;
        Jc.col(i) = (centre_of(hi.data()) - centre_of(lo.data())) / (2 * h);
      }
      cc.position_covariance = Jc * P * Jc.transpose();
      const Eigen::Vector3d dir = (cc.position - ref_centre).normalized();
      cc.baseline_sigma_m = std::sqrt(std::max(0.0, dir.dot(cc.position_covariance * dir)));
    }
    if (options.refine_intrinsics && have_cov && offset.count(intr[c].data()) != 0) {
      const int n = static_cast<int>(intr[c].size());
      const Eigen::MatrixXd P = cov_block(intr[c].data(), n);
      for (int i = 0; i < n; ++i)
        cc.intrinsic_sigma.push_back(std::sqrt(std::max(0.0, inflate * P(i, i))));
    }
    double sq = 0.0;
    for (size_t v = 0; v < nv; ++v) {
      if (!view_used[v] || pnp[v][c].empty()) continue;
      const Eigen::Isometry3d cam_T_board = cc.camera_T_rig * *res.rig_T_board[v];
      double vsq = 0.0;
      int vn = 0;
      for (size_t k = 0; k < views[v][c].corners.size(); ++k) {
        const CornerObservation& o = views[v][c].corners[k];
        const auto it = board.find(o.id);
        if (it == board.end() || !o.pixel.allFinite()) continue;
        if (outlier[v][c][k]) {
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
    cc.rms_px = cc.corners > 0 ? std::sqrt(sq / (2.0 * cc.corners)) : 0.0;
    total_sq += sq;
    total_n += cc.corners;
    res.cameras.push_back(cc);
  }
  res.rms_px = total_n > 0 ? std::sqrt(total_sq / (2.0 * total_n)) : 0.0;
  for (size_t v = 0; v < nv; ++v)
    for (size_t c = 0; c < nc; ++c)
      for (size_t k = 0; k < outlier[v][c].size(); ++k)
        if (outlier[v][c][k]) {
          const CornerObservation& o = views[v][c].corners[k];
          RigRejectedCorner rc;
          rc.view = static_cast<int>(v);
          rc.camera = static_cast<int>(c);
          rc.id = o.id;
          const CameraCalibration& cc = res.cameras[c];
          const auto px = project(cc.model, cc.camera_T_rig * *res.rig_T_board[v] * board.at(o.id));
          rc.residual_px = px ? Eigen::Vector2d(*px - o.pixel)
                              : Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
          res.rejected.push_back(rc);
        }
  res.ok = true;
  std::vector<std::string> notes;
  if (!res.rejected.empty())
    notes.push_back(fmt::format("{} corners rejected as outliers", res.rejected.size()));
  if (!have_cov) notes.emplace_back("covariance could not be computed (degenerate geometry)");
  const int unused = static_cast<int>(std::count(view_used.begin(), view_used.end(), false));
  if (unused > 0) notes.push_back(fmt::format("{} views seen by no camera were skipped", unused));
  res.message = fmt::format("{}", fmt::join(notes, "; "));
  return res;
}

OpenCvStereoResult opencv_stereo_calibrate(const std::vector<RigCamera>& cameras,
                                           const BoardPoints& board,
                                           const std::vector<std::vector<CameraFrame>>& views,
                                           int camera_a, int camera_b, int min_common_corners) {
  OpenCvStereoResult out;
  const auto a = static_cast<size_t>(camera_a);
  const auto b = static_cast<size_t>(camera_b);
  if (camera_a < 0 || camera_b < 0 || a >= cameras.size() || b >= cameras.size()) {
    out.message = "camera index out of range";
    return out;
  }
  for (size_t c : {a, b})
    if (cameras[c].model.kind == CameraKind::kFisheyeKB4) {
      out.message = "cv::stereoCalibrate needs pinhole models";
      return out;
    }
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> pa, pb;
  for (const auto& view : views) {
    if (view.size() <= std::max(a, b)) continue;
    std::map<int, Eigen::Vector2d> in_b;
    for (const auto& o : view[b].corners) in_b[o.id] = o.pixel;
    std::vector<cv::Point3f> obj;
    std::vector<cv::Point2f> ua, ub;
    for (const auto& o : view[a].corners) {
      const auto it = board.find(o.id);
      const auto jt = in_b.find(o.id);
      if (it == board.end() || jt == in_b.end()) continue;
      obj.emplace_back(static_cast<float>(it->second.x()), static_cast<float>(it->second.y()),
                       static_cast<float>(it->second.z()));
      ua.emplace_back(static_cast<float>(o.pixel.x()), static_cast<float>(o.pixel.y()));
      ub.emplace_back(static_cast<float>(jt->second.x()), static_cast<float>(jt->second.y()));
    }
    if (static_cast<int>(obj.size()) < min_common_corners) continue;
    object.push_back(obj);
    pa.push_back(ua);
    pb.push_back(ub);
  }
  out.views = static_cast<int>(object.size());
  if (object.empty()) {
    out.message = "no view with enough corners seen by both cameras";
    return out;
  }
  const auto K = [](const CameraModel& m) -> cv::Mat {
    cv::Mat k = cv::Mat::eye(3, 3, CV_64F);
    k.at<double>(0, 0) = m.params[0];
    k.at<double>(1, 1) = m.params[1];
    k.at<double>(0, 2) = m.params[2];
    k.at<double>(1, 2) = m.params[3];
    return k;
  };
  const auto D = [](const CameraModel& m) -> cv::Mat {
    return cv::Mat(std::vector<double>(m.params.begin() + 4, m.params.end()), true);
  };
  cv::Mat Ka = K(cameras[a].model), Kb = K(cameras[b].model);
  cv::Mat Da = D(cameras[a].model), Db = D(cameras[b].model);
  cv::Mat R, T, E, F;
  int flags = cv::CALIB_FIX_INTRINSIC;
  if (cameras[a].model.kind == CameraKind::kPinholeRational) flags |= cv::CALIB_RATIONAL_MODEL;
  try {
    out.rms_px = cv::stereoCalibrate(
        object, pa, pb, Ka, Da, Kb, Db, cv::Size(cameras[a].model.width, cameras[a].model.height),
        R, T, E, F, flags,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12));
  } catch (const cv::Exception& e) {
    out.message = std::string("cv::stereoCalibrate failed: ") + e.what();
    return out;
  }
  Eigen::Matrix3d Re;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) Re(i, j) = R.at<double>(i, j);
  out.b_T_a.linear() = Re;
  out.b_T_a.translation() = Eigen::Vector3d(T.at<double>(0), T.at<double>(1), T.at<double>(2));
  out.baseline_m = out.b_T_a.translation().norm();
  out.ok = true;
  return out;
}

}  // namespace robocal::vision
