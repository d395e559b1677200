#include "robocal/vision/pose_measurement.hpp"

#include "fit/board_pose.hpp"
#include "fit/outlier_rounds.hpp"
#include "measure/pose_fit.hpp"

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

using detail::Corner;
using detail::FitResult;
using detail::Linearisation;
using detail::Matrix6d;
using detail::Observations;
using Vector6d = Eigen::Matrix<double, 6, 1>;

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
  const Linearisation lin = detail::linearise(rig, obs, m.world_T_target);
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

// Starting poses: every IPPE solution of every camera (first frame), or the guess; and per camera
// the cost ratio of its second IPPE solution to its first (a diagnostic).
struct PoseStarts {
  std::vector<Eigen::Isometry3d> candidates;
  std::vector<double> ippe_ratio;
};

PoseStarts pose_starts(const std::vector<RigCamera>& rig, const BoardPoints& board,
                       const std::vector<CameraFrame>& first, const Eigen::Isometry3d* guess) {
  PoseStarts starts;
  starts.ippe_ratio.assign(rig.size(), std::numeric_limits<double>::infinity());
  for (size_t c = 0; c < rig.size(); ++c) {
    const auto sols = detail::planar_pnp_ippe(rig[c].model, board, first[c]);
    if (sols.size() >= 2 && sols[0].rms_px > 0.0)
      starts.ippe_ratio[c] = sols[1].rms_px / sols[0].rms_px;
    if (guess) continue;
    for (const auto& s : sols)
      starts.candidates.push_back(rig[c].camera_T_world.inverse() * s.camera_T_board);
  }
  if (guess) starts.candidates.push_back(*guess);
  return starts;
}

void sort_by_cost(std::vector<FitResult>& minima) {
  std::sort(minima.begin(), minima.end(),
            [](const FitResult& a, const FitResult& b) { return a.chi2 < b.chi2; });
}

