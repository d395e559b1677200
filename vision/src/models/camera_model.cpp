#include "robocal/vision/camera_model.hpp"

#include <ceres/jet.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace robocal::vision {

int num_params(CameraKind kind) {
  return visit_camera_kind(kind, [](auto model) { return decltype(model)::kNumParams; });
}

std::string_view kind_name(CameraKind kind) {
  return visit_camera_kind(kind,
                           [](auto model) { return std::string_view(decltype(model)::kName); });
}

std::optional<CameraKind> kind_from_name(std::string_view name) {
  for (CameraKind k :
       {CameraKind::kPinholeRadtan, CameraKind::kPinholeRational, CameraKind::kFisheyeKB4}) {
    if (kind_name(k) == name) return k;
  }
  return std::nullopt;
}

CameraModel make_camera(CameraKind kind, int width, int height, double fx, double fy, double cx,
                        double cy, const std::vector<double>& distortion) {
  CameraModel cam;
  cam.kind = kind;
  cam.width = width;
  cam.height = height;
  cam.params.assign(static_cast<size_t>(num_params(kind)), 0.0);
  cam.params[0] = fx;
  cam.params[1] = fy;
  cam.params[2] = cx;
  cam.params[3] = cy;
  for (size_t i = 0; i < distortion.size() && i + 4 < cam.params.size(); ++i)
    cam.params[i + 4] = distortion[i];
  return cam;
}

std::string validate_camera(const CameraModel& camera) {
  const int n = num_params(camera.kind);
  if (static_cast<int>(camera.params.size()) != n)
    return std::string(kind_name(camera.kind)) + " needs " + std::to_string(n) +
           " parameters, got " + std::to_string(camera.params.size());
  if (camera.width <= 0 || camera.height <= 0) return "image width and height must be positive";
  for (double p : camera.params)
    if (!std::isfinite(p)) return "parameters must be finite numbers";
  if (!(camera.params[0] > 0.0) || !(camera.params[1] > 0.0))
    return "focal lengths fx, fy must be positive";
  return {};
}

std::optional<Eigen::Vector2d> project(const CameraModel& camera, const Eigen::Vector3d& p_cam) {
  Eigen::Vector2d px;
  const bool ok = visit_camera_kind(camera.kind, [&](auto model) {
    return decltype(model)::project(camera.params.data(), p_cam.data(), px.data());
  });
  if (!ok) return std::nullopt;
  return px;
}

namespace {

// Newton iteration on OpenCV's Brown-Conrady distortion: finds (x, y) with distort(x, y) = m.
std::optional<Eigen::Vector3d> unproject_brown_conrady(const CameraModel& camera,
                                                       const Eigen::Vector2d& pixel,
                                                       const Eigen::Vector3d* guess) {
  const double* p = camera.params.data();
  const bool rational = camera.kind == CameraKind::kPinholeRational;
  double d[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::copy(p + 4, p + camera.params.size(), d);
  const Eigen::Vector2d m((pixel.x() - p[2]) / p[0], (pixel.y() - p[3]) / p[1]);

  // Residual and its analytic 2x2 Jacobian at (x, y) (OpenCV's distortion, differentiated).
  auto eval = [&](const Eigen::Vector2d& xy, Eigen::Vector2d* r, Eigen::Matrix2d* jac) {
    const double x = xy.x(), y = xy.y();
    const double r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
    const double num = 1 + d[0] * r2 + d[1] * r4 + d[4] * r6;
    const double dnum = d[0] + 2 * d[1] * r2 + 3 * d[4] * r4;
    double den = 1, dden = 0;
    if (rational) {
      den = 1 + d[5] * r2 + d[6] * r4 + d[7] * r6;
      dden = d[5] + 2 * d[6] * r2 + 3 * d[7] * r4;
      if (!(den > 0)) return false;
    }
    const double R = num / den;
    const double dR = (dnum * den - num * dden) / (den * den);  // dR / d(r^2)
    const double p1 = d[2], p2 = d[3];
    *r << x * R + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - m.x(),
        y * R + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - m.y();
    const double off = 2 * x * y * dR + 2 * p1 * x + 2 * p2 * y;
    *jac << R + 2 * x * x * dR + 2 * p1 * y + 6 * p2 * x, off, off,
        R + 2 * y * y * dR + 6 * p1 * y + 2 * p2 * x;
    return true;
  };

  Eigen::Vector2d xy = m;
  if (guess && guess->allFinite() && guess->z() > 1e-12) xy = guess->head<2>() / guess->z();
  Eigen::Vector2d r;
  Eigen::Matrix2d jac;
  if (!eval(xy, &r, &jac)) return std::nullopt;
  for (int iter = 0; iter < 100 && r.norm() > 1e-17 * (1.0 + m.norm()); ++iter) {
    const double det = jac.determinant();
    if (!(std::abs(det) > 1e-14)) return std::nullopt;
    Eigen::Vector2d step = jac.inverse() * r;
    if (step.norm() <= 1e-16 * (1.0 + xy.norm())) break;  // converged to double precision
    // Backtracking keeps the iteration from jumping across a fold of a strong distortion.
    bool improved = false;
    for (int half = 0; half < 40; ++half) {
      Eigen::Vector2d r_new;
      Eigen::Matrix2d jac_new;
      const Eigen::Vector2d xy_new = xy - step;
      if (eval(xy_new, &r_new, &jac_new) && r_new.norm() <= r.norm()) {
        xy = xy_new;
        r = r_new;
        jac = jac_new;
        improved = true;
        break;
      }
      step *= 0.5;
    }
    if (!improved) break;  // at the limit of double precision
  }
  // Accept only a real solution on the orientation-preserving side of the distortion.
  const double residual_px = std::max(std::abs(r.x() * p[0]), std::abs(r.y() * p[1]));
  if (!(residual_px < 1e-9) || !(jac.determinant() > 0.0)) return std::nullopt;
  return Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
}

// Newton iteration on theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8).
std::optional<Eigen::Vector3d> unproject_kb4(const CameraModel& camera,
                                             const Eigen::Vector2d& pixel) {
  const double* p = camera.params.data();
  const Eigen::Vector2d m((pixel.x() - p[2]) / p[0], (pixel.y() - p[3]) / p[1]);
  const double theta_d = m.norm();
  if (theta_d < 1e-300) return Eigen::Vector3d(0, 0, 1);
  const double k1 = p[4], k2 = p[5], k3 = p[6], k4 = p[7];
  auto g = [&](double t) {
    const double t2 = t * t;
    return t * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d;
  };
  auto dg = [&](double t) {
    const double t2 = t * t;
    return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)));
  };
  double theta = theta_d;
  double r = g(theta);
  for (int iter = 0; iter < 100 && std::abs(r) > 1e-17 * (1.0 + theta_d); ++iter) {
    const double slope = dg(theta);
    if (!(slope > 1e-12)) return std::nullopt;
    double step = r / slope;
    if (std::abs(step) <= 1e-16 * (1.0 + theta)) break;  // converged to double precision
    bool improved = false;
    for (int half = 0; half < 40; ++half) {
      const double t_new = theta - step;
      const double r_new = g(t_new);
      if (t_new >= 0.0 && std::abs(r_new) <= std::abs(r)) {
        theta = t_new;
        r = r_new;
        improved = true;
        break;
      }
      step *= 0.5;
    }
    if (!improved) break;
  }
  const double residual_px = std::abs(r) * std::max(p[0], p[1]);
  if (!(residual_px < 1e-9) || !(dg(theta) > 0.0) || !(theta < std::numbers::pi))
    return std::nullopt;
  const double s = std::sin(theta) / theta_d;
  return Eigen::Vector3d(s * m.x(), s * m.y(), std::cos(theta));
}

}  // namespace

