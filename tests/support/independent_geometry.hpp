#pragma once
// Geometry written in the tests, independent of the planner's FCL scene: the references that
// planned poses and collision verdicts are checked against.
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <functional>

namespace robocal::test {

// Minimum of a convex function on [0, 1] (golden section; 80 steps -> 1e-16 in t).
inline double convex_min(const std::function<double(double)>& f) {
  const double g = (std::sqrt(5.0) - 1) / 2;
  double a = 0, b = 1, c = b - g * (b - a), d = a + g * (b - a);
  double fc = f(c), fd = f(d);
  for (int i = 0; i < 80; ++i) {
    if (fc < fd) {
      b = d;
      d = c;
      fd = fc;
      c = b - g * (b - a);
      fc = f(c);
    } else {
      a = c;
      c = d;
      fc = fd;
      d = a + g * (b - a);
      fd = f(d);
    }
  }
  return std::min({f(0.0), f(1.0), fc, fd});
}

// An oriented box: centre, rotation (columns: its axes in the world) and half sizes.
struct Box {
  Eigen::Vector3d centre;
  Eigen::Matrix3d rotation;
  Eigen::Vector3d half;
};

// Distance from a point to a box (0 inside).
inline double point_box(const Eigen::Vector3d& p, const Box& box) {
  const Eigen::Vector3d local = box.rotation.transpose() * (p - box.centre);
  return (local.cwiseAbs() - box.half).cwiseMax(0.0).norm();
}

}  // namespace robocal::test
