#include "robocal/calib/closed_form.hpp"

#include <cmath>

namespace robocal::calib {
namespace {

// Intersection of three spheres; the solution on the requested side of the centres' plane.
std::optional<Eigen::Vector3d> trilaterate(const Eigen::Vector3d& c1, const Eigen::Vector3d& c2,
                                           const Eigen::Vector3d& c3, double r1, double r2,
                                           double r3, const Eigen::Vector3d& branch_dir,
                                           double branch_sign) {
  const Eigen::Vector3d e12 = c2 - c1;
  const double d = e12.norm();
  if (d < 1e-12) return std::nullopt;
  const Eigen::Vector3d ex = e12 / d;
  const double i = ex.dot(c3 - c1);
  Eigen::Vector3d ey = c3 - c1 - i * ex;
  const double j = ey.norm();
  if (j < 1e-12) return std::nullopt;
  ey /= j;
  const Eigen::Vector3d ez = ex.cross(ey);
  const double x = (r1 * r1 - r2 * r2 + d * d) / (2 * d);
  const double y = (r1 * r1 - r3 * r3 + i * i + j * j) / (2 * j) - i * x / j;
  const double z2 = r1 * r1 - x * x - y * y;
  if (z2 < 0) return std::nullopt;
  double z = std::sqrt(z2);
  if (branch_sign * ez.dot(branch_dir) < 0) z = -z;
  return c1 + x * ex + y * ey + z * ez;
}

Eigen::Vector3d rz(double phi, const Eigen::Vector3d& v) {
  const double c = std::cos(phi), s = std::sin(phi);
  return {c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z()};
}

}  // namespace

std::optional<Eigen::Vector3d> delta_forward(const ClosedFormSpec& s,
                                             const Eigen::Vector3d& theta) {
  Eigen::Vector3d c[3];
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d elbow(s.base_radius + s.upper_arm * std::cos(theta[i]), 0.0,
                                -s.upper_arm * std::sin(theta[i]));
    c[i] = rz(s.arm_angles[static_cast<std::size_t>(i)],
              elbow - Eigen::Vector3d(s.plate_radius, 0, 0));
  }
  return trilaterate(c[0], c[1], c[2], s.rod, s.rod, s.rod, Eigen::Vector3d::UnitZ(), -1.0);
}

std::optional<Eigen::Vector3d> delta_inverse(const ClosedFormSpec& s, const Eigen::Vector3d& T) {
  Eigen::Vector3d theta;
  for (int i = 0; i < 3; ++i) {
    // Plate joint relative to the shoulder, in the arm's vertical plane.
    const Eigen::Vector3d p = rz(-s.arm_angles[static_cast<std::size_t>(i)], T) +
                              Eigen::Vector3d(s.plate_radius - s.base_radius, 0, 0);
    // (n cos t - x)^2 + y^2 + (n sin t + z)^2 = m^2  ->  -x cos t + z sin t = K
    const double n = s.upper_arm;
    const double K = (s.rod * s.rod - n * n - p.squaredNorm()) / (2 * n);
    const double A = -p.x(), B = p.z();
    const double R = std::hypot(A, B);
    if (R < 1e-15 || std::abs(K) > R) return std::nullopt;
    const double base = std::atan2(B, A), delta = std::acos(K / R);
    const double t1 = base + delta, t2 = base - delta;
    theta[i] = std::cos(t1) >= std::cos(t2) ? t1 : t2;  // elbow out
    theta[i] = std::remainder(theta[i], 2 * M_PI);
  }
  return theta;
}

std::optional<Eigen::Vector3d> rails_forward(const ClosedFormSpec& s, const Eigen::Vector3d& q) {
  Eigen::Vector3d c[3];
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    c[i] = s.rail_origin[k] + q[i] * s.rail_direction[k] - s.platform_offset[k];
  }
  return trilaterate(c[0], c[1], c[2], s.link_length[0], s.link_length[1], s.link_length[2],
                     s.branch_direction, s.branch_sign);
}

std::optional<Eigen::Vector3d> rails_inverse(const ClosedFormSpec& s, const Eigen::Vector3d& T) {
  Eigen::Vector3d q;
  for (int i = 0; i < 3; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const Eigen::Vector3d& v = s.rail_direction[k];
    const Eigen::Vector3d D = T + s.platform_offset[k] - s.rail_origin[k];
    const double a = v.squaredNorm(), b = v.dot(D),
                 c = D.squaredNorm() - s.link_length[k] * s.link_length[k];
    const double disc = b * b - a * c;
    if (disc < 0 || a <= 0) return std::nullopt;
    const double r = std::sqrt(disc);
    const double q1 = (b + r) / a, q2 = (b - r) / a;
    // T must lie on the branch side of the rail point: larger (T - point).dir * sign wins.
    auto side = [&](double qi) { return s.branch_sign * (D - qi * v).dot(s.branch_direction); };
    q[i] = side(q1) >= side(q2) ? q1 : q2;
  }
  return q;
}

std::optional<Eigen::Vector3d> closed_form_forward(const ClosedFormSpec& spec,
                                                   const Eigen::VectorXd& q) {
  if (q.size() != 3) return std::nullopt;
  switch (spec.kind) {
    case ClosedFormKind::kRotaryDelta:
      return delta_forward(spec, q);
    case ClosedFormKind::kLinearDelta:
    case ClosedFormKind::kGantryTau:
      return rails_forward(spec, q);
    case ClosedFormKind::kNone:
      break;
  }
  return std::nullopt;
}

std::optional<Eigen::VectorXd> closed_form_inverse(const ClosedFormSpec& spec,
                                                   const Eigen::Vector3d& T) {
  std::optional<Eigen::Vector3d> q;
  switch (spec.kind) {
    case ClosedFormKind::kRotaryDelta:
      q = delta_inverse(spec, T);
      break;
    case ClosedFormKind::kLinearDelta:
    case ClosedFormKind::kGantryTau:
      q = rails_inverse(spec, T);
      break;
    case ClosedFormKind::kNone:
      break;
  }
  if (!q) return std::nullopt;
  return Eigen::VectorXd(*q);
}

}  // namespace robocal::calib
