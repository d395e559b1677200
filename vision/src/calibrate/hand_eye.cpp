#include "robocal/vision/hand_eye.hpp"

#include "fit/solver_options.hpp"
#include "robocal/core/median.hpp"
#include "robocal/vision/pose.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <fmt/format.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace robocal::vision {

namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
constexpr double kDeg = std::numbers::pi / 180.0;

double median_of(std::vector<double> v) {
  return core::median(std::move(v), std::numeric_limits<double>::quiet_NaN());
}

double rotation_angle(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle();
}

// The reported motion M_i of the model camera_T_target_i = Y · M_i · X (hand_eye.hpp).
Eigen::Isometry3d reported(const HandEyeView& view, HandEyeMount mount) {
  return mount == HandEyeMount::kFixedCamera ? view.base_T_flange : view.base_T_flange.inverse();
}

Vector6d params_of(const Eigen::Isometry3d& pose) {
  Vector6d p;
  p << rvec_of(pose), pose.translation();
  return p;
}

Eigen::Isometry3d pose_of(const double* p) {
  return pose_from_rvec_tvec(Eigen::Vector3d(p[0], p[1], p[2]), Eigen::Vector3d(p[3], p[4], p[5]));
}

// Reprojection residual (px) of one board corner: p_cam = Y · M · X · P.
template <class Model>
struct HandEyeCornerResidual {
  Eigen::Vector3d board_point;
  Eigen::Vector2d pixel;
  Eigen::Matrix3d motion_rotation;
  Eigen::Vector3d motion_translation;

  template <class T>
  bool operator()(const T* y, const T* x, const T* intrinsics, T* residual) const {
    const T P[3] = {T(board_point[0]), T(board_point[1]), T(board_point[2])};
    T p_x[3];
    ceres::AngleAxisRotatePoint(x, P, p_x);
    for (int i = 0; i < 3; ++i) p_x[i] += x[3 + i];
    T p_m[3];
    for (int r = 0; r < 3; ++r) {
      p_m[r] = T(motion_translation[r]);
      for (int c = 0; c < 3; ++c) p_m[r] += T(motion_rotation(r, c)) * p_x[c];
    }
    T p_cam[3];
    ceres::AngleAxisRotatePoint(y, p_m, p_cam);
    for (int i = 0; i < 3; ++i) p_cam[i] += y[3 + i];
    T px[2];
    if (!Model::project(intrinsics, p_cam, px)) return false;
    residual[0] = px[0] - T(pixel[0]);
    residual[1] = px[1] - T(pixel[1]);
    return true;
  }
};

ceres::CostFunction* make_corner_cost(CameraKind kind, const Eigen::Vector3d& point,
                                      const Eigen::Vector2d& pixel,
                                      const Eigen::Isometry3d& motion) {
  return visit_camera_kind(kind, [&](auto model) -> ceres::CostFunction* {
    using M = decltype(model);
    auto* f = new HandEyeCornerResidual<M>{point, pixel, motion.linear(), motion.translation()};
    return new ceres::AutoDiffCostFunction<HandEyeCornerResidual<M>, 2, 6, 6, M::kNumParams>(f);
  });
}

// Sum of squared pixel residuals and corner count of one view under (Y, X); NaN when a corner
// cannot be projected.
std::pair<double, int> view_squares(const CameraModel& camera, const BoardPoints& board,
                                    const HandEyeView& view, HandEyeMount mount,
                                    const Eigen::Isometry3d& Y, const Eigen::Isometry3d& X) {
  const Eigen::Isometry3d camera_T_target = Y * reported(view, mount) * X;
  double sq = 0.0;
  int n = 0;
  for (const CornerObservation& o : view.frame.corners) {
    const auto it = board.find(o.id);
    if (it == board.end() || !o.pixel.allFinite()) continue;
    const auto px = project(camera, camera_T_target * it->second);
    if (!px) return {std::numeric_limits<double>::quiet_NaN(), n};
    sq += (*px - o.pixel).squaredNorm();
    ++n;
  }
  return {sq, n};
}

double view_rms(const CameraModel& camera, const BoardPoints& board, const HandEyeView& view,
                HandEyeMount mount, const Eigen::Isometry3d& Y, const Eigen::Isometry3d& X) {
  const auto [sq, n] = view_squares(camera, board, view, mount, Y, X);
  return n > 0 ? std::sqrt(sq / n) : std::numeric_limits<double>::quiet_NaN();
}

