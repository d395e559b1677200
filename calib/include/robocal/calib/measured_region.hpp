#pragma once
// The measured region: the part of the workspace an identification's poses cover, and how far a
// configuration lies from it.
//
// Identification constrains the model where it was measured. A configuration far outside the
// measured poses is predicted by extrapolation along directions the measurements constrain
// weakly, and its error can be millimetres where the measured region's is micrometres. The
// region is the convex hull of the measured end-effector positions: "inside" is interpolation
// between measured poses, "outside" extrapolation, and the distance to the hull says how far.
#include <Eigen/Core>

#include <cstddef>
#include <utility>
#include <vector>

namespace robocal::calib {

// A position within this distance of the hull counts as inside it (rounding only: the hull of
// measured positions has no tolerance of its own).
inline constexpr double kRegionInsideTolerance = 1e-6;  // m

struct RegionDistance {
  double outside_m = 0.0;                             // distance to the convex hull; 0 inside
  double nearest_measured_m = 0.0;                    // distance to the nearest measured position
  bool inside = false;                                // outside_m <= kRegionInsideTolerance
  Eigen::Vector3d closest = Eigen::Vector3d::Zero();  // the hull's point nearest to the query
  // closest = sum of weight * measured[index] (weights >= 0, summing to 1): at most 4 points.
  std::vector<std::pair<std::size_t, double>> support;
  bool converged = true;  // false: the iteration cap was hit (closest is still a hull point)
};

// Distance from `p` to the convex hull of `measured` (exact minimum-norm point, Wolfe's
// algorithm; works for flat or collinear sets too). An empty set is infinitely far away.
RegionDistance distance_to_region(const std::vector<Eigen::Vector3d>& measured,
                                  const Eigen::Vector3d& p);

}  // namespace robocal::calib
