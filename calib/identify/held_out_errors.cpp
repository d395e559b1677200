#include "robocal/calib/held_out_errors.hpp"

#include <Eigen/Geometry>

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

}  // namespace robocal::calib
