#pragma once
// Templated camera projection models, usable with double and ceres::Jet (basalt-headers style:
// one struct per model, a fixed parameter layout, `project` templated on the scalar type).
//
// PIXEL CONVENTION (the one convention of the whole project): OpenCV's. Pixel (0,0) is the
// CENTRE of the top-left pixel; u grows to the right, v grows downwards; the image covers
// [-0.5, width-0.5] x [-0.5, height-0.5]. AprilTag reports (0,0) at the top-left pixel's corner:
// subtract 0.5 px from its coordinates before using them with these models.
//
// Camera frame: x right, y down, z forward along the optical axis (OpenCV).
//
// Parameter layouts (all lengths in pixels for f and c):
//   PinholeRadtan   (9):  fx fy cx cy k1 k2 p1 p2 k3            == cv::projectPoints, 5 coeffs
//   PinholeRational (12): fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6   == cv::projectPoints, 8 coeffs
//   FisheyeKB4      (8):  fx fy cx cy k1 k2 k3 k4               == cv::fisheye::projectPoints
//                                                                   (skew alpha = 0)
#include <cmath>

namespace robocal::vision {

namespace detail {

// OpenCV's Brown-Conrady distortion of normalised coordinates (x, y) = (X/Z, Y/Z).
// `d` = k1 k2 p1 p2 k3 [k4 k5 k6]; `rational` selects the 8-coefficient form.
template <class T>
bool distort_brown_conrady(const T* d, bool rational, const T& x, const T& y, T* xd, T* yd) {
  const T r2 = x * x + y * y;
  const T r4 = r2 * r2;
  const T r6 = r4 * r2;
  const T num = T(1) + d[0] * r2 + d[1] * r4 + d[4] * r6;
  T radial = num;
  if (rational) {
    const T den = T(1) + d[5] * r2 + d[6] * r4 + d[7] * r6;
    if (!(den > T(0))) return false;  // the rational model is undefined beyond its pole
    radial = num / den;
  }
  const T p1 = d[2];
  const T p2 = d[3];
  *xd = x * radial + T(2) * p1 * x * y + p2 * (r2 + T(2) * x * x);
  *yd = y * radial + p1 * (r2 + T(2) * y * y) + T(2) * p2 * x * y;
  return true;
}

}  // namespace detail

// Pinhole + Brown-Conrady with k1 k2 p1 p2 k3 (OpenCV's default 5-coefficient model).
struct PinholeRadtan {
  static constexpr int kNumParams = 9;
  static constexpr const char* kName = "pinhole_radtan";

  // Projects a point in the camera frame to a pixel. Returns false for points with Z <= 0.
  template <class T>
  static bool project(const T* params, const T* p_cam, T* pixel) {
    using std::abs;
    if (!(p_cam[2] > T(0))) return false;
    const T x = p_cam[0] / p_cam[2];
    const T y = p_cam[1] / p_cam[2];
    T xd, yd;
    if (!detail::distort_brown_conrady(params + 4, false, x, y, &xd, &yd)) return false;
    pixel[0] = params[0] * xd + params[2];
    pixel[1] = params[1] * yd + params[3];
    return true;
  }
};

// Pinhole + rational Brown-Conrady k1 k2 p1 p2 k3 k4 k5 k6 (OpenCV CALIB_RATIONAL_MODEL).
struct PinholeRational {
  static constexpr int kNumParams = 12;
  static constexpr const char* kName = "pinhole_rational";

  template <class T>
  static bool project(const T* params, const T* p_cam, T* pixel) {
    if (!(p_cam[2] > T(0))) return false;
    const T x = p_cam[0] / p_cam[2];
    const T y = p_cam[1] / p_cam[2];
    T xd, yd;
    if (!detail::distort_brown_conrady(params + 4, true, x, y, &xd, &yd)) return false;
    pixel[0] = params[0] * xd + params[2];
    pixel[1] = params[1] * yd + params[3];
    return true;
  }
};

// Kannala-Brandt with four coefficients, identical to OpenCV's fisheye model for Z > 0:
// theta = angle from the optical axis, theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8),
// pixel = f * theta_d * (X, Y)/|(X, Y)| + c. Unlike OpenCV it also accepts Z <= 0 (theta up to
// pi), which wide lenses can see; it returns false only on the optical axis behind the camera.
struct FisheyeKB4 {
  static constexpr int kNumParams = 8;
  static constexpr const char* kName = "fisheye_kb4";

  template <class T>
  static bool project(const T* params, const T* p_cam, T* pixel) {
    using std::atan2;
    using std::sqrt;
    const T& X = p_cam[0];
    const T& Y = p_cam[1];
    const T& Z = p_cam[2];
    const T rxy2 = X * X + Y * Y;
    T mx, my;  // theta_d * (X, Y) / |(X, Y)|
    // Near the axis theta_d / r_xy -> 1/Z; this branch avoids sqrt(0), whose Jet derivative is
    // infinite. 1e-18 (relative) keeps both branches within double precision of each other.
    if (rxy2 > T(1e-18) * Z * Z) {
      const T rxy = sqrt(rxy2);
      const T theta = atan2(rxy, Z);
      const T t2 = theta * theta;
      const T theta_d =
          theta * (T(1) + t2 * (params[4] + t2 * (params[5] + t2 * (params[6] + t2 * params[7]))));
      const T s = theta_d / rxy;
      mx = s * X;
      my = s * Y;
    } else {
      if (!(Z > T(0))) return false;
      mx = X / Z;
      my = Y / Z;
    }
    pixel[0] = params[0] * mx + params[2];
    pixel[1] = params[1] * my + params[3];
    return true;
  }
};

}  // namespace robocal::vision
