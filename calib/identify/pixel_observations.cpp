#include "robocal/calib/pixel_observations.hpp"

#include "robocal/core/random_draws.hpp"
#include "robocal/vision/camera_parameter_names.hpp"

#include <ceres/jet.h>
#include <ceres/rotation.h>
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

namespace robocal::calib {

namespace {

// Projection of a world point by a camera at pose [c; r] (centre, rotation vector from R0) with
// intrinsics k, differentiated by Jets with respect to (x_world, c, r, k): slots 0–2, 3–5, 6–8,
// 9…. Returns false where the model cannot project (behind the camera, beyond a pole).
template <class Model>
bool project_with_derivatives(const Eigen::Vector3d& x_world, const double* pose,
                              const Eigen::Matrix3d& R0, const double* intrinsics,
                              Eigen::Vector2d& pixel, Eigen::MatrixXd* jacobian) {
  constexpr int kN = Model::kNumParams;
  using J = ceres::Jet<double, 9 + kN>;
  Vec3<J> xw;
  Vec3<J> centre;
  J rv[3];
  J k[kN];
  for (int i = 0; i < 3; ++i) {
    xw(i) = J(x_world(i), i);
    centre(i) = J(pose[i], 3 + i);
    rv[i] = J(pose[3 + i], 6 + i);
  }
  for (int i = 0; i < kN; ++i) k[i] = J(intrinsics[i], 9 + i);
  Mat3<J> dR;
  ceres::AngleAxisToRotationMatrix(rv, dR.data());
  const Mat3<J> R = dR * R0.cast<J>();
  const Vec3<J> xc = R.transpose() * (xw - centre);
  J px[2];
  if (!Model::project(k, xc.data(), px)) return false;
  for (int i = 0; i < 2; ++i) {
    pixel(i) = px[i].a;
    if (jacobian) jacobian->row(i) = px[i].v.transpose();
  }
  return true;
}

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Vector3d rotation_vector_of(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.axis() * aa.angle();
}

}  // namespace

CameraRigPredictor::CameraRigPredictor(const FramePredictor& robot,
                                       std::vector<ObservingCamera> cameras,
                                       CameraRigOptions options)
    : robot_(robot), cameras_(std::move(cameras)), options_(options) {
  robot_count_ = robot.parameter_count();
  if (cameras_.empty()) throw std::invalid_argument("a camera rig needs at least one camera");
  if (options_.gauge_camera < -1 || options_.gauge_camera >= static_cast<int>(cameras_.size()))
    throw std::invalid_argument(fmt::format("gauge camera {} out of range (0–{})",
                                            options_.gauge_camera, cameras_.size() - 1));
  std::set<std::string> names;
  std::size_t offset = robot_count_;
  for (const auto& cam : cameras_) {
    if (cam.name.empty() || !names.insert(cam.name).second)
      throw std::invalid_argument(
          fmt::format("camera names must be unique and not empty ('{}')", cam.name));
    const std::string problem = vision::validate_camera(cam.model);
    if (!problem.empty())
      throw std::invalid_argument(fmt::format("camera {}: {}", cam.name, problem));
    offsets_.push_back(offset);
    offset += 6 + (options_.estimate_intrinsics ? cam.model.params.size() : 0);
  }
}

std::size_t CameraRigPredictor::parameter_count() const {
  const auto& last = cameras_.back();
  return offsets_.back() + 6 + (options_.estimate_intrinsics ? last.model.params.size() : 0);
}

std::vector<std::string> CameraRigPredictor::parameter_names() const {
  std::vector<std::string> names = robot_.parameter_names();
  for (const auto& cam : cameras_) {
    for (const char* n : {"x", "y", "z", "rx", "ry", "rz"}) names.push_back(cam.name + "." + n);
    if (options_.estimate_intrinsics)
      for (const auto& n : vision::camera_param_names(cam.model.kind))
        names.push_back(cam.name + "." + n);
  }
  return names;
}

std::vector<std::string> CameraRigPredictor::parameter_labels() const {
  std::vector<std::string> labels = robot_.parameter_labels();
  const std::vector<std::string> names = parameter_names();
  labels.insert(labels.end(), names.begin() + static_cast<std::ptrdiff_t>(labels.size()),
                names.end());
  return labels;
}

std::size_t CameraRigPredictor::pose_offset(int camera) const {
  return offsets_.at(static_cast<std::size_t>(camera));
}

std::size_t CameraRigPredictor::intrinsics_offset(int camera) const {
  if (!options_.estimate_intrinsics)
    throw std::logic_error("intrinsics are not parameters of this rig (estimate_intrinsics off)");
  return pose_offset(camera) + 6;
}

Eigen::VectorXd CameraRigPredictor::initial_parameters(const Eigen::VectorXd& robot_params) const {
  if (static_cast<std::size_t>(robot_params.size()) != robot_count_)
    throw std::invalid_argument(fmt::format("{} robot parameters given, the robot has {}",
                                            robot_params.size(), robot_count_));
  Eigen::VectorXd x(static_cast<Eigen::Index>(parameter_count()));
  x.head(static_cast<Eigen::Index>(robot_count_)) = robot_params;
  for (int c = 0; c < camera_count(); ++c) {
    const auto& cam = cameras_[static_cast<std::size_t>(c)];
    const auto o = static_cast<Eigen::Index>(pose_offset(c));
    x.segment<3>(o) = cam.world_T_camera.translation();
    x.segment<3>(o + 3).setZero();
    if (options_.estimate_intrinsics)
      for (std::size_t i = 0; i < cam.model.params.size(); ++i)
        x(o + 6 + static_cast<Eigen::Index>(i)) = cam.model.params[i];
  }
  return x;
}

Eigen::VectorXd CameraRigPredictor::robot_parameters(const Eigen::VectorXd& params) const {
  return params.head(static_cast<Eigen::Index>(robot_count_));
}

Eigen::Isometry3d CameraRigPredictor::world_T_camera(const Eigen::VectorXd& params,
                                                     int camera) const {
  const auto o = static_cast<Eigen::Index>(pose_offset(camera));
  const Eigen::Vector3d r = params.segment<3>(o + 3);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Eigen::Matrix3d dR = r.norm() > 0
                                 ? Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix()
                                 : Eigen::Matrix3d::Identity();
  T.linear() = dR * cameras_[static_cast<std::size_t>(camera)].world_T_camera.linear();
  T.translation() = params.segment<3>(o);
  return T;
}

vision::CameraModel CameraRigPredictor::camera_model(const Eigen::VectorXd& params,
                                                     int camera) const {
  vision::CameraModel m = cameras_.at(static_cast<std::size_t>(camera)).model;
  if (options_.estimate_intrinsics) {
    const auto o = static_cast<Eigen::Index>(intrinsics_offset(camera));
    for (std::size_t i = 0; i < m.params.size(); ++i)
      m.params[i] = params(o + static_cast<Eigen::Index>(i));
  }
  return m;
}

void CameraRigPredictor::set_camera(Eigen::VectorXd& params, int camera,
                                    const Eigen::Isometry3d& world_T_cam,
                                    const vision::CameraModel* model) const {
  const auto o = static_cast<Eigen::Index>(pose_offset(camera));
  params.segment<3>(o) = world_T_cam.translation();
  params.segment<3>(o + 3) = rotation_vector_of(
      world_T_cam.linear() *
      cameras_[static_cast<std::size_t>(camera)].world_T_camera.linear().transpose());
  if (model != nullptr && options_.estimate_intrinsics)
    for (std::size_t i = 0; i < model->params.size(); ++i)
      params(o + 6 + static_cast<Eigen::Index>(i)) = model->params[i];
}

bool CameraRigPredictor::predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators,
                                 int slot, bool with_jacobian, FramePrediction& out,
                                 std::string& why) const {
  if (static_cast<std::size_t>(params.size()) != parameter_count()) {
    why = fmt::format("{} parameters given, the camera rig model has {}", params.size(),
                      parameter_count());
    return false;
  }
  if (!robot_.predict(robot_parameters(params), actuators, slot, with_jacobian, out, why))
    return false;
  if (with_jacobian) {
    const auto P = static_cast<Eigen::Index>(parameter_count());
    const auto R = static_cast<Eigen::Index>(robot_count_);
    out.jacobian.conservativeResize(6, P);
    out.jacobian.rightCols(P - R).setZero();
  }
  return true;
}

