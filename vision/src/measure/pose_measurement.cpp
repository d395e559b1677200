#include "robocal/vision/pose_measurement.hpp"

#include "fit/board_pose.hpp"
#include "fit/corner_noise.hpp"

#include <ceres/ceres.h>
#include <fmt/format.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <stdexcept>

namespace robocal::vision {

namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// One observed corner with everything the residual needs.
struct Corner {
  int camera = 0;
  int frame = 0;
  int id = 0;
  Eigen::Vector3d board_point;
  Eigen::Vector2d pixel;
  double sigma = 0.1;                // used when the corner is in no group
  Eigen::Matrix2d marginal_inverse;  // inverse of its own 2x2 covariance (outlier test)
  bool outlier = false;
};

// Residual blocks: one corner (whitened by its sigma) or a CornerGroup of one camera frame
// (pixel residuals stacked and whitened by `whitening`).
struct NoiseBlock {
  std::vector<size_t> members;  // into the corner list
  Eigen::MatrixXd whitening;    // empty: a single corner
};

struct Observations {
  std::vector<Corner> corners;
  // Per (frame, camera): the corner groups given with it and the indices of its corners.
  struct Source {
    const std::vector<CornerGroup>* groups = nullptr;
    std::vector<size_t> indices;
  };
  std::vector<Source> sources;
};

// Whitened reprojection residual of one corner. Parameters: the target pose perturbation
// [d_theta; d_t] around (R0, t0) in the world frame, and the camera pose perturbation (held
// constant in the fit; used for the extrinsic-uncertainty Jacobian).
template <class Model>
struct TargetCornerResidual {
  std::array<double, 12> intrinsics{};
  Eigen::Matrix3d camera_R_world;
  Eigen::Vector3d camera_t_world;
  Eigen::Vector3d rotated_point;  // R0 * board point
  Eigen::Vector3d t0;
  Eigen::Vector2d pixel;
  double inv_sigma = 1.0;

