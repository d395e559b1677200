#include "robocal/calib/bed_plane.hpp"

#include <algorithm>
#include <limits>

namespace robocal::calib {

BedPlanePredictor::BedPlanePredictor(const FramePredictor& inner)
    : inner_(inner), inner_count_(inner.parameter_count()) {}

std::vector<std::string> BedPlanePredictor::parameter_labels() const {
  auto labels = inner_.parameter_labels();
  labels.emplace_back("bed tilt about x");
  labels.emplace_back("bed tilt about y");
  return labels;
}

std::vector<std::string> BedPlanePredictor::parameter_names() const {
  auto names = inner_.parameter_names();
  names.emplace_back("bed.tilt_x");
  names.emplace_back("bed.tilt_y");
  return names;
}

bool BedPlanePredictor::predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators,
                                int slot, bool with_jacobian, FramePrediction& out,
                                std::string& why) const {
  const auto n = static_cast<Eigen::Index>(inner_count_);
  if (!inner_.predict(params.head(n), actuators, slot, with_jacobian, out, why)) return false;
  if (with_jacobian)
    out.jacobian.conservativeResizeLike(Eigen::Matrix<double, 6, Eigen::Dynamic>::Zero(6, n + 2));
  return true;
}

bool BedPlanePredictor::pixel_residual(const PixelObservation& obs, const Eigen::VectorXd& params,
                                       const FramePrediction& frame, Eigen::Vector2d& residual,
                                       Eigen::Matrix<double, 2, Eigen::Dynamic>* jacobian,
                                       std::string& why) const {
  const auto n = static_cast<Eigen::Index>(inner_count_);
  FramePrediction inner_frame;
  inner_frame.pose = frame.pose;
  if (jacobian != nullptr) inner_frame.jacobian = frame.jacobian.leftCols(n);
  Eigen::Matrix<double, 2, Eigen::Dynamic> J;
  if (!inner_.pixel_residual(obs, params.head(n), inner_frame, residual,
                             jacobian != nullptr ? &J : nullptr, why))
    return false;
  if (jacobian != nullptr) {
    jacobian->setZero(2, n + 2);
    jacobian->leftCols(n) = J;
  }
  return true;
}

bool BedPlanePredictor::probe_residual(const ProbeHeightObservation& obs,
                                       const Eigen::VectorXd& params, const FramePrediction& frame,
                                       double& residual, Eigen::RowVectorXd* jacobian,
                                       std::string& why) const {
  if (!obs.normal.isApprox(Eigen::Vector3d::UnitZ())) {
    why =
        "a probe height with its own plane normal cannot be measured against an estimated bed "
        "plane (leave 'normal' out)";
    return false;
  }
  const auto n = static_cast<Eigen::Index>(inner_count_);
  const double tx = tilt_x(params);
  const double ty = tilt_y(params);
  const Eigen::Vector3d p = frame.pose.translation();
  residual = (p.z() - tx * p.x() - ty * p.y() - obs.offset - obs.measured_height) / obs.sigma;
  if (jacobian != nullptr) {
    jacobian->setZero(n + 2);
    const Eigen::RowVector3d d(-tx, -ty, 1.0);
    jacobian->head(n) = d * frame.jacobian.topLeftCorner(3, n) / obs.sigma;
    (*jacobian)(n) = -p.x() / obs.sigma;
    (*jacobian)(n + 1) = -p.y() / obs.sigma;
  }
  return true;
}

Eigen::VectorXd BedPlanePredictor::initial_parameters(const Eigen::VectorXd& inner_params) const {
  Eigen::VectorXd x = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(inner_count_) + 2);
  x.head(static_cast<Eigen::Index>(inner_count_)) = inner_params;
  return x;
}

SolveOptions BedPlanePredictor::solve_options(const SolveOptions& inner) const {
  const std::size_t P = parameter_count();
  SolveOptions opt = inner;
  if (opt.candidates.empty())
    for (std::size_t i = 0; i < inner_count_; ++i) opt.candidates.push_back(i);
  opt.candidates.push_back(inner_count_);
  opt.candidates.push_back(inner_count_ + 1);
  int highest = 0;
  for (int p : inner.preference) highest = std::max(highest, p);
  opt.preference.resize(inner_count_, 0);
  opt.preference.resize(P, highest + 1);
  auto extend = [&](std::vector<double>& v, double fill) {
    if (!v.empty()) v.resize(P, fill);
  };
  extend(opt.prior_sigma, 0.0);
  extend(opt.lower_bound, std::numeric_limits<double>::quiet_NaN());
  extend(opt.upper_bound, std::numeric_limits<double>::quiet_NaN());
  extend(opt.start_sigma, 0.0);
  return opt;
}

}  // namespace robocal::calib
