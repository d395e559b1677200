#pragma once
// Motion order of the selected poses: a short tour in actuator space (joint units), nearest
// neighbour from the start, then 2-opt. Every segment used is checked for collision (and
// continuous assembly) along the interpolated motion by the caller's `segment_free`; a segment
// that fails is never used (2-opt only accepts moves whose new segments are free).
#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace robocal::planner {

// true when the straight actuator-space motion a -> b is safe; `why` says what blocks it.
using SegmentTest =
    std::function<bool(const Eigen::VectorXd& a, const Eigen::VectorXd& b, std::string* why)>;

struct Tour {
  std::vector<std::size_t> order;  // indices into the poses, in motion order
  double length = 0.0;             // sum of Euclidean actuator-space segment lengths
  double nearest_neighbour_length = 0.0;
  bool complete = false;  // every pose is in the order with free segments
  std::size_t segments_checked = 0;
  std::vector<std::string> problems;  // poses that could not be connected, and why
};

// `start` (optional): the robot's current readings; the tour begins there. `metric` scales
// each actuator coordinate (joint units per reading unit), empty = 1.
Tour plan_tour(const std::vector<Eigen::VectorXd>& poses, const SegmentTest& segment_free,
               const Eigen::VectorXd& start = Eigen::VectorXd(),
               const Eigen::VectorXd& metric = Eigen::VectorXd());

}  // namespace robocal::planner
