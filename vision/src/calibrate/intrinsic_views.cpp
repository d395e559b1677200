#include "calibrate/intrinsic_views.hpp"

#include "robocal/vision/pose.hpp"

#include <fmt/format.h>
#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <algorithm>
#include <cmath>
#include <optional>
#include <set>

namespace robocal::vision::detail {
namespace {

// Homography board (x, y) -> pixel by normalised DLT (OpenCV, all points, no RANSAC: the
// detections are already verified).
std::optional<Eigen::Matrix3d> view_homography(const CalibrationView& v) {
  std::vector<cv::Point2d> src;
  std::vector<cv::Point2d> dst;
  for (size_t i = 0; i < v.pixels.size(); ++i) {
    src.emplace_back(v.board_points[i].x(), v.board_points[i].y());
    dst.emplace_back(v.pixels[i].x(), v.pixels[i].y());
  }
  const cv::Mat h = cv::findHomography(src, dst, 0);
  if (h.empty()) return std::nullopt;
  Eigen::Matrix3d out;
  cv::cv2eigen(h, out);
  if (!out.allFinite()) return std::nullopt;
  return out;
}

// Zhang's constraints with the principal point fixed at (cx, cy) and zero skew: linear in
// (1/fx^2, 1/fy^2) (the same simplification as OpenCV's initialisation).
std::optional<Eigen::Vector2d> init_focal(const std::vector<Eigen::Matrix3d>& hs, double cx,
                                          double cy) {
  Eigen::MatrixXd a(2 * hs.size(), 2);
  Eigen::VectorXd b(2 * hs.size());
  Eigen::Matrix3d shift;
  shift << 1, 0, -cx, 0, 1, -cy, 0, 0, 1;
  for (size_t i = 0; i < hs.size(); ++i) {
    const Eigen::Matrix3d h = shift * hs[i];
    const Eigen::Vector3d h1 = h.col(0) / h.col(0).norm();
    const Eigen::Vector3d h2 = h.col(1) / h.col(0).norm();
    a.row(static_cast<Eigen::Index>(2 * i)) << h1.x() * h2.x(), h1.y() * h2.y();
    b(static_cast<Eigen::Index>(2 * i)) = -h1.z() * h2.z();
    a.row(static_cast<Eigen::Index>(2 * i + 1)) << h1.x() * h1.x() - h2.x() * h2.x(),
        h1.y() * h1.y() - h2.y() * h2.y();
    b(static_cast<Eigen::Index>(2 * i + 1)) = -(h1.z() * h1.z() - h2.z() * h2.z());
  }
  const Eigen::Vector2d x = a.colPivHouseholderQr().solve(b);
  if (!(x.x() > 0.0) || !(x.y() > 0.0)) return std::nullopt;
  return Eigen::Vector2d(1.0 / std::sqrt(x.x()), 1.0 / std::sqrt(x.y()));
}

// Board pose from a pinhole K without distortion (IPPE: exact for planar targets).
std::optional<Eigen::Isometry3d> init_pose(const CalibrationView& v, double fx, double fy,
                                           double cx, double cy) {
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (size_t i = 0; i < v.pixels.size(); ++i) {
    obj.emplace_back(v.board_points[i].x(), v.board_points[i].y(), 0.0);
    img.emplace_back(v.pixels[i].x(), v.pixels[i].y());
  }
  const cv::Matx33d k(fx, 0, cx, 0, fy, cy, 0, 0, 1);
  cv::Vec3d rvec;
  cv::Vec3d tvec;
  if (!cv::solvePnP(obj, img, k, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE)) {
    return std::nullopt;
  }
  return pose_from_rvec_tvec({rvec[0], rvec[1], rvec[2]}, {tvec[0], tvec[1], tvec[2]});
}

int region_of(const Eigen::Vector2d& px, int width, int height) {
  const int c = std::clamp(static_cast<int>(3.0 * (px.x() + 0.5) / width), 0, 2);
  const int r = std::clamp(static_cast<int>(3.0 * (px.y() + 0.5) / height), 0, 2);
  return r * 3 + c;
}

// Why a view cannot be used, or "".
std::string view_problem(const CalibrationView& v, const IntrinsicCalibrationOptions& options) {
  if (v.pixels.size() != v.board_points.size() || v.corner_ids.size() != v.pixels.size())
    return "inconsistent observation arrays";
  if (static_cast<int>(v.pixels.size()) < options.min_corners_per_view)
    return fmt::format("only {} corners (need {})", v.pixels.size(), options.min_corners_per_view);
  if (std::set<int>(v.corner_ids.begin(), v.corner_ids.end()).size() != v.corner_ids.size())
    return "duplicate corner ids";
  bool finite = true;
  for (size_t i = 0; i < v.pixels.size(); ++i) {
    finite = finite && v.pixels[i].allFinite() && v.board_points[i].allFinite();
  }
  return finite ? "" : "non-finite coordinates";
}

}  // namespace

Eigen::Isometry3d to_isometry(const Pose6& p) {
  return pose_from_rvec_tvec({p[0], p[1], p[2]}, {p[3], p[4], p[5]});
}

Pose6 from_isometry(const Eigen::Isometry3d& t) {
  const Eigen::Vector3d r = rvec_of(t);
  return {r.x(), r.y(), r.z(), t.translation().x(), t.translation().y(), t.translation().z()};
}

double view_tilt_deg(const CalibrationView& v, const Eigen::Isometry3d& camera_T_board) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : v.board_points) centre += p;
  centre /= static_cast<double>(v.board_points.size());
  const Eigen::Vector3d c = camera_T_board * centre;
  const Eigen::Vector3d normal = camera_T_board.rotation().col(2);
  return std::acos(std::clamp(std::abs(normal.dot(c.normalized())), 0.0, 1.0)) * 180.0 / M_PI;
}