// Every distinct start refined jointly over all cameras (Huber); the distinct minima, cheapest
// first.
std::vector<FitResult> distinct_minima(const std::vector<RigCamera>& rig, const Observations& obs,
                                       const std::vector<Eigen::Isometry3d>& candidates,
                                       double huber_sigmas) {
  std::vector<FitResult> minima;
  for (const Eigen::Isometry3d& start : candidates) {
    bool seen = false;
    for (const FitResult& r : minima)
      if (!distinct(r.world_T_target, start)) seen = true;
    if (seen) continue;
    FitResult r = detail::refine(rig, obs, start, huber_sigmas);
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
  sort_by_cost(minima);
  return minima;
}

// Outlier rounds on the best branch (fit/outlier_rounds.hpp), re-fitting it (Huber) after each.
// False: too few corners are left for a pose (m says so).
bool reject_outliers(const std::vector<RigCamera>& rig, Observations& obs,
                     const PoseMeasurementOptions& options, FitResult& best, PoseMeasurement& m) {
  std::vector<size_t> inliers;  // corner indices of the current inliers
  const auto inlier_d2 = [&] {
    const std::vector<double> d2 = detail::corner_d2(rig, obs, best.world_T_target);
    inliers.clear();
    std::vector<double> out;
    for (size_t i = 0; i < d2.size(); ++i)
      if (!obs.corners[i].outlier) {
        inliers.push_back(i);
        out.push_back(d2[i]);
      }
    return out;
  };
  const auto reject = [&](size_t i) { obs.corners[inliers[i]].outlier = true; };
  const auto refit = [&](int) {
    const FitResult r = detail::refine(rig, obs, best.world_T_target, options.huber_sigmas);
    if (r.converged && std::isfinite(r.chi2)) best = r;
    return true;
  };
  const detail::OutlierRoundsEnd end = detail::run_outlier_rounds(
      detail::OutlierRule{options.outlier_sigmas, options.max_outlier_rounds, 4}, inlier_d2, reject,
      refit);
  if (!end.too_few_left) return true;
  const size_t all = obs.corners.size();
  m.status = PoseStatus::kFailed;
  m.message = fmt::format("{} of {} corners rejected as outliers: no consistent pose",
                          all - end.inliers_left, all);
  return false;
}

std::vector<RejectedCorner> rejected_corners(const std::vector<RigCamera>& rig,
                                             const Observations& obs,
                                             const Eigen::Isometry3d& world_T_target) {
  std::vector<RejectedCorner> rejected;
  for (const Corner& c : obs.corners) {
    if (!c.outlier) continue;
    RejectedCorner rc;
    rc.frame = c.frame;
    rc.camera = c.camera;
    rc.id = c.id;
    const RigCamera& cam = rig[static_cast<size_t>(c.camera)];
    const auto px = project(cam.model, cam.camera_T_world * (world_T_target * c.board_point));
    rc.residual_px = px ? Eigen::Vector2d(*px - c.pixel)
                        : Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
    rejected.push_back(rc);
  }
  return rejected;
}

// The runner-up: the cheapest other local minimum that lies well outside the best pose's own
// noise ellipsoid (a broad single basin is expressed by the covariance; a second branch is an
// ambiguity), and whether it explains the corners nearly as well.
void judge_ambiguity(const std::vector<FitResult>& minima, const PoseMeasurementOptions& options,
                     PoseMeasurement& m) {
  const Eigen::LDLT<Matrix6d> ldlt(m.covariance_corner_noise);
  for (size_t i = 1; i < minima.size(); ++i) {
    const FitResult& o = minima[i];
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

// What a good measurement's user should know about it.
std::string measurement_notes(const PoseMeasurement& m, const PoseMeasurementOptions& options) {
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
  return fmt::format("{}", fmt::join(why, "; "));
}

PoseMeasurement measure_frames(const std::vector<RigCamera>& rig, const BoardPoints& board,
                               const std::vector<const std::vector<CameraFrame>*>& frames,
                               const Eigen::Isometry3d* guess,
                               const PoseMeasurementOptions& options) {
  PoseMeasurement m;
  m.frames_used = static_cast<int>(frames.size());
  Observations obs = detail::gather(rig, board, frames, options.default_sigma_px);
  if (obs.corners.empty()) {
    m.status = PoseStatus::kNotSeen;
    m.message = "no camera saw a corner of the target";
    return m;
  }
  const PoseStarts starts = pose_starts(rig, board, *frames.front(), guess);
  if (starts.candidates.empty()) {
    m.status = PoseStatus::kTooFewCorners;
    m.message = fmt::format(
        "{} corners in all cameras together, but no camera has the 4 needed "
        "for an initial pose",
        obs.corners.size());
    m.corners = static_cast<int>(obs.corners.size());
    m.few_corners = true;
    return m;
  }
  std::vector<FitResult> minima =
      distinct_minima(rig, obs, starts.candidates, options.huber_sigmas);
  if (minima.empty()) {
    m.status = PoseStatus::kFailed;
    m.message = "the joint pose refinement did not converge from any IPPE solution";
    return m;
  }
  if (options.outlier_sigmas > 0.0 && !reject_outliers(rig, obs, options, minima[0], m)) return m;
  // Final plain least squares on the inliers, for every branch (their costs are compared).
  for (FitResult& r : minima) {
    const FitResult plain = detail::refine(rig, obs, r.world_T_target);
    if (plain.converged && std::isfinite(plain.chi2)) r = plain;
  }
  sort_by_cost(minima);
  m.world_T_target = minima[0].world_T_target;
  m.rejected = rejected_corners(rig, obs, m.world_T_target);
  m.outliers = static_cast<int>(m.rejected.size());
  finish(rig, obs, frames, options, m);
  if (m.status == PoseStatus::kOk) judge_ambiguity(minima, options, m);
  for (auto& d : m.cameras) d.ippe_rms_ratio = starts.ippe_ratio[static_cast<size_t>(d.camera)];
  if (m.status == PoseStatus::kOk) m.message = measurement_notes(m, options);
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