// The pairwise motions (M_ij, C_ij) of the views, for the closed form.
void pair_motions(const std::vector<Eigen::Isometry3d>& M, const std::vector<Eigen::Isometry3d>& C,
                  std::vector<Eigen::Isometry3d>& A, std::vector<Eigen::Isometry3d>& B) {
  for (std::size_t i = 0; i < M.size(); ++i)
    for (std::size_t j = i + 1; j < M.size(); ++j) {
      A.push_back(M[i].inverse() * M[j]);
      B.push_back(C[i].inverse() * C[j]);
    }
}

struct ClosedForm {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  // Median over the motions that turn of the angle between R_A R_X and R_X R_B (degrees): how
  // far the reported rotations are from what the camera sees, whatever the translations.
  double rotation_residual_deg = 0.0;
  // The same median over the motions each view takes part in (a foreign pose stands out).
  std::vector<double> view_residual_deg;
};

// X from the views' motions and the rotation residuals it leaves; nullopt when the motions' axes
// do not determine it.
std::optional<ClosedForm> closed_form(const std::vector<Eigen::Isometry3d>& M,
                                      const std::vector<Eigen::Isometry3d>& C,
                                      const HandEyeOptions& options) {
  std::vector<Eigen::Isometry3d> A;
  std::vector<Eigen::Isometry3d> B;
  pair_motions(M, C, A, B);
  const auto X = solve_ax_xb(A, B, options.min_motion_deg, options.min_axis_separation_deg);
  if (!X) return std::nullopt;
  std::vector<double> residual;
  std::vector<std::vector<double>> per_view(M.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < M.size(); ++i)
    for (std::size_t j = i + 1; j < M.size(); ++j, ++k) {
      if (std::max(rotation_angle(A[k].linear()), rotation_angle(B[k].linear())) <
          options.min_motion_deg * kDeg)
        continue;
      const Eigen::Matrix3d lhs = A[k].linear() * X->linear();
      const Eigen::Matrix3d rhs = X->linear() * B[k].linear();
      const double r = rotation_angle(lhs.transpose() * rhs) / kDeg;
      residual.push_back(r);
      per_view[i].push_back(r);
      per_view[j].push_back(r);
    }
  ClosedForm out{*X, median_of(residual), {}};
  for (const auto& v : per_view) out.view_residual_deg.push_back(median_of(v));
  return out;
}

// Y from every view (Y_i = C_i X⁻¹ M_i⁻¹): the chordal mean of the rotations and the mean of the
// translations.
Eigen::Isometry3d mean_y(const std::vector<Eigen::Isometry3d>& M,
                         const std::vector<Eigen::Isometry3d>& C, const Eigen::Isometry3d& X) {
  Eigen::Matrix3d rotation_sum = Eigen::Matrix3d::Zero();
  Eigen::Vector3d translation_sum = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < M.size(); ++i) {
    const Eigen::Isometry3d Yi = C[i] * X.inverse() * M[i].inverse();
    rotation_sum += Yi.linear();
    translation_sum += Yi.translation();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(rotation_sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) {
    Eigen::Matrix3d U = svd.matrixU();
    U.col(2) *= -1.0;
    R = U * svd.matrixV().transpose();
  }
  Eigen::Isometry3d Y = Eigen::Isometry3d::Identity();
  Y.linear() = R;
  Y.translation() = translation_sum / static_cast<double>(M.size());
  return Y;
}

// The covariance [δp; δφ] of pose(p) from the covariance of its parameters p = [aa; t], by
// central differences of the perturbation core/pose_covariance.hpp defines.
core::PoseCovariance pose_covariance(const Vector6d& p, const Eigen::Matrix<double, 6, 6>& cov,
                                     bool inverted) {
  auto pose = [&](const Vector6d& q) {
    const Eigen::Isometry3d T = pose_of(q.data());
    return inverted ? Eigen::Isometry3d(T.inverse()) : T;
  };
  Eigen::Matrix<double, 6, 6> J;
  const double h = 1e-7;
  for (int k = 0; k < 6; ++k) {
    Vector6d plus = p;
    Vector6d minus = p;
    plus(k) += h;
    minus(k) -= h;
    const Eigen::Isometry3d a = pose(plus);
    const Eigen::Isometry3d b = pose(minus);
    Vector6d d;
    d.head<3>() = a.translation() - b.translation();
    const Eigen::AngleAxisd turn(a.linear() * b.linear().transpose());
    d.tail<3>() = turn.angle() * turn.axis();
    J.col(k) = d / (2.0 * h);
  }
  return J * cov * J.transpose();
}

