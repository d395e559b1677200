#pragma once
// Probe heights against a bed whose tilt is unknown.
//
// A printer's probe reports how far above the bed the nozzle is. The bed is rarely square to the
// printer's axes; a fixed plane z = 0 then blames the bed's tilt on the printer's geometry (the
// endstops, mostly). BedPlanePredictor wraps any predictor (the robot, or a camera rig) and
// appends two unknowns, the bed's slopes: the bed is the plane z = tilt_x·x + tilt_y·y through
// the world origin (the bed defines z = 0 at the origin; its height is the gauge, so probe
// heights stay relative to it). A probe height is the nozzle's vertical distance above that
// plane: residual = (p_z − tilt_x·p_x − tilt_y·p_y − offset − measured) / σ, the observation's
// `normal` being the vertical (its default).
//
// The rank analysis decides what the data separate: with heights alone the tilt trades against
// the endstop offsets (both tilt the probed surface), the bed is held level and the summary says
// so; a printed part measured with a caliper, which the bed's tilt does not change, separates
// them.
#include "robocal/calib/identification.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::calib {

class BedPlanePredictor final : public FramePredictor {
 public:
  explicit BedPlanePredictor(const FramePredictor& inner);

  std::size_t parameter_count() const override { return inner_count_ + 2; }
  std::vector<std::string> parameter_labels() const override;  // inner's + "bed tilt about x/y"
  std::vector<std::string> parameter_names() const override;   // inner's + bed.tilt_x, bed.tilt_y
  bool predict(const Eigen::VectorXd& params, const Eigen::VectorXd& actuators, int slot,
               bool with_jacobian, FramePrediction& out, std::string& why) const override;
  bool pixel_residual(const PixelObservation& obs, const Eigen::VectorXd& params,
                      const FramePrediction& frame, Eigen::Vector2d& residual,
                      Eigen::Matrix<double, 2, Eigen::Dynamic>* jacobian,
                      std::string& why) const override;
  bool probe_residual(const ProbeHeightObservation& obs, const Eigen::VectorXd& params,
                      const FramePrediction& frame, double& residual, Eigen::RowVectorXd* jacobian,
                      std::string& why) const override;

  // The inner predictor's start values followed by a level bed.
  Eigen::VectorXd initial_parameters(const Eigen::VectorXd& inner_params) const;
  // The inner predictor's solve options extended to the full vector: both slopes are
  // candidates (after the inner's); where the data confound them with the geometry, the geometry
  // is estimated and the bed held level (what a firmware's endstop calibration does); no prior,
  // no bounds.
  SolveOptions solve_options(const SolveOptions& inner) const;
  double tilt_x(const Eigen::VectorXd& params) const {
    return params(static_cast<Eigen::Index>(inner_count_));
  }
  double tilt_y(const Eigen::VectorXd& params) const {
    return params(static_cast<Eigen::Index>(inner_count_) + 1);
  }

  // Its own parts are pure; the robot's predictor decides.
  bool thread_safe() const override { return inner_.thread_safe(); }

 private:
  const FramePredictor& inner_;
  std::size_t inner_count_ = 0;
};

}  // namespace robocal::calib