std::optional<Eigen::Vector3d> unproject(const CameraModel& camera, const Eigen::Vector2d& pixel) {
  if (static_cast<int>(camera.params.size()) != num_params(camera.kind)) return std::nullopt;
  if (camera.kind == CameraKind::kFisheyeKB4) return unproject_kb4(camera, pixel);
  return unproject_brown_conrady(camera, pixel, nullptr);
}

std::optional<Eigen::Vector3d> unproject(const CameraModel& camera, const Eigen::Vector2d& pixel,
                                         const Eigen::Vector3d& initial_bearing) {
  if (static_cast<int>(camera.params.size()) != num_params(camera.kind)) return std::nullopt;
  if (camera.kind == CameraKind::kFisheyeKB4) return unproject_kb4(camera, pixel);
  return unproject_brown_conrady(camera, pixel, &initial_bearing);
}

bool in_image(const CameraModel& camera, const Eigen::Vector2d& pixel, double margin) {
  return pixel.x() >= -0.5 + margin && pixel.y() >= -0.5 + margin &&
         pixel.x() <= camera.width - 0.5 - margin && pixel.y() <= camera.height - 0.5 - margin;
}

bool project_jacobians(const CameraModel& camera, const Eigen::Vector3d& p_cam,
                       Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* d_point,
                       Eigen::MatrixXd* d_params) {
  return visit_camera_kind(camera.kind, [&](auto model) {
    using M = decltype(model);
    constexpr int kN = M::kNumParams + 3;
    using J = ceres::Jet<double, kN>;
    J params[M::kNumParams];
    J point[3];
    for (int i = 0; i < M::kNumParams; ++i) params[i] = J(camera.params[static_cast<size_t>(i)], i);
    for (int i = 0; i < 3; ++i) point[i] = J(p_cam[i], M::kNumParams + i);
    J px[2];
    if (!M::project(params, point, px)) return false;
    if (pixel) *pixel << px[0].a, px[1].a;
    if (d_point)
      for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c) (*d_point)(r, c) = px[r].v[M::kNumParams + c];
    if (d_params) {
      d_params->resize(2, M::kNumParams);
      for (int r = 0; r < 2; ++r)
        for (int c = 0; c < M::kNumParams; ++c) (*d_params)(r, c) = px[r].v[c];
    }
    return true;
  });
}

double projection_difference_px(const CameraModel& other, const CameraModel& reference) {
  double sum = 0;
  int n = 0;
  for (int j = 0; j <= 10; ++j) {
    for (int i = 0; i <= 10; ++i) {
      const Eigen::Vector2d px(i * (reference.width - 1) / 10.0, j * (reference.height - 1) / 10.0);
      const auto ray = unproject(reference, px);
      if (!ray) continue;
      const auto p = project(other, *ray / ray->z());
      if (!p) continue;
      sum += (*p - px).squaredNorm();
      ++n;
    }
  }
  return n > 0 ? std::sqrt(sum / n) : std::numeric_limits<double>::infinity();
}

}  // namespace robocal::vision