struct Start {
  std::vector<std::size_t> views;    // the views with a trusted board pose
  std::vector<Eigen::Isometry3d> M;  // their reported motions
  std::vector<Eigen::Isometry3d> C;  // their board poses in the camera
};

// Each view's board pose in the camera (the closed form's input); views without one are marked
// in `reports` (not seen, too few corners) or only left out of the start (ambiguous).
Start view_starts(const CameraModel& camera, const BoardPoints& board,
                  const std::vector<HandEyeView>& views, const HandEyeOptions& options,
                  std::vector<HandEyeViewReport>& reports, std::vector<std::string>& warnings) {
  Start s;
  const std::vector<RigCamera> rig = {RigCamera{"camera", camera, Eigen::Isometry3d::Identity(),
                                                Eigen::Matrix<double, 6, 6>::Zero()}};
  for (std::size_t i = 0; i < views.size(); ++i) {
    HandEyeViewReport& rep = reports[i];
    rep.name = views[i].name;
    for (const CornerObservation& o : views[i].frame.corners)
      rep.corners += board.count(o.id) && o.pixel.allFinite() ? 1 : 0;
    if (!views[i].base_T_flange.matrix().allFinite()) {
      rep.rejection = "the flange pose is not finite";
      continue;
    }
    if (rep.corners == 0) {
      rep.rejection = "the board is not seen";
      continue;
    }
    if (rep.corners < options.pose.min_corners) {
      rep.rejection = fmt::format("only {} board corners seen (at least {} needed)", rep.corners,
                                  options.pose.min_corners);
      continue;
    }
    const PoseMeasurement m = measure_target_pose(rig, board, {views[i].frame}, options.pose);
    if (m.status != PoseStatus::kOk) {
      rep.rejection = fmt::format("no board pose: {}", m.message);
      continue;
    }
    rep.used = true;
    if (m.ambiguous) {
      warnings.push_back(fmt::format(
          "{}: the board's pose alone is ambiguous (two planar solutions); the view is used in "
          "the bundle adjustment, not in the closed form",
          views[i].name));
      continue;
    }
    s.views.push_back(i);
    s.M.push_back(reported(views[i], options.mount));
    s.C.push_back(m.world_T_target);
  }
  return s;
}

// The pose whose quaternion is the reported one's components read in the order w x y z: what the
// controller meant when its file holds w in the qx key.
Eigen::Isometry3d read_w_first(const Eigen::Isometry3d& pose) {
  const Eigen::Quaterniond q(pose.linear());
  Eigen::Isometry3d out = pose;
  out.linear() = Eigen::Quaterniond(q.x(), q.y(), q.z(), q.w()).normalized().toRotationMatrix();
  return out;
}

std::string mismatch_reason(double mismatch_deg, double other_deg, double w_first_deg,
                            HandEyeMount mount, const HandEyeOptions& options) {
  const HandEyeMount other = mount == HandEyeMount::kFixedCamera ? HandEyeMount::kCameraOnTool
                                                                 : HandEyeMount::kFixedCamera;
  if (w_first_deg <= options.max_rotation_mismatch_deg)
    return fmt::format(
        "the flange quaternions fit the images when read in the order w x y z (the seen and "
        "reported rotations then agree to {:.3f} deg; as given, x y z w, they disagree by {:.2f} "
        "deg): the pose files hold w under qx; write them as qx qy qz qw",
        w_first_deg, mismatch_deg);
  if (other_deg <= options.max_rotation_mismatch_deg)
    return fmt::format(
        "the views fit a {} (the reported and the seen rotations between views agree to {:.3f} "
        "deg), not a {} ({:.2f} deg): give the mounting as {}",
        other == HandEyeMount::kFixedCamera ? "fixed camera" : "camera on the tool", other_deg,
        mount == HandEyeMount::kFixedCamera ? "fixed camera" : "camera on the tool", mismatch_deg,
        hand_eye_mount_name(other));
  return fmt::format(
      "the flange rotations the controller reports disagree with the board rotations the camera "
      "sees: they differ by {:.2f} deg between views (median; a calibrated camera and robot "
      "agree within {:.1f} deg). Check the quaternion order of the flange poses (x y z w), "
      "that each pose file belongs to its image, and that the board cannot slip",
      mismatch_deg, options.max_rotation_mismatch_deg);
}

