// cv::stereoCalibrate on the rig calibration's detections, for comparison with calibrate_rig.
#include "robocal/vision/rig_calibration.hpp"

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <map>
#include <string>
#include <vector>

namespace robocal::vision {

OpenCvStereoResult opencv_stereo_calibrate(const std::vector<RigCamera>& cameras,
                                           const BoardPoints& board,
                                           const std::vector<std::vector<CameraFrame>>& views,
                                           int camera_a, int camera_b, int min_common_corners) {
  OpenCvStereoResult out;
  const auto a = static_cast<size_t>(camera_a);
  const auto b = static_cast<size_t>(camera_b);
  if (camera_a < 0 || camera_b < 0 || a >= cameras.size() || b >= cameras.size()) {
    out.message = "camera index out of range";
    return out;
  }
  for (size_t c : {a, b})
    if (cameras[c].model.kind == CameraKind::kFisheyeKB4) {
      out.message = "cv::stereoCalibrate needs pinhole models";
      return out;
    }
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> pa, pb;
  for (const auto& view : views) {
    if (view.size() <= std::max(a, b)) continue;
    std::map<int, Eigen::Vector2d> in_b;
    for (const auto& o : view[b].corners) in_b[o.id] = o.pixel;
    std::vector<cv::Point3f> obj;
    std::vector<cv::Point2f> ua, ub;
    for (const auto& o : view[a].corners) {
      const auto it = board.find(o.id);
      const auto jt = in_b.find(o.id);
      if (it == board.end() || jt == in_b.end()) continue;
      obj.emplace_back(static_cast<float>(it->second.x()), static_cast<float>(it->second.y()),
                       static_cast<float>(it->second.z()));
      ua.emplace_back(static_cast<float>(o.pixel.x()), static_cast<float>(o.pixel.y()));
      ub.emplace_back(static_cast<float>(jt->second.x()), static_cast<float>(jt->second.y()));
    }
    if (static_cast<int>(obj.size()) < min_common_corners) continue;
    object.push_back(obj);
    pa.push_back(ua);
    pb.push_back(ub);
  }
  out.views = static_cast<int>(object.size());
  if (object.empty()) {
    out.message = "no view with enough corners seen by both cameras";
    return out;
  }
  const auto K = [](const CameraModel& m) -> cv::Mat {
    cv::Mat k = cv::Mat::eye(3, 3, CV_64F);
    k.at<double>(0, 0) = m.params[0];
    k.at<double>(1, 1) = m.params[1];
    k.at<double>(0, 2) = m.params[2];
    k.at<double>(1, 2) = m.params[3];
    return k;
  };
  const auto D = [](const CameraModel& m) -> cv::Mat {
    return cv::Mat(std::vector<double>(m.params.begin() + 4, m.params.end()), true);
  };
  cv::Mat Ka = K(cameras[a].model), Kb = K(cameras[b].model);
  cv::Mat Da = D(cameras[a].model), Db = D(cameras[b].model);
  cv::Mat R, T, E, F;
  int flags = cv::CALIB_FIX_INTRINSIC;
  if (cameras[a].model.kind == CameraKind::kPinholeRational) flags |= cv::CALIB_RATIONAL_MODEL;
  try {
    out.rms_px = cv::stereoCalibrate(
        object, pa, pb, Ka, Da, Kb, Db, cv::Size(cameras[a].model.width, cameras[a].model.height),
        R, T, E, F, flags,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-12));
  } catch (const cv::Exception& e) {
    out.message = std::string("cv::stereoCalibrate failed: ") + e.what();
    return out;
  }
  Eigen::Matrix3d Re;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) Re(i, j) = R.at<double>(i, j);
  out.b_T_a.linear() = Re;
  out.b_T_a.translation() = Eigen::Vector3d(T.at<double>(0), T.at<double>(1), T.at<double>(2));
  out.baseline_m = out.b_T_a.translation().norm();
  out.ok = true;
  return out;
}

}  // namespace robocal::vision
