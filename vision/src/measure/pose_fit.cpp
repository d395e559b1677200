#include "measure/pose_fit.hpp"

#include "fit/board_pose.hpp"
#include "fit/corner_noise.hpp"
#include "fit/reprojection_cost.hpp"
#include "fit/solver_options.hpp"

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include <array>
#include <map>
#include <memory>

namespace robocal::vision::detail {

namespace {

// Residual blocks: one corner (whitened by its sigma) or a CornerGroup of one camera frame
// (pixel residuals stacked and whitened by `whitening`).
struct NoiseBlock {
  std::vector<size_t> members;  // into the corner list
  Eigen::MatrixXd whitening;    // empty: a single corner
};

// Pose measurement's way from the board to a camera: the board's world pose perturbed by
// [d_theta; d_t] (world frame) around (R0, t0), seen by a camera whose pose may be perturbed
// likewise (held constant in the fit; used for the extrinsic-uncertainty Jacobian). The
// intrinsics are fixed.
template <class Model>
struct PerturbedBoardInCamera {
  std::array<double, 12> intrinsics{};
  Eigen::Matrix3d camera_R_world;
  Eigen::Vector3d camera_t_world;
  Eigen::Vector3d rotated_point;  // R0 * board point
  Eigen::Vector3d t0;

  template <class T, class Project>
  bool operator()(const T* d_target, const T* d_camera, Project project) const {
    const T a[3] = {T(rotated_point[0]), T(rotated_point[1]), T(rotated_point[2])};
    T w[3];
    rotate(d_target, a, w);
    for (int i = 0; i < 3; ++i) w[i] += T(t0[i]) + d_target[3 + i];
    T b[3];
    for (int i = 0; i < 3; ++i)
      b[i] = T(camera_R_world(i, 0)) * w[0] + T(camera_R_world(i, 1)) * w[1] +
             T(camera_R_world(i, 2)) * w[2];
    T c[3];
    rotate(d_camera, b, c);
    for (int i = 0; i < 3; ++i) c[i] += T(camera_t_world[i]) + d_camera[3 + i];
    T intr[Model::kNumParams];
    for (int i = 0; i < Model::kNumParams; ++i) intr[i] = T(intrinsics[static_cast<size_t>(i)]);
    return project(intr, c);
  }

  // The camera held exactly: the fit differentiates 6 parameters, not 12.
  template <class T, class Project>
  bool operator()(const T* d_target, Project project) const {
    const T zero[6] = {T(0), T(0), T(0), T(0), T(0), T(0)};
    return (*this)(d_target, zero, project);
  }
};

std::unique_ptr<ceres::CostFunction> make_cost(const RigCamera& cam, const Corner& corner,
                                               const Eigen::Isometry3d& world_T_target,
                                               bool target_only = false, bool whiten = true) {
  return visit_camera_kind(cam.model.kind, [&](auto model) -> std::unique_ptr<ceres::CostFunction> {
    using M = decltype(model);
    using Chain = PerturbedBoardInCamera<M>;
    using Cost = ReprojectionCost<M, Chain>;
    Chain chain;
    for (int i = 0; i < M::kNumParams && i < static_cast<int>(cam.model.params.size()); ++i)
      chain.intrinsics[static_cast<size_t>(i)] = cam.model.params[static_cast<size_t>(i)];
    chain.camera_R_world = cam.camera_T_world.linear();
    chain.camera_t_world = cam.camera_T_world.translation();
    chain.rotated_point = world_T_target.linear() * corner.board_point;
    chain.t0 = world_T_target.translation();
    auto* f = new Cost{chain, corner.pixel, whiten ? 1.0 / corner.sigma : 1.0};
    if (target_only) return std::make_unique<ceres::AutoDiffCostFunction<Cost, 2, 6>>(f);
    return std::make_unique<ceres::AutoDiffCostFunction<Cost, 2, 6, 6>>(f);
  });
}

Eigen::Isometry3d apply_delta(const Eigen::Isometry3d& pose, const double* d) {
  Eigen::Isometry3d out = pose;
  out.linear() = exp_so3(Eigen::Vector3d(d[0], d[1], d[2])) * pose.linear();
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
    const CornerGrouping g =
        group_corners(ids, use, src.groups ? *src.groups : std::vector<CornerGroup>{});
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
  return std::make_unique<WhitenedGroupCost>(std::move(costs), b.whitening);
}

}  // namespace

FitResult refine(const std::vector<RigCamera>& rig, const Observations& obs,
                 const Eigen::Isometry3d& start, double huber_scale) {
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
    const ceres::Solver::Options sopts = detail::tight_dense_fit(ceres::DENSE_NORMAL_CHOLESKY, 100);
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
        k.sigma = sigma_or(o.sigma_px, default_sigma);
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

}  // namespace robocal::vision::detail
