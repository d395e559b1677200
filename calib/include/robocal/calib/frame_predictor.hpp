#pragma once
// What the identification engine needs from a mechanism model: the pose of the measured frame
// for a pose's actuator readings and its exact derivative with respect to every model parameter
// (for a parallel robot: closure solved per pose, derivative by the implicit-function theorem).
// The adapter for the closed-loop mechanism model lives in mechanism_predictor.hpp; the solve
// that uses it in identification.hpp.
#include "robocal/calib/observations.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace robocal::calib {

// Pose of the measured frame in the world and d[p; φ]/d(parameters) (6 × parameter_count),
// perturbation convention of observations.hpp: p' = p + δp, R' = exp([δφ]×) R.
struct FramePrediction {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, Eigen::Dynamic> jacobian;
};

class FramePredictor {
 public:
  virtual ~FramePredictor() = default;
  virtual std::size_t parameter_count() const = 0;
  virtual std::vector<std::string> parameter_names() const = 0;
  // What a person reads for each parameter (the robot file's labels); the raw names by default.
  virtual std::vector<std::string> parameter_labels() const { return parameter_names(); }
  // Predicts the measured frame for `actuators` with parameter vector `params`. `slot` identifies
  // the pose so an implementation may warm-start from its previous solution. When `with_jacobian`
  // is false the jacobian may be left empty. Returns false (and says why) when the pose cannot be
  // solved (closure fails, singular configuration).
  virtual bool predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators, int slot,
                       bool with_jacobian, FramePrediction& out, std::string& why) const = 0;
  // Whether predict, pixel_residual and probe_residual may be called from several threads at
  // once (SolveOptions::threads evaluates poses in parallel only then), each call's answer the
  // same as from one thread.
  virtual bool thread_safe() const { return false; }
  // Pixel observations (camera-in-the-loop): the whitened residual of `obs` for the measured
  // frame `frame` predicted at `params` and, when `jacobian` is not null, its exact
  // 2 × parameter_count derivative (then `frame` must carry its jacobian). Only a predictor that
  // models cameras implements it (CameraRigPredictor, pixel_observations.hpp); this default says
  // so and returns false.
  virtual bool pixel_residual(const PixelObservation& /*obs*/, const Eigen::VectorXd& /*params*/,
                              const FramePrediction& /*frame*/, Eigen::Vector2d& /*residual*/,
                              Eigen::Matrix<double, 2, Eigen::Dynamic>* /*jacobian*/,
                              std::string& why) const {
    why = "the model has no cameras: pixel observations need a CameraRigPredictor";
    return false;
  }
  // Probe heights: the whitened residual of `obs` for `frame` predicted at `params` and, when
  // `jacobian` is not null, its 1 × parameter_count derivative. This default measures against
  // the observation's own fixed plane; a predictor that estimates the bed plane overrides it
  // (BedPlanePredictor, bed_plane.hpp).
  virtual bool probe_residual(const ProbeHeightObservation& obs, const Eigen::VectorXd& /*params*/,
                              const FramePrediction& frame, double& residual,
                              Eigen::RowVectorXd* jacobian, std::string& /*why*/) const {
    const Eigen::Vector3d p = frame.pose.translation();
    residual = (obs.normal.dot(p) - obs.offset - obs.measured_height) / obs.sigma;
    if (jacobian != nullptr)
      *jacobian = obs.normal.transpose() * frame.jacobian.topRows<3>() / obs.sigma;
    return true;
  }
};

}  // namespace robocal::calib
