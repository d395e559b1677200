#pragma once
// Statistics of position errors on held-out poses (poses the fit never used): RMS and maximum,
// absolute and after the best-fit rigid registration. The registered figure is the robot's
// accuracy in its own frame, unaffected by where the whole measurement world sits.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstddef>
#include <optional>
#include <vector>

namespace robocal::calib {

struct PositionErrorStats {
  double rms = 0.0;  // m
  double max = 0.0;  // m
  std::size_t n = 0;
};

// RMS / max of the distances between predicted[k] and truth[k] (sizes must agree).
PositionErrorStats position_error_stats(const std::vector<Eigen::Vector3d>& predicted,
                                        const std::vector<Eigen::Vector3d>& truth);

struct HeldOutErrors {
  PositionErrorStats absolute;
  PositionErrorStats registered;                   // n = 0 with fewer than 3 points
  std::vector<Eigen::Vector3d> registered_points;  // predicted, after the best-fit transform
};

// Absolute errors and the errors after the rigid transform (Umeyama, no scale) that best aligns
// `predicted` with `truth`.
HeldOutErrors held_out_errors(const std::vector<Eigen::Vector3d>& predicted,
                              const std::vector<Eigen::Vector3d>& truth);

// The measurement world as the cameras' calibration realises it: the rigid transform (Umeyama, no
// scale) that carries the true positions of the measured poses onto their measured positions. A
// camera's frame is only as well placed as its intrinsics place it (a principal point 0.03 px off
// turns it by 20 µrad), no measurement can tell, and every measurement and calibrated model lives
// in the frame as calibrated: held-out truth carried into it is what the calibrated cell answers
// to. It is fitted on the measured poses alone, never on a model's predictions. nullopt with fewer
// than three positions, or positions along one line (the turn about it is undetermined).
std::optional<Eigen::Isometry3d> realised_frame(const std::vector<Eigen::Vector3d>& measured,
                                                const std::vector<Eigen::Vector3d>& truth);

}  // namespace robocal::calib