bool CameraRigPredictor::pixel_residual(const PixelObservation& obs, const Eigen::VectorXd& params,
                                        const FramePrediction& frame, Eigen::Vector2d& residual,
                                        Eigen::Matrix<double, 2, Eigen::Dynamic>* jacobian,
                                        std::string& why) const {
  if (obs.camera < 0 || obs.camera >= camera_count()) {
    why = fmt::format("camera {} does not exist (the rig has {})", obs.camera, camera_count());
    return false;
  }
  const auto& cam = cameras_[static_cast<std::size_t>(obs.camera)];
  const auto o = static_cast<Eigen::Index>(pose_offset(obs.camera));
  const double* intrinsics =
      options_.estimate_intrinsics ? params.data() + o + 6 : cam.model.params.data();
  const Eigen::Vector3d y = frame.pose.linear() * obs.point;  // corner offset, world axes
  const Eigen::Vector3d x_world = y + frame.pose.translation();
  const int n = static_cast<int>(cam.model.params.size());
  Eigen::MatrixXd J(2, 9 + n);
  Eigen::Vector2d pixel;
  const bool ok = vision::visit_camera_kind(cam.model.kind, [&](auto model) {
    return project_with_derivatives<decltype(model)>(x_world, params.data() + o,
                                                     cam.world_T_camera.linear(), intrinsics, pixel,
                                                     jacobian ? &J : nullptr);
  });
  if (!ok) {
    why = fmt::format("corner {} cannot be projected by {} (behind the camera)", obs.corner,
                      cam.name);
    return false;
  }
  residual = obs.weight * (pixel - obs.measured);
  if (jacobian != nullptr) {
    const auto P = static_cast<Eigen::Index>(parameter_count());
    const auto R = static_cast<Eigen::Index>(robot_count_);
    if (frame.jacobian.cols() < R) {
      why = "the frame prediction carries no jacobian";
      return false;
    }
    // Frame twist δ = [δp; δφ]: δx_world = δp − [y]× δφ.
    Eigen::Matrix<double, 2, 6> twist;
    twist.leftCols<3>() = J.leftCols<3>();
    twist.rightCols<3>() = -J.leftCols<3>() * skew(y);
    jacobian->setZero(2, P);
    jacobian->leftCols(R) = obs.weight * twist * frame.jacobian.leftCols(R);
    jacobian->middleCols<6>(o) = obs.weight * J.middleCols<6>(3);
    if (options_.estimate_intrinsics) jacobian->middleCols(o + 6, n) = obs.weight * J.rightCols(n);
  }
  return true;
}

