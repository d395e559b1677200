#pragma once
// Test fixture only: a planar two-link arm moving in a horizontal plane, with base and tool
// parameters chosen so that the redundancies are known in closed form:
//   base yaw ≡ encoder offset 1, tool length ≡ link length 2, tool z ≡ base z.
// Derivatives come from Jets (exact), so the fixture needs no finite differences.
#include <ceres/jet.h>
#include <Eigen/Core>

#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace robocal::calib::testing {

enum PlanarParam { kBx, kBy, kBz, kYaw, kO1, kO2, kL1, kL2, kToolLen, kToolZ, kPlanarCount };

inline std::vector<std::string> planar_names() {
  return {"base.x",        "base.y",       "base.z",       "base.yaw",    "joint1.offset",
          "joint2.offset", "link1.length", "link2.length", "tool.length", "tool.z"};
}

inline Eigen::VectorXd planar_nominal() {
  Eigen::VectorXd a(kPlanarCount);
  a << 0.1, -0.2, 0.3, 0.0, 0.0, 0.0, 0.5, 0.4, 0.05, 0.02;
  return a;
}

template <typename T>
Eigen::Matrix<T, 3, 1> planar_position(const T* a, double q1, double q2) {
  using std::cos;
  using std::sin;
  const T t1 = a[kYaw] + T(q1) + a[kO1];
  const T t2 = t1 + T(q2) + a[kO2];
  const T reach2 = a[kL2] + a[kToolLen];
  Eigen::Matrix<T, 3, 1> p;
  p << a[kBx] + a[kL1] * cos(t1) + reach2 * cos(t2), a[kBy] + a[kL1] * sin(t1) + reach2 * sin(t2),
      a[kBz] + a[kToolZ];
  return p;
}

// 3×10 Jacobian of the tool position at joint values (q1, q2).
inline Eigen::Matrix<double, 3, kPlanarCount> planar_jacobian(const Eigen::VectorXd& a, double q1,
                                                              double q2) {
  using J = ceres::Jet<double, kPlanarCount>;
  J aj[kPlanarCount];
  for (int i = 0; i < kPlanarCount; ++i) aj[i] = J(a(i), i);
  const auto p = planar_position<J>(aj, q1, q2);
  Eigen::Matrix<double, 3, kPlanarCount> jac;
  for (int r = 0; r < 3; ++r) jac.row(r) = p(r).v.transpose();
  return jac;
}

struct JointSample {
  double q1;
  double q2;
};

inline std::vector<JointSample> planar_poses(int count, double q2_min, double q2_max,
                                             unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u1(-2.5, 2.5);
  std::uniform_real_distribution<double> u2(q2_min, q2_max);
  std::vector<JointSample> poses;
  for (int i = 0; i < count; ++i) poses.push_back({u1(rng), u2(rng)});
  return poses;
}

inline Eigen::MatrixXd stacked_jacobian(const Eigen::VectorXd& a,
                                        const std::vector<JointSample>& poses) {
  Eigen::MatrixXd J(3 * static_cast<Eigen::Index>(poses.size()), kPlanarCount);
  for (std::size_t k = 0; k < poses.size(); ++k)
    J.middleRows<3>(3 * static_cast<Eigen::Index>(k)) =
        planar_jacobian(a, poses[k].q1, poses[k].q2);
  return J;
}

}  // namespace robocal::calib::testing
