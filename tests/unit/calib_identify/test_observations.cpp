#include "robocal/calib/observations.hpp"
#include "robocal/core/random_draws.hpp"

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <random>

namespace {

using namespace robocal::calib;

Eigen::Isometry3d make_pose(const Eigen::Vector3d& aa, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (aa.norm() > 0) T.linear() = Eigen::AngleAxisd(aa.norm(), aa.normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

// Applies the documented perturbation p' = p + δp, R' = exp(δφ) R.
Eigen::Isometry3d perturb(const Eigen::Isometry3d& T, const Eigen::Matrix<double, 6, 1>& d) {
  Eigen::Isometry3d out = T;
  out.translation() += d.head<3>();
  const Eigen::Vector3d phi = d.tail<3>();
  if (phi.norm() > 0)
    out.linear() = Eigen::AngleAxisd(phi.norm(), phi.normalized()).toRotationMatrix() * T.linear();
  return out;
}

template <class Obs>
void check_single_pose_jacobian(const Obs& obs, const Eigen::Isometry3d& T) {
  constexpr int R = Obs::kResiduals;
  Eigen::Matrix<double, R, 1> r0;
  const auto J = residual_and_twist_jacobian(obs, T, r0);
  const double h = 1e-6;
  for (int c = 0; c < 6; ++c) {
    Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
    d(c) = h;
    Eigen::Matrix<double, R, 1> rp;
    Eigen::Matrix<double, R, 1> rm;
    residual_and_twist_jacobian(obs, perturb(T, d), rp);
    residual_and_twist_jacobian(obs, perturb(T, -d), rm);
    const Eigen::Matrix<double, R, 1> fd = (rp - rm) / (2 * h);
    const double tol = 1e-5 * std::max(1.0, J.col(c).norm());
    EXPECT_LT((fd - J.col(c)).norm(), tol) << "column " << c;
  }
}

TEST(Observations, JacobiansMatchCentralDifferences) {
  const Eigen::Isometry3d T = make_pose({0.3, -0.2, 1.1}, {0.2, -0.1, -0.9});
  Matrix6d cov = Matrix6d::Identity() * 1e-6;
  cov(0, 1) = cov(1, 0) = 3e-7;
  cov(3, 3) = cov(4, 4) = cov(5, 5) = 1e-5;
  const auto pose_obs =
      PoseObservation::with_covariance(make_pose({0.31, -0.19, 1.12}, {0.21, -0.1, -0.88}), cov);
  check_single_pose_jacobian(pose_obs, T);
  check_single_pose_jacobian(PointObservation::with_sigma({0.2, -0.1, -0.91}, 2e-5), T);
  ProbeHeightObservation probe;
  probe.normal = Eigen::Vector3d(0.1, 0.0, 1.0).normalized();
  probe.offset = -0.95;
  probe.measured_height = 1e-4;
  check_single_pose_jacobian(probe, T);

  // Distance: both poses' columns.
  DistanceObservation dist{.measured_distance = 0.3, .sigma = 1e-5};
  const Eigen::Isometry3d Tb = make_pose({0.0, 0.1, 0.0}, {-0.05, 0.1, -1.0});
  Eigen::Matrix<double, 1, 1> r0;
  const auto J = residual_and_twist_jacobian(dist, T, Tb, r0);
  const Eigen::Vector3d diff = T.translation() - Tb.translation();
  EXPECT_NEAR(r0(0), (diff.norm() - 0.3) / 1e-5, 1e-6);
  const Eigen::Vector3d u = diff.normalized() / 1e-5;
  const Eigen::Vector3d ja = J.leftCols<3>().transpose();
  const Eigen::Vector3d jb = J.middleCols<3>(6).transpose();
  EXPECT_LT((ja - u).norm(), 1e-6);
  EXPECT_LT((jb + u).norm(), 1e-6);
  EXPECT_LT(J.middleCols<3>(3).norm() + J.middleCols<3>(9).norm(), 1e-12);
}

TEST(Observations, PoseResidualIsWhitenedDifference) {
  const Eigen::Isometry3d truth = make_pose({0.1, 0.2, 0.3}, {1, 2, 3});
  const Eigen::Matrix<double, 6, 1> delta =
      (Eigen::Matrix<double, 6, 1>() << 1e-3, -2e-3, 0, 0, 0, 5e-3).finished();
  const auto obs = PoseObservation::with_sigmas(truth, 1e-3, 1e-3);
  Eigen::Matrix<double, 6, 1> r;
  residual_and_twist_jacobian(obs, perturb(truth, delta), r);
  EXPECT_LT((r - delta / 1e-3).norm(), 1e-9);
  EXPECT_THROW(PoseObservation::with_sigmas(truth, 0.0, 1e-3), std::invalid_argument);
}

TEST(Observations, SqrtInformationWhitens) {
  Eigen::Matrix3d cov;
  cov << 4, 1, 0, 1, 3, 0.5, 0, 0.5, 2;
  const Eigen::MatrixXd W = sqrt_information(cov);
  EXPECT_LT((W * cov * W.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  Eigen::Matrix3d bad = cov;
  bad(2, 2) = -1;
  EXPECT_THROW(sqrt_information(bad), std::invalid_argument);
  bad = cov;
  bad(0, 1) = 7;
  EXPECT_THROW(sqrt_information(bad), std::invalid_argument);
}

// Every functor works inside Ceres: recover a pose from noisy point observations of three
// markers (tool offsets) and one full-pose observation.
struct MarkerCost {
  Eigen::Vector3d offset;
  PointObservation obs;
  template <typename T>
  bool operator()(const T* pose, T* r) const {
    Mat3<T> R;
    ceres::AngleAxisToRotationMatrix(pose + 3, R.data());
    const Vec3<T> p = Vec3<T>(pose[0], pose[1], pose[2]) + R * offset.cast<T>();
    obs(R, p, r);
    return true;
  }
};

TEST(Observations, PoseRecoveredThroughCeres) {
  const Eigen::Isometry3d truth = make_pose({0.2, -0.4, 0.9}, {0.3, 0.1, -1.0});
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0.0, 1e-6);
  double pose[6] = {0, 0, 0, 0, 0, 0};
  ceres::Problem problem;
  const Eigen::Vector3d offsets[] = {{0.1, 0, 0}, {0, 0.1, 0}, {0, 0, 0.1}, {0.05, 0.05, 0}};
  for (const auto& o : offsets) {
    const Eigen::Vector3d m = truth * o + robocal::core::draw_vector3(n, rng);
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<MarkerCost, 3, 6>(
                                 new MarkerCost{o, PointObservation::with_sigma(m, 1e-6)}),
                             nullptr, pose);
  }
  problem.AddResidualBlock(
      PoseBlockCost<PoseObservation>::create(PoseObservation::with_sigmas(truth, 1e-3, 1e-2)),
      nullptr, pose);
  ceres::Solver::Options opt;
  opt.function_tolerance = 1e-14;
  opt.gradient_tolerance = 1e-14;
  ceres::Solver::Summary summary;
  ceres::Solve(opt, &problem, &summary);
  EXPECT_LT((Eigen::Vector3d(pose[0], pose[1], pose[2]) - truth.translation()).norm(), 1e-5);
  Eigen::Matrix3d R;
  ceres::AngleAxisToRotationMatrix(pose + 3, R.data());
  EXPECT_LT(Eigen::AngleAxisd(R.transpose() * truth.linear()).angle(), 1e-4);
}

}  // namespace