struct Solve {
  Vector6d y;
  Vector6d x;
  std::vector<double> intrinsics;
  int iterations = 0;
  bool converged = false;
};

// The bundle adjustment over the used views; robust (Huber, 1 px) for the outlier rounds, plain
// least squares for the final estimate and its covariance.
void adjust(const CameraModel& camera, const BoardPoints& board,
            const std::vector<HandEyeView>& views, const std::vector<bool>& use,
            const HandEyeOptions& options, bool robust, Solve& s, ceres::Problem& problem) {
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!use[i]) continue;
    const Eigen::Isometry3d motion = reported(views[i], options.mount);
    for (const CornerObservation& o : views[i].frame.corners) {
      const auto it = board.find(o.id);
      if (it == board.end() || !o.pixel.allFinite()) continue;
      problem.AddResidualBlock(make_corner_cost(camera.kind, it->second, o.pixel, motion),
                               robust ? new ceres::HuberLoss(1.0) : nullptr, s.y.data(), s.x.data(),
                               s.intrinsics.data());
    }
  }
  if (!options.estimate_intrinsics) problem.SetParameterBlockConstant(s.intrinsics.data());
  const ceres::Solver::Options so = detail::tight_dense_fit(ceres::DENSE_QR, 200);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  s.iterations += static_cast<int>(summary.iterations.size());
  s.converged = summary.termination_type == ceres::CONVERGENCE;
}

}  // namespace

const char* hand_eye_mount_name(HandEyeMount mount) {
  return mount == HandEyeMount::kFixedCamera ? "fixed_camera" : "camera_on_tool";
}

std::optional<Eigen::Isometry3d> solve_ax_xb(const std::vector<Eigen::Isometry3d>& A,
                                             const std::vector<Eigen::Isometry3d>& B,
                                             double min_motion_deg,
                                             double min_axis_separation_deg) {
  if (A.size() != B.size()) return std::nullopt;
  std::vector<Eigen::Vector3d> alpha;
  std::vector<Eigen::Vector3d> beta;
  for (std::size_t k = 0; k < A.size(); ++k) {
    const Eigen::AngleAxisd a(A[k].linear());
    const Eigen::AngleAxisd b(B[k].linear());
    if (a.angle() < min_motion_deg * kDeg || b.angle() < min_motion_deg * kDeg) continue;
    alpha.emplace_back(a.angle() * a.axis());
    beta.emplace_back(b.angle() * b.axis());
  }
  // Two rotation axes far enough apart determine the rotation; one axis leaves a turn about it.
  double widest = 0.0;
  for (std::size_t i = 0; i < alpha.size(); ++i)
    for (std::size_t j = i + 1; j < alpha.size(); ++j) {
      const double c = std::abs(alpha[i].normalized().dot(alpha[j].normalized()));
      widest = std::max(widest, std::acos(std::min(1.0, c)));
    }
  if (widest < min_axis_separation_deg * kDeg) return std::nullopt;
  // Park and Martin: R maximises Σ αₖᵀ R βₖ = tr(R H), H = Σ βₖ αₖᵀ.
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < alpha.size(); ++k) H += beta[k] * alpha[k].transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d R = svd.matrixV() * D * svd.matrixU().transpose();
  // Translation: (R_A − I) t = R t_B − t_A for every motion, stacked.
  Eigen::MatrixXd lhs(3 * static_cast<Eigen::Index>(A.size()), 3);
  Eigen::VectorXd rhs(3 * static_cast<Eigen::Index>(A.size()));
  for (std::size_t k = 0; k < A.size(); ++k) {
    const auto row = 3 * static_cast<Eigen::Index>(k);
    lhs.block<3, 3>(row, 0) = A[k].linear() - Eigen::Matrix3d::Identity();
    rhs.segment<3>(row) = R * B[k].translation() - A[k].translation();
  }
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = R;
  X.translation() = lhs.colPivHouseholderQr().solve(rhs);
  return X;
}