  template <class T>
  bool operator()(const T* d_target, const T* d_camera, T* residual) const {
    const T a[3] = {T(rotated_point[0]), T(rotated_point[1]), T(rotated_point[2])};
    T w[3];
    detail::rotate(d_target, a, w);
    for (int i = 0; i < 3; ++i) w[i] += T(t0[i]) + d_target[3 + i];
    T b[3];
    for (int i = 0; i < 3; ++i)
      b[i] = T(camera_R_world(i, 0)) * w[0] + T(camera_R_world(i, 1)) * w[1] +
             T(camera_R_world(i, 2)) * w[2];
    T c[3];
    detail::rotate(d_camera, b, c);
    for (int i = 0; i < 3; ++i) c[i] += T(camera_t_world[i]) + d_camera[3 + i];
    T intr[Model::kNumParams];
    for (int i = 0; i < Model::kNumParams; ++i) intr[i] = T(intrinsics[static_cast<size_t>(i)]);
    T px[2];
    if (!Model::project(intr, c, px)) return false;
    residual[0] = (px[0] - T(pixel[0])) * T(inv_sigma);
    residual[1] = (px[1] - T(pixel[1])) * T(inv_sigma);
    return true;
  }
};

// The same with the camera held exactly: the fit differentiates 6 parameters, not 12.
template <class Model>
struct TargetOnlyResidual {
  TargetCornerResidual<Model> full;
  template <class T>
  bool operator()(const T* d_target, T* residual) const {
    const T zero[6] = {T(0), T(0), T(0), T(0), T(0), T(0)};
    return full(d_target, zero, residual);
  }
};

std::unique_ptr<ceres::CostFunction> make_cost(const RigCamera& cam, const Corner& corner,
                                               const Eigen::Isometry3d& world_T_target,
                                               bool target_only = false, bool whiten = true) {
  return visit_camera_kind(cam.model.kind, [&](auto model) -> std::unique_ptr<ceres::CostFunction> {
    using M = decltype(model);
    auto* f = new TargetCornerResidual<M>();
    for (int i = 0; i < M::kNumParams && i < static_cast<int>(cam.model.params.size()); ++i)
      f->intrinsics[static_cast<size_t>(i)] = cam.model.params[static_cast<size_t>(i)];
    f->camera_R_world = cam.camera_T_world.linear();
    f->camera_t_world = cam.camera_T_world.translation();
    f->rotated_point = world_T_target.linear() * corner.board_point;
    f->t0 = world_T_target.translation();
    f->pixel = corner.pixel;
    f->inv_sigma = whiten ? 1.0 / corner.sigma : 1.0;
    if (target_only) {
      auto* g = new TargetOnlyResidual<M>{*f};
      delete f;
      return std::make_unique<ceres::AutoDiffCostFunction<TargetOnlyResidual<M>, 2, 6>>(g);
    }
    return std::make_unique<ceres::AutoDiffCostFunction<TargetCornerResidual<M>, 2, 6, 6>>(f);
  });
}

Eigen::Isometry3d apply_delta(const Eigen::Isometry3d& pose, const double* d) {
  Eigen::Isometry3d out = pose;
  out.linear() = detail::exp_so3(Eigen::Vector3d(d[0], d[1], d[2])) * pose.linear();
  out.translation() = pose.translation() + Eigen::Vector3d(d[3], d[4], d[5]);
  return out;
}

// Residual blocks over the non-outlier corners (groups re-formed from the members left).
std::vector<NoiseBlock> noise_blocks(const Observations& obs) {
  std::vector<NoiseBlock> blocks;
  for (const auto& src : obs.sources) {
    std::vector<int> ids;
    std::vector<bool> use;
    for (size_t i : src.indices) {
      ids.push_back(obs.corners[i].id);
      use.push_back(!obs.corners[i].outlier);
    }
    const detail::CornerGrouping g =
        detail::group_corners(ids, use, src.groups ? *src.groups : std::vector<CornerGroup>{});
    for (size_t k = 0; k < g.groups.size(); ++k) {
      NoiseBlock b;
      for (size_t m : g.groups[k]) b.members.push_back(src.indices[m]);
      b.whitening = g.whitening[k];
      blocks.push_back(std::move(b));
    }
    for (size_t m : g.singles) blocks.push_back({{src.indices[m]}, Eigen::MatrixXd()});
  }
  return blocks;
}

std::unique_ptr<ceres::CostFunction> make_block_cost(const std::vector<RigCamera>& rig,
                                                     const Observations& obs, const NoiseBlock& b,
                                                     const Eigen::Isometry3d& pose,
                                                     bool target_only) {
  if (b.whitening.size() == 0) {
    const Corner& c = obs.corners[b.members.front()];
    return make_cost(rig[static_cast<size_t>(c.camera)], c, pose, target_only);
  }
  std::vector<std::unique_ptr<ceres::CostFunction>> costs;
  for (size_t m : b.members) {
    const Corner& c = obs.corners[m];
    costs.push_back(make_cost(rig[static_cast<size_t>(c.camera)], c, pose, target_only, false));
  }
  return std::make_unique<detail::WhitenedGroupCost>(std::move(costs), b.whitening);
}

struct FitResult {
  bool converged = false;
  Eigen::Isometry3d world_T_target = Eigen::Isometry3d::Identity();
  double chi2 = std::numeric_limits<double>::infinity();
};

// Levenberg-Marquardt over the 6 pose perturbation parameters (the covariance is evaluated
// afterwards by linearise(), re-centred at the solution).
// huber_scale > 0: robust (Huber) loss on each block's whitened residual norm.
FitResult refine(const std::vector<RigCamera>& rig, const Observations& obs,
                 const Eigen::Isometry3d& start, double huber_scale = 0.0) {
  FitResult out;
  out.world_T_target = start;
  {
    double d_target[6] = {0, 0, 0, 0, 0, 0};
    ceres::Problem problem;
    problem.AddParameterBlock(d_target, 6);
    for (const NoiseBlock& b : noise_blocks(obs))
      problem.AddResidualBlock(make_block_cost(rig, obs, b, out.world_T_target, true).release(),
                               huber_scale > 0.0 ? new ceres::HuberLoss(huber_scale) : nullptr,
                               d_target);
    ceres::Solver::Options sopts;
    sopts.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
    sopts.max_num_iterations = 100;
    sopts.function_tolerance = 1e-12;
    sopts.gradient_tolerance = 1e-12;
    sopts.parameter_tolerance = 1e-12;
    sopts.logging_type = ceres::SILENT;
    sopts.num_threads = 1;
    ceres::Solver::Summary summary;
    ceres::Solve(sopts, &problem, &summary);
    if (!summary.IsSolutionUsable()) return out;
    out.world_T_target = apply_delta(out.world_T_target, d_target);
    out.chi2 = 2.0 * summary.final_cost;
    out.converged = summary.termination_type == ceres::CONVERGENCE ||
                    summary.termination_type == ceres::NO_CONVERGENCE;
  }
  return out;
}

struct Linearisation {
  Matrix6d information = Matrix6d::Zero();  // J^T J over the target perturbation
  std::vector<Matrix6d> cross;              // per camera: J_target^T J_camera
  std::vector<double> sq_px;                // per camera: sum of squared pixel residuals
  std::vector<int> count;
  double chi2 = 0.0;
  bool ok = true;
};

Linearisation linearise(const std::vector<RigCamera>& rig, const Observations& obs,
                        const Eigen::Isometry3d& pose) {
  Linearisation lin;
  lin.cross.assign(rig.size(), Matrix6d::Zero());
  lin.sq_px.assign(rig.size(), 0.0);
  lin.count.assign(rig.size(), 0);
  const double zeros[6] = {0, 0, 0, 0, 0, 0};
  const double* params[2] = {zeros, zeros};
  for (const NoiseBlock& b : noise_blocks(obs)) {
    // Pixel residuals and Jacobians of the members, stacked, then whitened.
    const auto n = static_cast<Eigen::Index>(2 * b.members.size());
    Eigen::VectorXd r(n);
    Eigen::MatrixXd jt(n, 6), jc(n, 6);
    bool ok = true;
    for (size_t k = 0; k < b.members.size() && ok; ++k) {
      const Corner& c = obs.corners[b.members[k]];
      const auto cost = make_cost(rig[static_cast<size_t>(c.camera)], c, pose, false, false);
      double rk[2];
      Eigen::Matrix<double, 2, 6, Eigen::RowMajor> jtk, jck;
      double* jac[2] = {jtk.data(), jck.data()};
      ok = cost->Evaluate(params, rk, jac);
      const auto row = static_cast<Eigen::Index>(2 * k);
      r.segment<2>(row) = Eigen::Vector2d(rk[0], rk[1]);
      jt.middleRows<2>(row) = jtk;
      jc.middleRows<2>(row) = jck;
    }
    if (!ok) {
      lin.ok = false;
      continue;
    }
    const int cam = obs.corners[b.members.front()].camera;
    lin.sq_px[static_cast<size_t>(cam)] += r.squaredNorm();
    lin.count[static_cast<size_t>(cam)] += static_cast<int>(b.members.size());
    if (b.whitening.size() == 0) {
      const double inv = 1.0 / obs.corners[b.members.front()].sigma;
      r *= inv;
      jt *= inv;
      jc *= inv;
    } else {
      r = b.whitening * r;
      jt = b.whitening * jt;
      jc = b.whitening * jc;
    }
    lin.information += jt.transpose() * jt;
    lin.cross[static_cast<size_t>(cam)] += jt.transpose() * jc;
    lin.chi2 += r.squaredNorm();
  }
  return lin;
}

// Squared Mahalanobis distance of each corner's pixel residual under its own 2x2 covariance.
std::vector<double> corner_d2(const std::vector<RigCamera>& rig, const Observations& obs,
                              const Eigen::Isometry3d& world_T_target) {
  std::vector<double> d2(obs.corners.size(), std::numeric_limits<double>::infinity());
  for (size_t i = 0; i < obs.corners.size(); ++i) {
    const Corner& c = obs.corners[i];
    const RigCamera& cam = rig[static_cast<size_t>(c.camera)];
    const auto px = project(cam.model, cam.camera_T_world * (world_T_target * c.board_point));
    if (!px) continue;
    const Eigen::Vector2d r = *px - c.pixel;
    d2[i] = r.dot(c.marginal_inverse * r);
  }
  return d2;
}

Observations gather(const std::vector<RigCamera>& rig, const BoardPoints& board,
                    const std::vector<const std::vector<CameraFrame>*>& frames,
                    double default_sigma) {
  Observations out;
  for (size_t f = 0; f < frames.size(); ++f) {
    for (size_t c = 0; c < rig.size(); ++c) {
      const CameraFrame& frame = (*frames[f])[c];
      Observations::Source src;
      src.groups = &frame.corner_groups;
      std::map<int, size_t> by_id;
      for (const CornerObservation& o : frame.corners) {
        const auto it = board.find(o.id);
        if (it == board.end() || !o.pixel.allFinite() || by_id.count(o.id)) continue;
        Corner k;
        k.camera = static_cast<int>(c);
        k.frame = static_cast<int>(f);
        k.id = o.id;
        k.board_point = it->second;
        k.pixel = o.pixel;
        k.sigma = detail::sigma_or(o.sigma_px, default_sigma);
        k.marginal_inverse = Eigen::Matrix2d::Identity() / (k.sigma * k.sigma);
        by_id[o.id] = out.corners.size();
        src.indices.push_back(out.corners.size());
        out.corners.push_back(k);
      }
      // A grouped corner's own 2x2 covariance, for the outlier test.
      for (const CornerGroup& g : frame.corner_groups) {
        if (g.covariance.rows() != static_cast<Eigen::Index>(2 * g.corner_ids.size())) continue;
        for (size_t k = 0; k < g.corner_ids.size(); ++k) {
          const auto it = by_id.find(g.corner_ids[k]);
          if (it == by_id.end()) continue;
          const Eigen::Matrix2d m = g.covariance.block<2, 2>(static_cast<Eigen::Index>(2 * k),
                                                             static_cast<Eigen::Index>(2 * k));
          if (m.allFinite() && m.determinant() > 0.0)
            out.corners[it->second].marginal_inverse = m.inverse();
        }
      }
      if (!src.indices.empty()) out.sources.push_back(std::move(src));
    }
  }
  return out;
}

void check_sizes(const std::vector<RigCamera>& rig, const std::vector<CameraFrame>& frame) {
  if (frame.size() != rig.size())
    throw std::invalid_argument(
        fmt::format("pose measurement: {} camera frames given for a rig of {} cameras",
                    frame.size(), rig.size()));
}

// Fills covariance, diagnostics and flags for a converged pose.
void finish(const std::vector<RigCamera>& rig, const Observations& obs,
            const std::vector<const std::vector<CameraFrame>*>& frames,
            const PoseMeasurementOptions& options, PoseMeasurement& m) {
  const Linearisation lin = linearise(rig, obs, m.world_T_target);
  m.corners = 0;
  for (const auto& c : obs.corners) m.corners += c.outlier ? 0 : 1;
  m.dof = 2 * m.corners - 6;
  m.chi2 = lin.chi2;
  double sq = 0.0;
  for (double s : lin.sq_px) sq += s;
  m.rms_px = m.corners > 0 ? std::sqrt(sq / (2.0 * m.corners)) : 0.0;
  const Eigen::FullPivLU<Matrix6d> lu(lin.information);
  if (!lu.isInvertible()) {
    m.status = PoseStatus::kFailed;
    m.message = "the corners do not determine the pose (singular information matrix)";
    return;
  }
  const Matrix6d cov = lu.inverse();
  m.covariance_corner_noise = 0.5 * (cov + cov.transpose());
  m.covariance = m.covariance_corner_noise;
  if (options.include_extrinsic_covariance) {
    for (size_t c = 0; c < rig.size(); ++c) {
      if (lin.count[c] == 0 || rig[c].extrinsic_covariance.isZero(0.0)) continue;
      const Matrix6d A = -cov * lin.cross[c];
      m.covariance += A * rig[c].extrinsic_covariance * A.transpose();
    }
    m.covariance = 0.5 * (m.covariance + m.covariance.transpose());
  }
  m.cameras.clear();
  for (size_t c = 0; c < rig.size(); ++c) {
    CameraPoseDiagnostics d;
    d.camera = static_cast<int>(c);
    d.corners = lin.count[c];
    for (const auto& k : obs.corners)
      if (k.outlier && k.camera == static_cast<int>(c)) ++d.outliers;
    d.rms_px = lin.count[c] > 0 ? std::sqrt(lin.sq_px[c] / (2.0 * lin.count[c])) : 0.0;
    for (const auto* frame : frames) {
      const CameraFrame& f = (*frame)[c];
      if (!f.corners.empty() && std::isfinite(f.blur_px) && f.blur_px > options.max_blur_px)
        d.blurred = true;
    }
    m.blurred = m.blurred || d.blurred;
    m.cameras.push_back(d);
  }
  m.few_corners = m.corners < options.min_corners;
  m.status = PoseStatus::kOk;
}

double rotation_angle_deg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
}

