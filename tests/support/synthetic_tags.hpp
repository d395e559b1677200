#pragma once
// A small, exact renderer of planar AprilTag (tag36h11) grids and chessboards seen by an
// undistorted pinhole camera, for detector tests and benchmarks with known ground truth.
// Pixel convention: OpenCV's (pixel (u,v) covers [u-0.5,u+0.5] x [v-0.5,v+0.5]). Each pixel is the
// average of the board's reflectance over its area (adaptive 16x16 supersampling on edges), then
// Gaussian blur and Gaussian noise are applied (seeded).
#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <cstdlib>
#include <random>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
}

namespace robocal::testing {

struct SyntheticCamera {
  int width = 1280;
  int height = 1024;
  double f = 1200.0;
  double cx = 639.5;
  double cy = 511.5;
};

/// Board plane: x right, y down, z into the board; units mm.
struct TagGrid {
  int cols = 4;
  int rows = 3;
  double tag_mm = 40.0;  ///< outer size of the black border
  double gap_mm = 10.0;  ///< white space between black borders (>= 2 cells)
  int first_id = 0;
};

struct SyntheticImageOptions {
  double blur_sigma = 0.0;
  double noise_sigma = 0.0;
  double black = 20.0;
  double white = 220.0;
  unsigned seed = 1;
  int supersample = 16;
};

struct SyntheticTag {
  int id = 0;
  std::array<Eigen::Vector2d, 4> corners;  ///< AprilTag order, OpenCV pixel convention
};

/// Homography board(mm) -> image for pose (R, t) of the board in the camera frame.
inline Eigen::Matrix3d board_homography(const SyntheticCamera& cam, const Eigen::Matrix3d& r,
                                        const Eigen::Vector3d& t) {
  Eigen::Matrix3d k;
  k << cam.f, 0, cam.cx, 0, cam.f, cam.cy, 0, 0, 1;
  Eigen::Matrix3d m;
  m.col(0) = r.col(0);
  m.col(1) = r.col(1);
  m.col(2) = t;
  return k * m;
}

inline Eigen::Vector2d apply_h(const Eigen::Matrix3d& h, const Eigen::Vector2d& p) {
  const Eigen::Vector3d q = h * p.homogeneous();
  return q.hnormalized();
}

/// Pose looking at the board centre from distance `dist_mm`, board tilted by `tilt_deg` about an
/// axis in the board plane at angle `axis_deg` from the board x axis, then rotated in-plane by
/// `roll_deg`. The board centre projects to image point (u, v).
inline std::pair<Eigen::Matrix3d, Eigen::Vector3d> look_at_pose(const SyntheticCamera& cam,
                                                                const Eigen::Vector2d& board_centre,
                                                                double dist_mm, double tilt_deg,
                                                                double axis_deg, double roll_deg,
                                                                double u, double v) {
  const double d2r = M_PI / 180.0;
  const Eigen::Vector3d axis(std::cos(axis_deg * d2r), std::sin(axis_deg * d2r), 0.0);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(roll_deg * d2r, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(tilt_deg * d2r, axis).toRotationMatrix();
  const Eigen::Vector3d ray = Eigen::Vector3d((u - cam.cx) / cam.f, (v - cam.cy) / cam.f, 1.0);
  const Eigen::Vector3d centre_cam = ray.normalized() * dist_mm;
  const Eigen::Vector3d t = centre_cam - r * Eigen::Vector3d(board_centre.x(), board_centre.y(), 0);
  return {r, t};
}

/// Renders a planar reflectance function refl(x, y) in [0,1] (board units) seen through the
/// homography board -> image.
template <typename Reflectance>
cv::Mat render_planar(const SyntheticCamera& cam, const Eigen::Matrix3d& h,
                      const SyntheticImageOptions& opt, Reflectance&& refl) {
  const Eigen::Matrix3d hinv = h.inverse();
  auto to_board = [&](double u, double v) {
    const Eigen::Vector3d q = hinv * Eigen::Vector3d(u, v, 1.0);
    return Eigen::Vector2d(q.x() / q.z(), q.y() / q.z());
  };
  // Reflectance at pixel corners decides which pixels need supersampling.
  cv::Mat corner_val(cam.height + 1, cam.width + 1, CV_64F);
  for (int y = 0; y <= cam.height; ++y)
    for (int x = 0; x <= cam.width; ++x) {
      const Eigen::Vector2d b = to_board(x - 0.5, y - 0.5);
      corner_val.at<double>(y, x) = refl(b.x(), b.y());
    }
  cv::Mat img(cam.height, cam.width, CV_64F);
  const int s = opt.supersample;
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const double a = corner_val.at<double>(y, x);
      const double b = corner_val.at<double>(y, x + 1);
      const double c = corner_val.at<double>(y + 1, x);
      const double d = corner_val.at<double>(y + 1, x + 1);
      double value = a;
      // Edges thinner than a pixel do not occur (cells are several px), so equal corners mean a
      // uniform pixel... except near a cell boundary crossing the pixel twice; sample the centre
      // as a cheap check.
      const Eigen::Vector2d bc = to_board(x, y);
      if (a != b || a != c || a != d || a != refl(bc.x(), bc.y())) {
        double sum = 0.0;
        for (int j = 0; j < s; ++j)
          for (int i = 0; i < s; ++i) {
            const Eigen::Vector2d p = to_board(x - 0.5 + (i + 0.5) / s, y - 0.5 + (j + 0.5) / s);
            sum += refl(p.x(), p.y());
          }
        value = sum / (s * s);
      }
      img.at<double>(y, x) = opt.black + (opt.white - opt.black) * value;
    }
  }
  if (opt.blur_sigma > 0.0) {
    const int k = 2 * static_cast<int>(std::ceil(4.0 * opt.blur_sigma)) + 1;
    cv::GaussianBlur(img, img, cv::Size(k, k), opt.blur_sigma, opt.blur_sigma,
                     cv::BORDER_REPLICATE);
  }
  std::mt19937 rng(opt.seed);
  std::normal_distribution<double> noise(0.0, opt.noise_sigma > 0 ? opt.noise_sigma : 1.0);
  cv::Mat out(cam.height, cam.width, CV_8UC1);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      double v = img.at<double>(y, x);
      if (opt.noise_sigma > 0.0) v += noise(rng);
      out.at<unsigned char>(y, x) = cv::saturate_cast<unsigned char>(std::lround(v));
    }
  return out;
}

