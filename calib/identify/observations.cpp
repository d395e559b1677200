#include "robocal/calib/observations.hpp"

#include <fmt/core.h>
#include <Eigen/Cholesky>

#include <stdexcept>

namespace robocal::calib {

Eigen::MatrixXd sqrt_information(const Eigen::MatrixXd& covariance) {
  if (covariance.rows() != covariance.cols() || !covariance.allFinite())
    throw std::invalid_argument("covariance must be a finite square matrix");
  if ((covariance - covariance.transpose()).cwiseAbs().maxCoeff() >
      1e-9 * covariance.cwiseAbs().maxCoeff())
    throw std::invalid_argument("covariance must be symmetric");
  const Eigen::LLT<Eigen::MatrixXd> llt(covariance);
  if (llt.info() != Eigen::Success)
    throw std::invalid_argument("covariance must be positive definite");
  const Eigen::MatrixXd L = llt.matrixL();
  return L.triangularView<Eigen::Lower>().solve(
      Eigen::MatrixXd::Identity(covariance.rows(), covariance.cols()));
}

PoseObservation PoseObservation::with_covariance(const Eigen::Isometry3d& measured,
                                                 const Matrix6d& covariance) {
  PoseObservation o;
  o.measured_rotation = measured.linear();
  o.measured_position = measured.translation();
  o.weight = sqrt_information(covariance);
  return o;
}

PoseObservation PoseObservation::with_sigmas(const Eigen::Isometry3d& measured,
                                             double position_sigma, double rotation_sigma) {
  if (!(position_sigma > 0.0) || !(rotation_sigma > 0.0))
    throw std::invalid_argument(
        fmt::format("pose observation sigmas must be positive (got {} m, {} rad)", position_sigma,
                    rotation_sigma));
  Matrix6d cov = Matrix6d::Zero();
  cov.diagonal() << Eigen::Vector3d::Constant(position_sigma * position_sigma),
      Eigen::Vector3d::Constant(rotation_sigma * rotation_sigma);
  return with_covariance(measured, cov);
}

PointObservation PointObservation::with_covariance(const Eigen::Vector3d& measured,
                                                   const Eigen::Matrix3d& covariance) {
  PointObservation o;
  o.measured = measured;
  o.weight = sqrt_information(covariance);
  return o;
}

PointObservation PointObservation::with_sigma(const Eigen::Vector3d& measured, double sigma) {
  if (!(sigma > 0.0))
    throw std::invalid_argument(
        fmt::format("point observation sigma must be positive (got {})", sigma));
  return with_covariance(measured, Eigen::Matrix3d::Identity() * sigma * sigma);
}

PixelObservation PixelObservation::with_covariance(int camera, int corner,
                                                   const Eigen::Vector3d& point,
                                                   const Eigen::Vector2d& pixel,
                                                   const Eigen::Matrix2d& covariance) {
  PixelObservation o;
  o.camera = camera;
  o.corner = corner;
  o.point = point;
  o.measured = pixel;
  o.weight = sqrt_information(covariance);
  return o;
}

PixelGroup PixelGroup::from_covariance(int first, const std::vector<PixelObservation>& members,
                                       const Eigen::MatrixXd& covariance) {
  const auto n = 2 * static_cast<Eigen::Index>(members.size());
  if (members.empty() || covariance.rows() != n || covariance.cols() != n)
    throw std::invalid_argument(
        fmt::format("a pixel group of {} corners needs a {}x{} covariance (got {}x{})",
                    members.size(), n, n, covariance.rows(), covariance.cols()));
  Eigen::MatrixXd marginal_inverse = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index k = 0; k < static_cast<Eigen::Index>(members.size()); ++k)
    marginal_inverse.block<2, 2>(2 * k, 2 * k) =
        members[static_cast<std::size_t>(k)].weight.inverse();
  PixelGroup g;
  g.first = first;
  g.count = static_cast<int>(members.size());
  g.decorrelation = sqrt_information(covariance) * marginal_inverse;
  return g;
}

PixelObservation PixelObservation::with_sigma(int camera, int corner, const Eigen::Vector3d& point,
                                              const Eigen::Vector2d& pixel, double sigma_px) {
  if (!(sigma_px > 0.0))
    throw std::invalid_argument(
        fmt::format("pixel observation sigma must be positive (got {} px)", sigma_px));
  return with_covariance(camera, corner, point, pixel,
                         Eigen::Matrix2d::Identity() * sigma_px * sigma_px);
}

}  // namespace robocal::calib