bool distinct(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() > 0.5 * M_PI / 180.0 ||
         (a.translation() - b.translation()).norm() > 1e-3 * std::max(1e-3, a.translation().norm());
}

PoseMeasurement measure_frames(const std::vector<RigCamera>& rig, const BoardPoints& board,
                               const std::vector<const std::vector<CameraFrame>*>& frames,
                               const Eigen::Isometry3d* guess,
                               const PoseMeasurementOptions& options) {
  PoseMeasurement m;
  m.frames_used = static_cast<int>(frames.size());
  Observations obs = gather(rig, board, frames, options.default_sigma_px);
  const std::vector<Corner>& corners = obs.corners;
  if (corners.empty()) {
    m.status = PoseStatus::kNotSeen;
    m.message = "no camera saw a corner of the target";
    return m;
  }
  // Per-camera IPPE (first frame), for both the initial guesses and the per-camera diagnostics.
  std::vector<Eigen::Isometry3d> candidates;
  std::vector<double> ippe_ratio(rig.size(), std::numeric_limits<double>::infinity());
  const std::vector<CameraFrame>& first = *frames.front();
  for (size_t c = 0; c < rig.size(); ++c) {
    const auto sols = detail::planar_pnp_ippe(rig[c].model, board, first[c]);
    if (sols.size() >= 2 && sols[0].rms_px > 0.0) ippe_ratio[c] = sols[1].rms_px / sols[0].rms_px;
    if (guess) continue;
    for (const auto& s : sols)
      candidates.push_back(rig[c].camera_T_world.inverse() * s.camera_T_board);
  }
  if (guess) candidates.push_back(*guess);
  if (candidates.empty()) {
    m.status = PoseStatus::kTooFewCorners;
    m.message = fmt::format(
        "{} corners in all cameras together, but no camera has the 4 needed "
        "for an initial pose",
        corners.size());
    m.corners = static_cast<int>(corners.size());
    m.few_corners = true;
    return m;
  }
  // Refine every distinct candidate jointly over all cameras; keep the distinct minima.
  std::vector<FitResult> minima;
  for (const Eigen::Isometry3d& start : candidates) {
    bool seen = false;
    for (const FitResult& r : minima)
      if (!distinct(r.world_T_target, start)) seen = true;
    if (seen) continue;
    FitResult r = refine(rig, obs, start, options.huber_sigmas);
    if (!r.converged || !std::isfinite(r.chi2)) continue;
    bool dup = false;
    for (FitResult& q : minima) {
      if (!distinct(q.world_T_target, r.world_T_target)) {
        dup = true;
        if (r.chi2 < q.chi2) q = r;
      }
    }
    if (!dup) minima.push_back(r);
  }
  if (minima.empty()) {
    m.status = PoseStatus::kFailed;
    m.message = "the joint pose refinement did not converge from any IPPE solution";
    return m;
  }
  std::sort(minima.begin(), minima.end(),
            [](const FitResult& a, const FitResult& b) { return a.chi2 < b.chi2; });
  // Outlier rounds on the best branch: corners whose residual exceeds k sigma (k scaled up by
  // the robust spread of all corners when the given sigmas are too optimistic) are dropped and
  // the pose re-fitted (Huber) until no more go.
  if (options.outlier_sigmas > 0.0) {
    for (int round = 0; round < options.max_outlier_rounds; ++round) {
      const std::vector<double> d2 = corner_d2(rig, obs, minima[0].world_T_target);
      std::vector<double> inl;
      for (size_t i = 0; i < d2.size(); ++i)
        if (!obs.corners[i].outlier) inl.push_back(d2[i]);
      if (inl.empty()) break;
      std::nth_element(inl.begin(), inl.begin() + static_cast<long>(inl.size() / 2), inl.end());
      // The median of a chi-square with 2 dof is 2 ln 2.
      const double spread = std::max(1.0, inl[inl.size() / 2] / (2.0 * std::log(2.0)));
      const double limit = options.outlier_sigmas * options.outlier_sigmas * spread;
      int newly = 0;
      int left = 0;
      for (size_t i = 0; i < d2.size(); ++i) {
        if (obs.corners[i].outlier) continue;
        if (d2[i] > limit) {
          obs.corners[i].outlier = true;
          ++newly;
        } else {
          ++left;
        }
      }
      if (newly == 0) break;
      if (left < 4) {
        m.status = PoseStatus::kFailed;
        m.message = fmt::format("{} of {} corners rejected as outliers: no consistent pose",
                                corners.size() - static_cast<size_t>(left), corners.size());
        return m;
      }
      const FitResult r = refine(rig, obs, minima[0].world_T_target, options.huber_sigmas);
      if (r.converged && std::isfinite(r.chi2)) minima[0] = r;
    }
  }
  // Final plain least squares on the inliers, for every branch (their costs are compared).
  for (FitResult& r : minima) {
    const FitResult plain = refine(rig, obs, r.world_T_target);
    if (plain.converged && std::isfinite(plain.chi2)) r = plain;
  }
  std::sort(minima.begin(), minima.end(),
            [](const FitResult& a, const FitResult& b) { return a.chi2 < b.chi2; });
  m.world_T_target = minima[0].world_T_target;
  for (const Corner& c : corners) {
    if (!c.outlier) continue;
    RejectedCorner rc;
    rc.frame = c.frame;
    rc.camera = c.camera;
    rc.id = c.id;
    const RigCamera& cam = rig[static_cast<size_t>(c.camera)];
    const auto px = project(cam.model, cam.camera_T_world * (m.world_T_target * c.board_point));
    rc.residual_px = px ? Eigen::Vector2d(*px - c.pixel)
                        : Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
    m.rejected.push_back(rc);
  }
  m.outliers = static_cast<int>(m.rejected.size());
  finish(rig, obs, frames, options, m);
  if (m.status == PoseStatus::kOk) {
    // The runner-up: the cheapest other local minimum that lies well outside the best pose's
    // own noise ellipsoid (a broad single basin is expressed by the covariance; a second
    // branch is an ambiguity).
    std::vector<FitResult> others(minima.begin() + 1, minima.end());
    const Eigen::LDLT<Matrix6d> ldlt(m.covariance_corner_noise);
    for (const FitResult& o : others) {
      if (!std::isfinite(o.chi2) || o.chi2 >= m.alternative_chi2) continue;
      Vector6d e;
      e.head<3>() =
          detail::log_so3(o.world_T_target.linear() * m.world_T_target.linear().transpose());
      e.tail<3>() = o.world_T_target.translation() - m.world_T_target.translation();
      if (e.dot(ldlt.solve(e)) < options.ambiguity_min_separation_chi2) continue;
      m.alternative_chi2 = o.chi2;
      m.world_T_target_alternative = o.world_T_target;
    }
    const double best = m.chi2;
    m.ambiguous = m.alternative_chi2 < options.ambiguity_cost_ratio * best ||
                  m.alternative_chi2 < best + options.ambiguity_min_delta_chi2;
  }
  for (auto& d : m.cameras) d.ippe_rms_ratio = ippe_ratio[static_cast<size_t>(d.camera)];
  if (m.status == PoseStatus::kOk) {
    std::vector<std::string> why;
    if (m.ambiguous)
      why.push_back(
          fmt::format("ambiguous: a second pose explains the corners nearly as well "
                      "(chi2 {:.1f} vs {:.1f}, {:.2f} deg apart)",
                      m.alternative_chi2, m.chi2,
                      rotation_angle_deg(m.world_T_target, m.world_T_target_alternative)));
    if (m.few_corners)
      why.push_back(fmt::format("few corners ({} < {})", m.corners, options.min_corners));
    if (m.blurred) why.emplace_back("blurred image in at least one camera");
    if (m.outliers > 0) why.push_back(fmt::format("{} corners rejected as outliers", m.outliers));
    m.message = fmt::format("{}", fmt::join(why, "; "));
  }
  return m;
}

}  // namespace