SolveOptions CameraRigPredictor::solve_options(const SolveOptions& robot,
                                               double camera_start_sigma) const {
  const std::size_t P = parameter_count();
  const std::size_t R = robot_count_;
  SolveOptions opt = robot;
  opt.candidates = robot.candidates;
  if (opt.candidates.empty())
    for (std::size_t i = 0; i < R; ++i) opt.candidates.push_back(i);
  int lowest = 0;
  for (int p : robot.preference) lowest = std::min(lowest, p);
  opt.preference = robot.preference;
  opt.preference.resize(R, 0);
  opt.preference.resize(P, lowest - 1);
  for (int c = 0; c < camera_count(); ++c) {
    const std::size_t o = pose_offset(c);
    if (c != options_.gauge_camera)
      for (std::size_t i = 0; i < 6; ++i) {
        opt.candidates.push_back(o + i);
        opt.preference[o + i] = lowest - 2;
      }
    if (options_.estimate_intrinsics)
      for (std::size_t i = 0; i < cameras_[static_cast<std::size_t>(c)].model.params.size(); ++i)
        opt.candidates.push_back(o + 6 + i);
  }
  auto extend = [&](std::vector<double>& v, double fill) {
    if (!v.empty()) v.resize(P, fill);
  };
  extend(opt.prior_sigma, 0.0);
  extend(opt.lower_bound, std::numeric_limits<double>::quiet_NaN());
  extend(opt.upper_bound, std::numeric_limits<double>::quiet_NaN());
  if (camera_start_sigma > 0.0 && opt.start_sigma.empty()) opt.start_sigma.assign(R, 0.0);
  if (!opt.start_sigma.empty()) {
    opt.start_sigma.resize(P, 0.0);
    for (int c = 0; c < camera_count(); ++c)
      if (c != options_.gauge_camera)
        for (std::size_t i = 0; i < 6; ++i)
          opt.start_sigma[pose_offset(c) + i] = camera_start_sigma;
  }
  if (opt.start.size() > 0 && static_cast<std::size_t>(opt.start.size()) == R)
    opt.start = initial_parameters(opt.start);
  return opt;
}

Eigen::Isometry3d camera_looking_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                    const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up);  // right in the image when `up` is up
  if (x.norm() < 1e-9) x = z.cross(Eigen::Vector3d::UnitX());
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // down in the image
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

