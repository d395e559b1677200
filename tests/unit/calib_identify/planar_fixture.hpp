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

#include "robocal/calib/identification.hpp"

namespace robocal::calib::testing {

// The planar arm as a FramePredictor: measured frame at the tool point, yawed with the arm.
// Poses with |q2| > 3 rad are declared unsolvable (stands in for a closure that fails).
class PlanarPredictor : public FramePredictor {
 public:
  std::size_t parameter_count() const override { return kPlanarCount; }
  std::vector<std::string> parameter_names() const override { return planar_names(); }
  bool predict(const Eigen::VectorXd& a, const Eigen::VectorXd& q, int /*slot*/, bool with_jacobian,
               FramePrediction& out, std::string& why) const override {
    if (q.size() != 2) {
      why = "expected 2 actuator readings";
      return false;
    }
    if (std::abs(q(1)) > 3.0) {
      why = "joint 2 beyond its range";
      return false;
    }
    const Eigen::Vector3d p = planar_position<double>(a.data(), q(0), q(1));
    const double yaw = a(kYaw) + q(0) + a(kO1) + q(1) + a(kO2);
    out.pose = Eigen::Isometry3d::Identity();
    out.pose.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    out.pose.translation() = p;
    if (with_jacobian) {
      out.jacobian.setZero(6, kPlanarCount);
      out.jacobian.topRows<3>() = planar_jacobian(a, q(0), q(1));
      out.jacobian(5, kYaw) = out.jacobian(5, kO1) = out.jacobian(5, kO2) = 1.0;
    }
    return true;
  }
};

inline std::vector<Eigen::VectorXd> planar_actuators(int count, unsigned seed) {
  std::vector<Eigen::VectorXd> out;
  for (const auto& s : planar_poses(count, -2.0, 2.0, seed))
    out.push_back(Eigen::Vector2d(s.q1, s.q2));
  return out;
}

inline Eigen::VectorXd planar_truth() {
  Eigen::VectorXd t = planar_nominal();
  t(kBx) += 3e-3;
  t(kBy) -= 2e-3;
  t(kBz) += 1e-3;
  t(kO1) += 0.01;
  t(kO2) -= 0.02;
  t(kL1) += 2e-3;
  t(kL2) -= 1.5e-3;
  t(kToolLen) += 1e-3;  // redundant with link 2: only the sum is identifiable
  return t;
}

// The true planar arm measured as `sim` says at `count` actuator draws; `seed` seeds both the
// draws and the simulation's noise.
inline Measurements simulate_planar(const SimulationOptions& sim, int count, unsigned seed) {
  PlanarPredictor model;
  std::mt19937 rng(seed);
  return simulate_measurements(model, planar_truth(), planar_actuators(count, seed), sim, rng);
}

// Solve order that fixes the base and geometry before the offsets and the tool.
inline SolveOptions planar_geometry_first() {
  SolveOptions opt;
  opt.preference = {1, 1, 1, 1, 0, 0, 0, 0, 2, 2};
  return opt;
}

// Held-out prediction error of `estimate` against `truth` (tool positions over 100 fresh
// actuator draws), metres RMS.
inline double planar_heldout_rms(const Eigen::VectorXd& estimate, const Eigen::VectorXd& truth,
                                 unsigned seed = 99) {
  PlanarPredictor model;
  double sum = 0.0;
  const auto qs = planar_actuators(100, seed);
  for (const auto& q : qs) {
    FramePrediction a;
    FramePrediction b;
    std::string why;
    model.predict(estimate, q, 0, false, a, why);
    model.predict(truth, q, 0, false, b, why);
    sum += (a.pose.translation() - b.pose.translation()).squaredNorm();
  }
  return std::sqrt(sum / static_cast<double>(qs.size()));
}

}  // namespace robocal::calib::testing
