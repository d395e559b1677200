#include "robocal/calib/measured_region.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>

namespace robocal::calib {

namespace {

// The point of the affine hull of d[S] nearest the origin, as affine weights (sum 1):
// minimise |D a|^2 subject to sum(a) = 1 (KKT system; D's columns are d[S]).
Eigen::VectorXd affine_minimiser(const std::vector<Eigen::Vector3d>& d,
                                 const std::vector<std::size_t>& S) {
  const auto k = static_cast<Eigen::Index>(S.size());
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(k + 1, k + 1);
  for (Eigen::Index i = 0; i < k; ++i) {
    for (Eigen::Index j = 0; j < k; ++j)
      K(i, j) = d[S[static_cast<std::size_t>(i)]].dot(d[S[static_cast<std::size_t>(j)]]);
    K(i, k) = K(k, i) = 1.0;
  }
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(k + 1);
  rhs[k] = 1.0;
  return K.completeOrthogonalDecomposition().solve(rhs).head(k);
}

}  // namespace

RegionDistance distance_to_region(const std::vector<Eigen::Vector3d>& measured,
                                  const Eigen::Vector3d& p) {
  RegionDistance out;
  if (measured.empty()) {
    out.outside_m = out.nearest_measured_m = std::numeric_limits<double>::infinity();
    out.closest = p;
    return out;
  }
  // Work relative to p: the hull's minimum-norm point is the nearest point to p.
  std::vector<Eigen::Vector3d> d(measured.size());
  double scale = 0.0;
  std::size_t nearest = 0;
  for (std::size_t i = 0; i < measured.size(); ++i) {
    d[i] = measured[i] - p;
    scale = std::max(scale, d[i].squaredNorm());
    if (d[i].squaredNorm() < d[nearest].squaredNorm()) nearest = i;
  }
  out.nearest_measured_m = d[nearest].norm();
  // Wolfe's minimum-norm-point algorithm: a "corral" S of affinely independent points with
  // convex weights w; x = sum w d[S]. A major cycle adds the point most opposed to x; minor
  // cycles drop points until x is the affine minimiser of S inside conv(S). In 3-D, |S| <= 4.
  const double tol = 1e-12 * std::max(scale, 1e-300);
  std::vector<std::size_t> S{nearest};
  std::vector<double> w{1.0};
  Eigen::Vector3d x = d[nearest];
  const auto combine = [&] {
    Eigen::Vector3d y = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < S.size(); ++i) y += w[i] * d[S[i]];
    return y;
  };
  out.converged = false;
  for (int major = 0; major < 1000; ++major) {
    if (x.squaredNorm() <= 1e-24 * std::max(scale, 1e-300)) {
      out.converged = true;  // the origin (p) is in the hull
      break;
    }
    std::size_t j = 0;
    for (std::size_t i = 1; i < d.size(); ++i)
      if (x.dot(d[i]) < x.dot(d[j])) j = i;
    if (x.dot(d[j]) >= x.squaredNorm() - tol || std::find(S.begin(), S.end(), j) != S.end()) {
      out.converged = true;  // no point improves on x: x is the minimum-norm point
      break;
    }
    S.push_back(j);
    w.push_back(0.0);
    for (int minor = 0; minor < 100; ++minor) {
      const Eigen::VectorXd a = affine_minimiser(d, S);
      if (a.minCoeff() > 1e-14) {  // the affine minimiser lies inside conv(S)
        for (std::size_t i = 0; i < S.size(); ++i) w[i] = a[static_cast<Eigen::Index>(i)];
        break;
      }
      // Move from w towards a until a weight reaches zero, and drop that point.
      double theta = 1.0;
      for (std::size_t i = 0; i < S.size(); ++i) {
        const double ai = a[static_cast<Eigen::Index>(i)];
        if (ai <= 1e-14 && w[i] - ai > 0.0) theta = std::min(theta, w[i] / (w[i] - ai));
      }
      double sum = 0.0;
      std::vector<std::size_t> kept_S;
      std::vector<double> kept_w;
      for (std::size_t i = 0; i < S.size(); ++i) {
        const double wi = (1.0 - theta) * w[i] + theta * a[static_cast<Eigen::Index>(i)];
        if (wi > 1e-14) {
          kept_S.push_back(S[i]);
          kept_w.push_back(wi);
          sum += wi;
        }
      }
      if (kept_S.empty()) {  // numerically degenerate: fall back to the newest point
        kept_S = {j};
        kept_w = {1.0};
        sum = 1.0;
      }
      for (double& wi : kept_w) wi /= sum;
      S = std::move(kept_S);
      w = std::move(kept_w);
    }
    x = combine();
  }
  out.outside_m = x.norm();
  out.inside = out.outside_m <= kRegionInsideTolerance;
  out.closest = p + x;
  for (std::size_t i = 0; i < S.size(); ++i) out.support.emplace_back(S[i], w[i]);
  return out;
}

}  // namespace robocal::calib
