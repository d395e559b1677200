#pragma once
// The held-out figures split by the measured region (calib/measured_region.hpp: the convex hull
// of the measured end-effector positions) for validation.json (app/SESSION.md).
#include "robocal/calib/measured_region.hpp"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <cstddef>
#include <string>
#include <vector>

namespace robocal::app {

using calib::distance_to_region;
using calib::kRegionInsideTolerance;
using calib::RegionDistance;

// One prediction of the held-out positions (e.g. "calibrated": the pose route's model).
struct NamedPoints {
  std::string name;
  const std::vector<Eigen::Vector3d>* points = nullptr;
};

// Held-out position errors split by region: {"inside": {...}, "outside": {...}}, each with
// "held_out_poses" and, per prediction, {"rms_m", "max_m", "poses"} against `truth` (the same
// figures as validate's all-configurations ones, over the subset), and for "outside" the
// largest and median distance to the region. inside[k] says where truth[k] lies.
nlohmann::json split_errors_by_region(const std::vector<bool>& inside,
                                      const std::vector<double>& outside_m,
                                      const std::vector<Eigen::Vector3d>& truth,
                                      const std::vector<NamedPoints>& predictions);

}  // namespace robocal::app