UsedViews screen_views(const std::vector<CalibrationView>& views,
                       const IntrinsicCalibrationOptions& options,
                       IntrinsicCalibrationResult& result) {
  UsedViews used;
  for (const auto& v : views) {
    ViewReport rep;
    rep.name = v.name;
    rep.corners = static_cast<int>(v.pixels.size());
    rep.rejection = view_problem(v, options);
    result.views.push_back(rep);
    if (rep.rejection.empty()) {
      used.views.push_back(&v);
      used.report.push_back(result.views.size() - 1);
    }
  }
  return used;
}

Eigen::Vector2d focal_start(const UsedViews& used, const IntrinsicCalibrationOptions& options) {
  const double w = options.width;
  const double h = options.height;
  std::vector<Eigen::Matrix3d> hs;
  for (const auto* v : used.views) {
    if (auto hm = view_homography(*v)) hs.push_back(*hm);
  }
  double fx0 = std::max(w, h);
  double fy0 = fx0;
  if (const auto f = init_focal(hs, (w - 1.0) / 2.0, (h - 1.0) / 2.0)) {
    // Near-degenerate (all fronto-parallel) sets give wild values; keep a plausible start.
    if ((*f).minCoeff() > 0.1 * std::max(w, h) && (*f).maxCoeff() < 20.0 * std::max(w, h) &&
        (*f).maxCoeff() < 1.5 * (*f).minCoeff()) {
      fx0 = (*f).x();
      fy0 = (*f).y();
    } else {
      fx0 = fy0 = std::sqrt((*f).x() * (*f).y());
      if (!(fx0 > 0.1 * std::max(w, h)) || !(fx0 < 20.0 * std::max(w, h)))
        fx0 = fy0 = std::max(w, h);
    }
  }
  return {fx0, fy0};
}

ViewTilts pose_views(UsedViews& used, const Eigen::Vector4d& pinhole,
                     const IntrinsicCalibrationOptions& options,
                     IntrinsicCalibrationResult& result) {
  ViewTilts tilts;
  UsedViews posed;
  for (size_t i = 0; i < used.views.size(); ++i) {
    const CalibrationView& view = *used.views[i];
    auto pose = init_pose(view, pinhole[0], pinhole[1], pinhole[2], pinhole[3]);
    ViewReport& rep = result.views[used.report[i]];
    if (!pose) {
      rep.rejection = "no pose could be computed (degenerate point layout)";
      continue;
    }
    // The board's printed face points along board -z: it must face the camera. Mirrored
    // observations (a mirror image, or a board seen from behind) fit only with it facing away.
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const auto& p : view.board_points) centre += p;
    centre /= static_cast<double>(view.board_points.size());
    const Eigen::Vector3d c = *pose * centre;
    if (c.z() <= 0.0 || pose->rotation().col(2).dot(c) <= 0.0) {
      rep.rejection = "board seen mirrored or from behind (its printed face points away)";
      continue;
    }
    rep.tilt_deg = view_tilt_deg(view, *pose);
    tilts.max_tilt_deg = std::max(tilts.max_tilt_deg, rep.tilt_deg);
    if (rep.tilt_deg >= options.good_tilt_deg) ++tilts.tilted;
    posed.poses.push_back(from_isometry(*pose));
    posed.views.push_back(&view);
    posed.report.push_back(used.report[i]);
  }
  used = std::move(posed);
  for (size_t i : used.report) result.views[i].used = true;
  return tilts;
}

void find_uncovered_regions(const UsedViews& used, const IntrinsicCalibrationOptions& options,
                            IntrinsicCalibrationResult& result) {
  std::array<int, 9> region_count{};
  for (const auto* v : used.views) {
    for (const auto& px : v->pixels)
      ++region_count[static_cast<size_t>(region_of(px, options.width, options.height))];
  }
  for (size_t r = 0; r < 9; ++r) {
    if (region_count[r] == 0) result.uncovered_regions.push_back(image_region_names()[r]);
  }
  if (!result.uncovered_regions.empty()) {
    std::string list;
    for (const auto& n : result.uncovered_regions) list += (list.empty() ? "" : ", ") + n;
    result.advice.push_back("add views with the board in the " + list + " of the image");
  }
}

}  // namespace robocal::vision::detail
