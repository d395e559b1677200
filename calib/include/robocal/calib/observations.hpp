#pragma once
// Observation models: what a measuring instrument reports about the measured frame (the target on
// the robot's tool). Each is a small functor templated on the scalar so that Ceres Jets give exact
// derivatives; residuals are whitened (divided by the measurement's noise), so a correct noise
// model gives unit-variance residuals.
//
// Every functor takes the predicted pose of the measured frame in the world as a rotation matrix R
// and a position p (world ← measured frame). Single-pose observations implement
//     template <class T> void operator()(const Mat3<T>& R, const Vec3<T>& p, T* residual) const;
// the two-pose distance observation takes two such poses.
//
// Pose perturbation convention used for Jacobians (`residual_and_twist_jacobian`):
//     p' = p + δp,   R' = exp([δφ]×) · R        (δ = [δp; δφ], world-frame rotation vector)
#include <ceres/autodiff_cost_function.h>
#include <ceres/jet.h>
#include <ceres/rotation.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <vector>

namespace robocal::calib {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

// Square-root information W (WᵀW = Σ⁻¹) of a covariance, via Cholesky: W = L⁻¹ with Σ = L Lᵀ.
// Throws std::invalid_argument when Σ is not symmetric positive definite or not finite.
Eigen::MatrixXd sqrt_information(const Eigen::MatrixXd& covariance);

// Angle-axis of a rotation matrix (column-major, Jet-safe, correct near identity).
template <typename T>
Vec3<T> rotation_vector(const Mat3<T>& R) {
  Vec3<T> aa;
  ceres::RotationMatrixToAngleAxis(R.data(), aa.data());
  return aa;
}

// Full 6-D pose (e.g. a camera or tracker measuring position and orientation), with a 6×6
// covariance in [position (m); world-frame rotation vector (rad)] order.
// residual = W · [p − p_m; log(R · R_mᵀ)]
struct PoseObservation {
  static constexpr int kResiduals = 6;
  static constexpr int kPoses = 1;
  Eigen::Matrix3d measured_rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d measured_position = Eigen::Vector3d::Zero();
  Matrix6d weight = Matrix6d::Identity();  // square-root information

  static PoseObservation with_covariance(const Eigen::Isometry3d& measured,
                                         const Matrix6d& covariance);
  static PoseObservation with_sigmas(const Eigen::Isometry3d& measured, double position_sigma,
                                     double rotation_sigma);

  template <typename T>
  void operator()(const Mat3<T>& R, const Vec3<T>& p, T* residual) const {
    const Mat3<T> E = R * measured_rotation.cast<T>().transpose();
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = p - measured_position.cast<T>();
    e.template tail<3>() = rotation_vector<T>(E);
    Eigen::Map<Eigen::Matrix<T, 6, 1>> out(residual);
    out = weight.cast<T>() * e;
  }
};

// 3-D point (laser tracker, or a single marker position). residual = W · (p − p_m).
struct PointObservation {
  static constexpr int kResiduals = 3;
  static constexpr int kPoses = 1;
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();
  Eigen::Matrix3d weight = Eigen::Matrix3d::Identity();

  static PointObservation with_covariance(const Eigen::Vector3d& measured,
                                          const Eigen::Matrix3d& covariance);
  static PointObservation with_sigma(const Eigen::Vector3d& measured, double sigma);

  template <typename T>
  void operator()(const Mat3<T>& /*R*/, const Vec3<T>& p, T* residual) const {
    Eigen::Map<Vec3<T>> out(residual);
    out = weight.cast<T>() * (p - measured.cast<T>());
  }
};

// Probe height on a plane (printer deltas, touch probes): when the probe triggered, the tool point
// was at signed height `measured_height` above the plane n·x = offset (unit normal n).
// residual = (n·p − offset − measured_height) / σ.
struct ProbeHeightObservation {
  static constexpr int kResiduals = 1;
  static constexpr int kPoses = 1;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
  double measured_height = 0.0;
  double sigma = 1e-5;

  template <typename T>
  void operator()(const Mat3<T>& /*R*/, const Vec3<T>& p, T* residual) const {
    residual[0] = (normal.cast<T>().dot(p) - T(offset) - T(measured_height)) / T(sigma);
  }
};

// Distance between the measured frame's origin at two poses (ball-bar, scale bar).
// residual = (‖p_a − p_b‖ − d) / σ.
struct DistanceObservation {
  static constexpr int kResiduals = 1;
  static constexpr int kPoses = 2;
  double measured_distance = 0.0;
  double sigma = 1e-5;

  template <typename T>
  void operator()(const Mat3<T>& /*Ra*/, const Vec3<T>& pa, const Mat3<T>& /*Rb*/,
                  const Vec3<T>& pb, T* residual) const {
    residual[0] = ((pa - pb).norm() - T(measured_distance)) / T(sigma);
  }
};

// A target corner seen by a camera (camera-in-the-loop identification): the corner `point`, fixed
// in the measured frame (metres), was imaged at `measured` (pixels, OpenCV convention: see
// vision/camera_models.hpp) by camera `camera` (index into the cameras of the predictor).
//     residual = W · (π(K_c, world_T_camera_c⁻¹ · world_T_frame · X) − uv)
// It depends on the camera's pose and intrinsics as well as on the frame, so it is evaluated by a
// predictor that models cameras (CameraRigPredictor in pixel_observations.hpp) rather than by a
// single-pose functor.
struct PixelObservation {
  static constexpr int kResiduals = 2;
  static constexpr int kPoses = 1;
  int camera = 0;
  int corner = -1;  // the target's corner id (reporting and files; -1 = none)
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector2d measured = Eigen::Vector2d::Zero();
  Eigen::Matrix2d weight = Eigen::Matrix2d::Identity();  // square-root information (1/px)