/// Tag36h11 grid renderer. Returns the 8-bit image; fills `truth` with every tag fully inside.
class TagGridRenderer {
 public:
  explicit TagGridRenderer(TagGrid grid) : grid_(grid) {
    apriltag_family_t* fam = tag36h11_create();
    total_ = fam->total_width;
    border_start_ = (fam->total_width - fam->width_at_border) / 2;
    width_at_border_ = fam->width_at_border;
    for (int k = 0; k < grid_.cols * grid_.rows; ++k) {
      image_u8_t* im = apriltag_to_image(fam, grid_.first_id + k);
      std::vector<unsigned char> bits(static_cast<size_t>(total_ * total_));
      for (int y = 0; y < total_; ++y)
        for (int x = 0; x < total_; ++x)
          bits[static_cast<size_t>(y * total_ + x)] = im->buf[y * im->stride + x] > 127 ? 1 : 0;
      patterns_.push_back(bits);
      // image_u8_destroy is not exported by Debian's libapriltag 3.3; it is two free() calls.
      std::free(im->buf);
      std::free(im);
    }
    tag36h11_destroy(fam);
  }

  [[nodiscard]] Eigen::Vector2d board_size() const {
    return {grid_.cols * grid_.tag_mm + (grid_.cols + 1) * grid_.gap_mm,
            grid_.rows * grid_.tag_mm + (grid_.rows + 1) * grid_.gap_mm};
  }

  /// Board reflectance in [0,1] at board point (mm); 1 outside the tags.
  [[nodiscard]] double reflectance(double x, double y) const {
    const double pitch = grid_.tag_mm + grid_.gap_mm;
    const double gx = (x - grid_.gap_mm) / pitch;
    const double gy = (y - grid_.gap_mm) / pitch;
    if (gx < 0 || gy < 0) return 1.0;
    const int c = static_cast<int>(gx);
    const int r = static_cast<int>(gy);
    if (c >= grid_.cols || r >= grid_.rows) return 1.0;
    const double lx = (gx - c) * pitch;
    const double ly = (gy - r) * pitch;
    if (lx >= grid_.tag_mm || ly >= grid_.tag_mm) return 1.0;
    const double cell = grid_.tag_mm / width_at_border_;
    const int bx = static_cast<int>(lx / cell) + border_start_;
    const int by = static_cast<int>(ly / cell) + border_start_;
    return patterns_[static_cast<size_t>(r * grid_.cols + c)]
                    [static_cast<size_t>(by * total_ + bx)];
  }

  /// Ground-truth corners of tag k (AprilTag order: BL, BR, TR, TL of the upright pattern).
  [[nodiscard]] std::array<Eigen::Vector2d, 4> tag_board_corners(int k) const {
    const double pitch = grid_.tag_mm + grid_.gap_mm;
    const double x0 = grid_.gap_mm + (k % grid_.cols) * pitch;
    const double y0 = grid_.gap_mm + (k / grid_.cols) * pitch;
    const double s = grid_.tag_mm;
    return {Eigen::Vector2d(x0, y0 + s), Eigen::Vector2d(x0 + s, y0 + s),
            Eigen::Vector2d(x0 + s, y0), Eigen::Vector2d(x0, y0)};
  }

  cv::Mat render(const SyntheticCamera& cam, const Eigen::Matrix3d& h,
                 const SyntheticImageOptions& opt, std::vector<SyntheticTag>* truth) const {
    return render_function(
        cam, h, opt, [this](double x, double y) { return reflectance(x, y); }, truth);
  }

  template <typename Reflectance>
  cv::Mat render_function(const SyntheticCamera& cam, const Eigen::Matrix3d& h,
                          const SyntheticImageOptions& opt, Reflectance&& refl,
                          std::vector<SyntheticTag>* truth) const {
    cv::Mat out = render_planar(cam, h, opt, refl);
    if (truth != nullptr) {
      truth->clear();
      for (int k = 0; k < grid_.cols * grid_.rows; ++k) {
        SyntheticTag tag;
        tag.id = grid_.first_id + k;
        bool inside = true;
        const auto bc = tag_board_corners(k);
        for (size_t i = 0; i < 4; ++i) {
          tag.corners[i] = apply_h(h, bc[i]);
          inside = inside && tag.corners[i].x() > 10 && tag.corners[i].y() > 10 &&
                   tag.corners[i].x() < cam.width - 10 && tag.corners[i].y() < cam.height - 10;
        }
        if (inside) truth->push_back(tag);
      }
    }
    return out;
  }

 private:
  TagGrid grid_;
  int total_ = 10;
  int border_start_ = 1;
  int width_at_border_ = 8;
  std::vector<std::vector<unsigned char>> patterns_;
};

}  // namespace robocal::testing