const char* pose_status_name(PoseStatus status) {
  switch (status) {
    case PoseStatus::kOk:
      return "ok";
    case PoseStatus::kNotSeen:
      return "not_seen";
    case PoseStatus::kTooFewCorners:
      return "too_few_corners";
    case PoseStatus::kMoving:
      return "moving";
    case PoseStatus::kFailed:
    default:
      return "failed";
  }
}

PoseMeasurement measure_target_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                    const std::vector<CameraFrame>& frame,
                                    const PoseMeasurementOptions& options) {
  check_sizes(rig, frame);
  return measure_frames(rig, board, {&frame}, nullptr, options);
}

PoseMeasurement refine_target_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                   const std::vector<CameraFrame>& frame,
                                   const Eigen::Isometry3d& world_T_target_guess,
                                   const PoseMeasurementOptions& options) {
  check_sizes(rig, frame);
  return measure_frames(rig, board, {&frame}, &world_T_target_guess, options);
}

MotionCheck check_target_still(const PoseMeasurement& a, const PoseMeasurement& b,
                               double false_alarm) {
  MotionCheck out;
  Vector6d d;
  d.head<3>() = detail::log_so3(b.world_T_target.linear() * a.world_T_target.linear().transpose());
  d.tail<3>() = b.world_T_target.translation() - a.world_T_target.translation();
  out.rotation_rad = d.head<3>().norm();
  out.translation_m = d.tail<3>().norm();
  // Each frame's corner noise as its own fit shows it (the variance of unit weight): the
  // detector's sigma comes from the calibration views, and smaller or more oblique tags scatter
  // more (the wire robot's poses: 2-3x the sigma, every second pose called moving while the
  // robot stood still). Motion between frames leaves each frame's own fit unchanged, so it is
  // still caught; a frame that fits worse than its sigma says is only trusted less.
  auto unit_weight = [](const PoseMeasurement& m) {
    return m.dof > 0 ? std::max(1.0, m.chi2 / m.dof) : 1.0;
  };
  const Matrix6d S =
      unit_weight(a) * a.covariance_corner_noise + unit_weight(b) * b.covariance_corner_noise;
  const Eigen::LDLT<Matrix6d> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(S.trace() > 0.0)) {
    out.chi2 = std::numeric_limits<double>::infinity();
  } else {
    out.chi2 = d.dot(ldlt.solve(d));
  }
  out.p_value = chi2_survival(out.chi2, 6);
  out.moving = out.p_value < false_alarm;
  return out;
}