double hand_eye_reprojection_rms(const CameraModel& camera, const BoardPoints& board,
                                 const std::vector<HandEyeView>& views, HandEyeMount mount,
                                 const Eigen::Isometry3d& camera_pose,
                                 const Eigen::Isometry3d& target_pose,
                                 const std::vector<bool>& use) {
  const Eigen::Isometry3d Y = camera_pose.inverse();
  double sq = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!use.empty() && !use[i]) continue;
    const auto [s, k] = view_squares(camera, board, views[i], mount, Y, target_pose);
    sq += s;
    n += k;
  }
  return n > 0 ? std::sqrt(sq / n) : std::numeric_limits<double>::quiet_NaN();
}

namespace {

// The closed form over the views of `start`; a view whose reported rotation disagrees with every
// other view's (a pose file of another image) is set aside first, worst first, before it can bend
// the closed form (marked in `reports`, removed from `start`).
std::optional<ClosedForm> closed_form_without_outliers(Start& start, const HandEyeOptions& options,
                                                       std::vector<HandEyeViewReport>& reports) {
  auto fit = closed_form(start.M, start.C, options);
  for (int round = 0;
       fit &&
       round<options.max_outlier_rounds&& static_cast<int>(start.views.size())> options.min_views;
       ++round) {
    const auto& score = fit->view_residual_deg;
    const auto worst = static_cast<std::size_t>(
        std::max_element(
            score.begin(), score.end(),
            [](double a, double b) { return std::isnan(b) ? false : std::isnan(a) || a < b; }) -
        score.begin());
    const double limit = std::max(3.0 * median_of(score), options.max_rotation_mismatch_deg);
    if (!(score[worst] > limit)) break;
    HandEyeViewReport& rep = reports[start.views[worst]];
    rep.used = false;
    rep.rejection = fmt::format(
        "an outlier: its reported flange rotation disagrees with the board rotation the camera "
        "sees by {:.2f} deg (median over its motions; the others {:.2f} deg): a pose file of "
        "another image, or a board that moved",
        score[worst], median_of(score));
    const auto at = static_cast<std::ptrdiff_t>(worst);
    start.views.erase(start.views.begin() + at);
    start.M.erase(start.M.begin() + at);
    start.C.erase(start.C.begin() + at);
    fit = closed_form(start.M, start.C, options);
  }
  return fit;
}

// Why rotations that disagree by `mismatch_deg` are refused, naming the reading of the same
// data that fits where one does.
std::string mismatch_refusal(const CameraModel& camera, const BoardPoints& board,
                             const std::vector<HandEyeView>& views, const Start& start,
                             double mismatch_deg, const HandEyeOptions& options) {
  // Which reading of the same data fits: the other mounting, or quaternions written w first.
  // Rotations alone cannot tell these two apart (a quaternion read in another order, taken as
  // the other mounting's inverse, differs from the truth by one constant rotation, which X
  // absorbs); the closed form's reprojection can, since the positions were not reordered.
  struct Reading {
    double rotation_deg = std::numeric_limits<double>::infinity();
    double rms_px = std::numeric_limits<double>::infinity();
  };
  auto reading = [&](HandEyeMount mount, bool w_first) {
    std::vector<HandEyeView> reread;
    std::vector<Eigen::Isometry3d> M;
    for (std::size_t i : start.views) {
      reread.push_back(views[i]);
      if (w_first) reread.back().base_T_flange = read_w_first(views[i].base_T_flange);
      M.push_back(reported(reread.back(), mount));
    }
    Reading r;
    const auto other = closed_form(M, start.C, options);
    if (!other) return r;
    r.rotation_deg = other->rotation_residual_deg;
    r.rms_px = hand_eye_reprojection_rms(camera, board, reread, mount,
                                         mean_y(M, start.C, other->X).inverse(), other->X);
    if (std::isnan(r.rms_px)) r.rms_px = std::numeric_limits<double>::infinity();
    return r;
  };
  const HandEyeMount flipped = options.mount == HandEyeMount::kFixedCamera
                                   ? HandEyeMount::kCameraOnTool
                                   : HandEyeMount::kFixedCamera;
  const Reading other_mount = reading(flipped, false);
  const Reading w_first = reading(options.mount, true);
  const bool other_fits = other_mount.rotation_deg <= options.max_rotation_mismatch_deg;
  const bool w_first_fits = w_first.rotation_deg <= options.max_rotation_mismatch_deg;
  const double other_deg = other_fits && (!w_first_fits || other_mount.rms_px <= w_first.rms_px)
                               ? other_mount.rotation_deg
                               : std::numeric_limits<double>::infinity();
  const double w_first_deg = w_first_fits && !std::isfinite(other_deg)
                                 ? w_first.rotation_deg
                                 : std::numeric_limits<double>::infinity();
  return mismatch_reason(mismatch_deg, other_deg, w_first_deg, options.mount, options);
}

// The bundle adjustment with outlier views excluded one per round, worst first (robust loss;
// marked in `use` and `reports`).
void adjust_without_outliers(const CameraModel& camera, const BoardPoints& board,
                             const std::vector<HandEyeView>& views, const HandEyeOptions& options,
                             Solve& s, std::vector<bool>& use,
                             std::vector<HandEyeViewReport>& reports) {
  for (int round = 0; round <= options.max_outlier_rounds; ++round) {
    ceres::Problem problem;
    adjust(camera, board, views, use, options, true, s, problem);
    CameraModel now = camera;
    now.params = s.intrinsics;
    std::vector<double> rms;
    std::size_t worst = views.size();
    double worst_rms = 0.0;
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (!use[i]) continue;
      const double r =
          view_rms(now, board, views[i], options.mount, pose_of(s.y.data()), pose_of(s.x.data()));
      rms.push_back(std::isnan(r) ? std::numeric_limits<double>::infinity() : r);
      if (!(r <= worst_rms)) {
        worst_rms = std::isnan(r) ? std::numeric_limits<double>::infinity() : r;
        worst = i;
      }
    }
    const double limit =
        std::max(options.outlier_view_factor * median_of(rms), options.min_outlier_view_px);
    if (worst == views.size() || worst_rms <= limit || round == options.max_outlier_rounds) break;
    use[worst] = false;
    reports[worst].used = false;
    reports[worst].rejection = fmt::format(
        "an outlier: {:.2f} px reprojection RMS, over {:.1f} times the median view's (the flange "
        "pose or the detection of this image is wrong)",
        worst_rms, worst_rms / median_of(rms));
  }
}

