#include "fit/board_pose.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace robocal::vision::detail {

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-300) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

Eigen::Vector3d log_so3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

Eigen::Isometry3d pose_from_vec6(const double* v) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = exp_so3(Eigen::Vector3d(v[0], v[1], v[2]));
  pose.translation() = Eigen::Vector3d(v[3], v[4], v[5]);
  return pose;
}

void pose_to_vec6(const Eigen::Isometry3d& pose, double* v) {
  const Eigen::Vector3d w = log_so3(pose.linear());
  for (int i = 0; i < 3; ++i) {
    v[i] = w[i];
    v[3 + i] = pose.translation()[i];
  }
}

std::vector<PlanarPnpSolution> planar_pnp_ippe(const CameraModel& camera, const BoardPoints& board,
                                               const CameraFrame& frame) {
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> normalised;
  for (const CornerObservation& obs : frame.corners) {
    const auto it = board.find(obs.id);
    if (it == board.end() || !obs.pixel.allFinite()) continue;
    const auto ray = unproject(camera, obs.pixel);
    if (!ray || !((*ray)[2] > 1e-9)) continue;
    object.emplace_back(it->second.x(), it->second.y(), it->second.z());
    normalised.emplace_back((*ray)[0] / (*ray)[2], (*ray)[1] / (*ray)[2]);
  }
  std::vector<PlanarPnpSolution> out;
  if (object.size() < 4) return out;
  // IPPE wants a planar object with z = 0; our boards are (board frame, printed face z = 0).
  for (const cv::Point3d& p : object)
    if (std::abs(p.z) > 1e-9) return out;

  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat errors;
  const cv::Matx33d K = cv::Matx33d::eye();
  try {
    cv::solvePnPGeneric(object, normalised, K, cv::noArray(), rvecs, tvecs, false,
                        cv::SOLVEPNP_IPPE, cv::noArray(), cv::noArray(), errors);
  } catch (const cv::Exception&) {
    return out;
  }
  const double f = 0.5 * (camera.params[0] + camera.params[1]);
  for (size_t i = 0; i < rvecs.size(); ++i) {
    cv::Mat r, t;
    rvecs[i].convertTo(r, CV_64F);
    tvecs[i].convertTo(t, CV_64F);
    double v[6] = {r.at<double>(0), r.at<double>(1), r.at<double>(2),
                   t.at<double>(0), t.at<double>(1), t.at<double>(2)};
    PlanarPnpSolution s;
    s.camera_T_board = pose_from_vec6(v);
    // IPPE's error is the RMS over the 2N coordinates in normalised units; report it in pixels.
    s.rms_px = errors.empty() ? 0.0 : f * errors.at<double>(static_cast<int>(i));
    if (!std::isfinite(s.rms_px) || !s.camera_T_board.matrix().allFinite()) continue;
    out.push_back(s);
  }
  std::sort(out.begin(), out.end(), [](const PlanarPnpSolution& a, const PlanarPnpSolution& b) {
    return a.rms_px < b.rms_px;
  });
  return out;
}

double reprojection_chi2(const CameraModel& camera, const BoardPoints& board,
                         const CameraFrame& frame, const Eigen::Isometry3d& camera_T_board,
                         double default_sigma_px, int* used) {
  double chi2 = 0.0;
  int n = 0;
  for (const CornerObservation& obs : frame.corners) {
    const auto it = board.find(obs.id);
    if (it == board.end() || !obs.pixel.allFinite()) continue;
    const auto px = project(camera, camera_T_board * it->second);
    if (!px) return std::numeric_limits<double>::infinity();
    const double s = sigma_or(obs.sigma_px, default_sigma_px);
    chi2 += (*px - obs.pixel).squaredNorm() / (s * s);
    ++n;
  }
  if (used) *used = n;
  return chi2;
}

}  // namespace robocal::vision::detail