PoseMeasurement measure_settled_pose(const std::vector<RigCamera>& rig, const BoardPoints& board,
                                     const std::vector<std::vector<CameraFrame>>& frames,
                                     const PoseMeasurementOptions& options) {
  if (frames.empty()) {
    PoseMeasurement m;
    m.status = PoseStatus::kNotSeen;
    m.message = "no frames";
    return m;
  }
  for (const auto& f : frames) check_sizes(rig, f);
  PoseMeasurement first = measure_target_pose(rig, board, frames[0], options);
  if (frames.size() == 1 || first.status != PoseStatus::kOk) return first;
  double worst = 0.0;
  size_t worst_frame = 0;
  MotionCheck worst_check;
  for (size_t f = 1; f < frames.size(); ++f) {
    const PoseMeasurement other =
        refine_target_pose(rig, board, frames[f], first.world_T_target, options);
    if (other.status != PoseStatus::kOk) {
      first.status = other.status;
      first.message = fmt::format("frame {}: {}", f, other.message);
      return first;
    }
    const MotionCheck check = check_target_still(first, other, options.motion_false_alarm);
    if (check.chi2 > worst) {
      worst = check.chi2;
      worst_frame = f;
      worst_check = check;
    }
  }
  first.motion_chi2 = worst;
  if (worst_check.moving) {
    first.status = PoseStatus::kMoving;
    first.moving = true;
    first.message = fmt::format(
        "target moved between frame 0 and frame {}: {:.1f} um, {:.4f} deg (chi2 {:.1f} on 6 dof, "
        "p = {:.2g})",
        worst_frame, worst_check.translation_m * 1e6, worst_check.rotation_rad * 180.0 / M_PI,
        worst_check.chi2, worst_check.p_value);
    return first;
  }
  std::vector<const std::vector<CameraFrame>*> all;
  all.reserve(frames.size());
  for (const auto& f : frames) all.push_back(&f);
  PoseMeasurement joint = measure_frames(rig, board, all, &first.world_T_target, options);
  joint.motion_chi2 = worst;
  // The branch ambiguity was judged on frame 0 with IPPE; keep that verdict.
  joint.ambiguous = first.ambiguous;
  joint.alternative_chi2 = first.alternative_chi2;
  joint.world_T_target_alternative = first.world_T_target_alternative;
  return joint;
}

}  // namespace robocal::vision