// The covariances of the estimate: (JᵀJ)⁻¹ of the least-squares problem scaled by the residual
// variance. False when they cannot be computed (degenerate views).
bool add_covariance(ceres::Problem& problem, Solve& s, const HandEyeOptions& options,
                    HandEyeResult& out) {
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  ceres::Covariance covariance(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{s.y.data(), s.y.data()},
                                                                 {s.x.data(), s.x.data()}};
  if (options.estimate_intrinsics) blocks.emplace_back(s.intrinsics.data(), s.intrinsics.data());
  if (!covariance.Compute(blocks, &problem)) return false;
  const double variance = out.residual_sigma_px * out.residual_sigma_px;
  Eigen::Matrix<double, 6, 6, Eigen::RowMajor> cy;
  Eigen::Matrix<double, 6, 6, Eigen::RowMajor> cx;
  covariance.GetCovarianceBlock(s.y.data(), s.y.data(), cy.data());
  covariance.GetCovarianceBlock(s.x.data(), s.x.data(), cx.data());
  out.camera_pose_covariance = pose_covariance(s.y, variance * cy, true);
  out.target_pose_covariance = pose_covariance(s.x, variance * cx, false);
  if (options.estimate_intrinsics) {
    const auto k = static_cast<Eigen::Index>(s.intrinsics.size());
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> ci(k, k);
    covariance.GetCovarianceBlock(s.intrinsics.data(), s.intrinsics.data(), ci.data());
    for (Eigen::Index i = 0; i < k; ++i)
      out.intrinsics_stddev.push_back(std::sqrt(std::max(0.0, variance * ci(i, i))));
  }
  return true;
}

}  // namespace