std::vector<ObservingCamera> cameras_below(const std::vector<Eigen::Vector3d>& points, int count,
                                           int width, int height) {
  if (points.empty()) throw std::invalid_argument("cameras_below: no points to look at");
  Eigen::Vector3d lo = points.front();
  Eigen::Vector3d hi = lo;
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double size = std::max(0.2, (hi - lo).norm());
  const double distance = 2.5 * size;
  const double f = 0.5 * width * distance / (0.8 * size);
  std::vector<ObservingCamera> cams;
  for (int c = 0; c < count; ++c) {
    ObservingCamera cam;
    cam.name = fmt::format("camera{}", c);
    cam.model = vision::make_camera(vision::CameraKind::kPinholeRadtan, width, height, f, f,
                                    0.5 * (width - 1), 0.5 * (height - 1), {-0.05, 0.02});
    const double x = count > 1 ? (0.4 * size) * (static_cast<double>(c) / (count - 1) - 0.5) : 0.0;
    cam.world_T_camera = camera_looking_at(centre + Eigen::Vector3d(x, 0.0, -distance), centre,
                                           Eigen::Vector3d::UnitY());
    cams.push_back(std::move(cam));
  }
  return cams;
}

Measurements simulate_pixel_measurements(const CameraRigPredictor& rig,
                                         const Eigen::VectorXd& truth,
                                         const std::vector<Eigen::VectorXd>& actuators,
                                         const std::vector<Eigen::Vector3d>& target_points,
                                         const PixelSimulationOptions& options, std::mt19937& rng) {
  std::normal_distribution<double> n01(0.0, 1.0);
  const double noise = options.add_noise ? 1.0 : 0.0;
  std::vector<Eigen::Isometry3d> camera_T_world;
  std::vector<vision::CameraModel> models;
  for (int c = 0; c < rig.camera_count(); ++c) {
    camera_T_world.push_back(rig.world_T_camera(truth, c).inverse());
    models.push_back(rig.camera_model(truth, c));
  }
  Measurements out;
  for (std::size_t k = 0; k < actuators.size(); ++k) {
    FramePrediction pred;
    std::string why;
    if (!rig.predict(truth, actuators[k], static_cast<int>(k), false, pred, why)) continue;
    PoseMeasurement m;
    m.id = fmt::format("p{:04d}", k);
    for (int c = 0; c < rig.camera_count(); ++c) {
      const auto cu = static_cast<std::size_t>(c);
      const Eigen::Vector3d eye = camera_T_world[cu].inverse().translation();
      std::vector<PixelObservation> seen;
      for (std::size_t j = 0; j < target_points.size(); ++j) {
        const Eigen::Vector3d xw = pred.pose * target_points[j];
        if (options.target_normal.norm() > 0 &&
            (eye - xw).dot(pred.pose.linear() * options.target_normal) <= 0)
          continue;
        const auto px = vision::project(models[cu], camera_T_world[cu] * xw);
        if (!px || !vision::in_image(models[cu], *px, options.image_margin)) continue;
        const Eigen::Vector2d noisy =
            *px + noise * options.pixel_sigma * core::draw_vector2(n01, rng);
        seen.push_back(PixelObservation::with_sigma(c, static_cast<int>(j), target_points[j], noisy,
                                                    options.pixel_sigma));
      }
      if (static_cast<int>(seen.size()) >= options.min_corners)
        m.observations.insert(m.observations.end(), seen.begin(), seen.end());
    }
    if (m.observations.empty()) continue;
    m.actuators = actuators[k];
    if (options.actuator_sigma.size() == actuators[k].size())
      for (Eigen::Index i = 0; i < m.actuators.size(); ++i)
        m.actuators(i) += noise * options.actuator_sigma(i) * n01(rng);
    out.poses.push_back(std::move(m));
  }
  return out;
}

PixelErrorStatistics pixel_errors(const CameraRigPredictor& rig, const Eigen::VectorXd& params,
                                  const std::vector<PoseMeasurement>& poses) {
  PixelErrorStatistics s;
  double sum = 0.0;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    FramePrediction pred;
    std::string why;
    if (!poses[k].actuators.allFinite() ||
        !rig.predict(params, poses[k].actuators, static_cast<int>(k), false, pred, why))
      continue;
    for (const auto& obs : poses[k].observations) {
      const auto* px = std::get_if<PixelObservation>(&obs);
      if (px == nullptr || px->camera < 0 || px->camera >= rig.camera_count()) continue;
      const Eigen::Isometry3d cam_T_world = rig.world_T_camera(params, px->camera).inverse();
      const auto p = vision::project(rig.camera_model(params, px->camera),
                                     cam_T_world * (pred.pose * px->point));
      if (!p) continue;
      const double e = (*p - px->measured).norm();
      sum += e * e;
      s.max_px = std::max(s.max_px, e);
      ++s.observations;
    }
  }
  if (s.observations > 0) s.rms_px = std::sqrt(sum / static_cast<double>(s.observations));
  return s;
}

}  // namespace robocal::calib