  static PixelObservation with_covariance(int camera, int corner, const Eigen::Vector3d& point,
                                          const Eigen::Vector2d& pixel,
                                          const Eigen::Matrix2d& covariance);
  static PixelObservation with_sigma(int camera, int corner, const Eigen::Vector3d& point,
                                     const Eigen::Vector2d& pixel, double sigma_px);
};

// Pixel observations measured jointly: the four corners of one refined AprilTag come from one
// edge fit, so their errors correlate. Observations [first, first + count) of a pose, all
// PixelObservation, each already whitened by its own 2 × 2 weight (the marginal of the joint
// covariance), are decorrelated by `decorrelation` (2·count square), so that together they are
// whitened by the joint covariance: decorrelation · blockdiag(weights) = joint square-root
// information.
struct PixelGroup {
  int first = 0;
  int count = 0;
  Eigen::MatrixXd decorrelation;

  // The group of `members` (their weights must be the marginal 2 × 2 blocks of `covariance`,
  // e.g. made with PixelObservation::with_covariance) starting at observation `first`. Throws
  // std::invalid_argument when the covariance is not 2·count square, symmetric, positive
  // definite.
  static PixelGroup from_covariance(int first, const std::vector<PixelObservation>& members,
                                    const Eigen::MatrixXd& covariance);
};

namespace detail {
template <typename T, int N>
void perturbed_pose(const Eigen::Isometry3d& pose, int offset, Mat3<T>& R, Vec3<T>& p) {
  Vec3<T> dp;
  Vec3<T> dphi;
  for (int i = 0; i < 3; ++i) {
    dp(i) = T(0.0);
    dp(i).v[offset + i] = 1.0;
    dphi(i) = T(0.0);
    dphi(i).v[offset + 3 + i] = 1.0;
  }
  Mat3<T> dR;
  ceres::AngleAxisToRotationMatrix(dphi.data(), dR.data());
  R = dR * pose.linear().cast<T>();
  p = pose.translation().cast<T>() + dp;
}
}  // namespace detail

// Residual of a single-pose observation at `pose` and its exact Jacobian with respect to the pose
// perturbation δ = [δp; δφ] (see the convention above).
template <class Observation>
Eigen::Matrix<double, Observation::kResiduals, 6> residual_and_twist_jacobian(
    const Observation& obs, const Eigen::Isometry3d& pose,
    Eigen::Matrix<double, Observation::kResiduals, 1>& residual) {
  static_assert(Observation::kPoses == 1);
  using J = ceres::Jet<double, 6>;
  Mat3<J> R;
  Vec3<J> p;
  detail::perturbed_pose<J, 6>(pose, 0, R, p);
  J r[Observation::kResiduals];
  obs(R, p, r);
  Eigen::Matrix<double, Observation::kResiduals, 6> jac;
  for (int i = 0; i < Observation::kResiduals; ++i) {
    residual(i) = r[i].a;
    jac.row(i) = r[i].v.transpose();
  }
  return jac;
}

// Two-pose version: Jacobian columns 0–5 for pose a, 6–11 for pose b.
template <class Observation>
Eigen::Matrix<double, Observation::kResiduals, 12> residual_and_twist_jacobian(
    const Observation& obs, const Eigen::Isometry3d& pose_a, const Eigen::Isometry3d& pose_b,
    Eigen::Matrix<double, Observation::kResiduals, 1>& residual) {
  static_assert(Observation::kPoses == 2);
  using J = ceres::Jet<double, 12>;
  Mat3<J> Ra;
  Vec3<J> pa;
  Mat3<J> Rb;
  Vec3<J> pb;
  detail::perturbed_pose<J, 12>(pose_a, 0, Ra, pa);
  detail::perturbed_pose<J, 12>(pose_b, 6, Rb, pb);
  J r[Observation::kResiduals];
  obs(Ra, pa, Rb, pb, r);
  Eigen::Matrix<double, Observation::kResiduals, 12> jac;
  for (int i = 0; i < Observation::kResiduals; ++i) {
    residual(i) = r[i].a;
    jac.row(i) = r[i].v.transpose();
  }
  return jac;
}

// Ceres adapter for a pose held as one 6-double parameter block [translation; angle-axis]: lets an
// observation be used directly with ceres::AutoDiffCostFunction (frame-only fits, tests).
template <class Observation>
struct PoseBlockCost {
  Observation obs;
  template <typename T>
  bool operator()(const T* const pose, T* residual) const {
    Mat3<T> R;
    ceres::AngleAxisToRotationMatrix(pose + 3, R.data());
    const Vec3<T> p(pose[0], pose[1], pose[2]);
    obs(R, p, residual);
    return true;
  }
  static ceres::CostFunction* create(const Observation& o) {
    return new ceres::AutoDiffCostFunction<PoseBlockCost, Observation::kResiduals, 6>(
        new PoseBlockCost{o});
  }
};

}  // namespace robocal::calib