HandEyeResult calibrate_hand_eye(const CameraModel& camera, const BoardPoints& board,
                                 const std::vector<HandEyeView>& views,
                                 const HandEyeOptions& options) {
  HandEyeResult out;
  out.mount = options.mount;
  out.camera = camera;
  out.views.resize(views.size());
  auto refuse = [&](std::string why) {
    out.status = HandEyeStatus::kRefused;
    out.reason = std::move(why);
    return out;
  };
  if (const std::string bad = validate_camera(camera); !bad.empty())
    return refuse(fmt::format("the camera cannot be used: {}", bad));

  // Positions of a robot's flange lie within metres of its base; kilometres are millimetres.
  std::vector<double> reach;
  for (const HandEyeView& v : views)
    if (v.base_T_flange.translation().allFinite())
      reach.push_back(v.base_T_flange.translation().norm());
  if (!reach.empty() && median_of(reach) > options.max_plausible_reach_m)
    return refuse(fmt::format(
        "the flange positions lie {:.1f} m from the base (median): they look like millimetres; "
        "give them in metres",
        median_of(reach)));

  Start start = view_starts(camera, board, views, options, out.views, out.warnings);
  if (static_cast<int>(start.views.size()) < options.min_views)
    return refuse(fmt::format(
        "only {} views with a clear board pose (at least {} needed): add views where the camera "
        "sees the whole board, turned about two different axes by 15 degrees or more",
        start.views.size(), options.min_views));

  const auto fit = closed_form_without_outliers(start, options, out.views);
  if (!fit)
    return refuse(fmt::format(
        "the views turn about one axis only or hardly at all (a turn about that axis stays "
        "undetermined): add views turned about two different axes by 15 degrees or more, at "
        "least {} degrees apart",
        options.min_axis_separation_deg));
  out.rotation_mismatch_deg = fit->rotation_residual_deg;
  if (!(out.rotation_mismatch_deg <= options.max_rotation_mismatch_deg)) {
    return refuse(
        mismatch_refusal(camera, board, views, start, out.rotation_mismatch_deg, options));
  }
  const Eigen::Isometry3d* X0 = &fit->X;
  const Eigen::Isometry3d Y0 = mean_y(start.M, start.C, *X0);
  out.camera_pose_closed_form = Y0.inverse();
  out.target_pose_closed_form = *X0;

  // The bundle adjustment, with outlier views excluded one per round, worst first.
  std::vector<bool> use(views.size());
  for (std::size_t i = 0; i < views.size(); ++i) use[i] = out.views[i].used;
  Solve s;
  s.y = params_of(Y0);
  s.x = params_of(*X0);
  s.intrinsics = camera.params;
  adjust_without_outliers(camera, board, views, options, s, use, out.views);
  const auto used_views = static_cast<int>(std::count(use.begin(), use.end(), true));
  if (used_views < options.min_views)
    return refuse(fmt::format("only {} views agree with each other (at least {} needed)",
                              used_views, options.min_views));

  ceres::Problem problem;
  adjust(camera, board, views, use, options, false, s, problem);
  out.iterations = s.iterations;
  out.camera.params = s.intrinsics;
  const Eigen::Isometry3d Y = pose_of(s.y.data());
  const Eigen::Isometry3d X = pose_of(s.x.data());
  out.camera_pose = Y.inverse();
  out.target_pose = X;

  double sq = 0.0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const auto [vs, n] = view_squares(out.camera, board, views[i], options.mount, Y, X);
    out.views[i].rms_px = n > 0 ? std::sqrt(vs / n) : std::numeric_limits<double>::quiet_NaN();
    if (use[i]) {
      sq += vs;
      out.corners_used += n;
    }
  }
  out.rms_px = std::sqrt(sq / std::max(1, out.corners_used));
  const int free_params = 12 + (options.estimate_intrinsics ? num_params(camera.kind) : 0);
  const int dof = 2 * out.corners_used - free_params;
  if (dof <= 0) return refuse("fewer pixel equations than unknowns: add views");
  out.residual_sigma_px = std::sqrt(sq / dof);

  if (!add_covariance(problem, s, options, out)) {
    out.status = HandEyeStatus::kFailed;
    out.reason = "the covariance of the estimate could not be computed (degenerate views)";
    return out;
  }
  if (!s.converged) out.warnings.emplace_back("the bundle adjustment stopped before converging");
  out.status = HandEyeStatus::kOk;
  return out;
}

}  // namespace robocal::vision
