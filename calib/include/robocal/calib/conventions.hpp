#pragma once
// Convention checks before fitting: the common swaps in measurement files — quaternion
// order (x, y, z, w read as w, x, y, z), readings in degrees where the robot expects radians,
// target→camera given for camera→target — each tried against the nominal model on the data and
// named when one fits far better than what was declared.
//
// The comparison uses quantities the unknown base and tool frames cannot change: the distance
// between the measured positions of two poses and the angle of the relative rotation between
// their measured orientations (R_i R_jᵀ is conjugated by the base and the tool cancels), against
// the same quantities predicted by the nominal model. A nominal model is a few millimetres off;
// a convention swap is off by the size of the working volume, so the test is decisive.
#include "robocal/calib/frame_predictor.hpp"
#include "robocal/calib/measurements.hpp"

#include <Eigen/Core>

#include <optional>
#include <string>

namespace robocal::calib {

struct ConventionMismatch {
  std::string declared;             // e.g. "quaternions [w, x, y, z]"
  std::string alternative;          // e.g. "quaternions [x, y, z, w] (w last)"
  double declared_misfit = 0.0;     // median invariant mismatch as declared (m or rad)
  double alternative_misfit = 0.0;  // same, read the other way
  std::string message;              // plain words: what, by how much, what to change
};

// The first alternative reading that fits the nominal model at least `ratio` times better than
// the declared one (and the declared misfit above `min_misfit_*`), or nothing.
std::optional<ConventionMismatch> check_conventions(
    const FramePredictor& model, const Eigen::VectorXd& nominal, const Measurements& measurements,
    double ratio = 5.0, double min_misfit_position = 5e-3, double min_misfit_angle = 0.05);

}  // namespace robocal::calib
