#include "robocal/calib/held_out_errors.hpp"

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace robocal::calib {

namespace {

// Running sum of squares and maximum, in the order the errors come.
struct Accumulator {
  PositionErrorStats stats;
  double sum_squares = 0.0;
  void add(double e) {
    sum_squares += e * e;
    stats.max = std::max(stats.max, e);
    ++stats.n;
  }
  PositionErrorStats finish() {
    stats.rms = stats.n > 0 ? std::sqrt(sum_squares / static_cast<double>(stats.n)) : 0.0;
    return stats;
  }
};

}  // namespace

PositionErrorStats position_error_stats(const std::vector<Eigen::Vector3d>& predicted,
                                        const std::vector<Eigen::Vector3d>& truth) {
  if (predicted.size() != truth.size())
    throw std::invalid_argument("position_error_stats: one prediction per true position needed");
  Accumulator acc;
  for (std::size_t i = 0; i < predicted.size(); ++i) acc.add((predicted[i] - truth[i]).norm());
  return acc.finish();
}

HeldOutErrors held_out_errors(const std::vector<Eigen::Vector3d>& predicted,
                              const std::vector<Eigen::Vector3d>& truth) {
  HeldOutErrors out;
  out.absolute = position_error_stats(predicted, truth);
  Eigen::Matrix3Xd P(3, static_cast<Eigen::Index>(predicted.size()));
  Eigen::Matrix3Xd T(3, P.cols());
  for (std::size_t i = 0; i < predicted.size(); ++i) {
    P.col(static_cast<Eigen::Index>(i)) = predicted[i];
    T.col(static_cast<Eigen::Index>(i)) = truth[i];
  }
  if (P.cols() >= 3) {
    const Eigen::Isometry3d align(Eigen::umeyama(P, T, false));
    for (Eigen::Index i = 0; i < P.cols(); ++i)
      out.registered_points.push_back(align * Eigen::Vector3d(P.col(i)));
    out.registered = position_error_stats(out.registered_points, truth);
  }
  return out;
}

std::optional<Eigen::Isometry3d> realised_frame(const std::vector<Eigen::Vector3d>& measured,
                                                const std::vector<Eigen::Vector3d>& truth) {
  if (measured.size() != truth.size())
    throw std::invalid_argument("realised_frame: one measured position per true position needed");
  if (truth.size() < 3) return std::nullopt;
  Eigen::Matrix3Xd M(3, static_cast<Eigen::Index>(measured.size()));
  Eigen::Matrix3Xd T(3, M.cols());
  for (std::size_t i = 0; i < measured.size(); ++i) {
    M.col(static_cast<Eigen::Index>(i)) = measured[i];
    T.col(static_cast<Eigen::Index>(i)) = truth[i];
  }
  const Eigen::Matrix3Xd spread = T.colwise() - T.rowwise().mean();
  const Eigen::Vector3d s = Eigen::JacobiSVD<Eigen::Matrix3Xd>(spread).singularValues();
  if (!(s(1) > 1e-3 * s(0))) return std::nullopt;
  return Eigen::Isometry3d(Eigen::umeyama(T, M, false));
}

}  // namespace robocal::calib
