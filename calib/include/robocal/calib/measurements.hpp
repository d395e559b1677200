#pragma once
// Measurements of the robot's measured frame, as identification reads them: per pose the
// actuator readings and what was observed there, plus distances between poses. The file format
// that carries them is measurements_file.hpp.
#include "robocal/calib/observations.hpp"

#include <Eigen/Core>

#include <string>
#include <variant>
#include <vector>

namespace robocal::calib {

using Observation =
    std::variant<PoseObservation, PointObservation, ProbeHeightObservation, PixelObservation>;

// One measured pose: the actuator readings and what was observed of the measured frame there.
struct PoseMeasurement {
  std::string id;
  Eigen::VectorXd actuators;
  std::vector<Observation> observations;
  int line = 0;  // line in the measurements file (0 = not from a file), for messages
  std::vector<PixelGroup> pixel_groups{};  // jointly measured pixel observations (may be empty)
};

// Distance between the measured frame at two poses (ball-bar, scale bar), by pose id.
struct DistanceMeasurement {
  std::string first;
  std::string second;
  DistanceObservation observation;
};

struct Measurements {
  std::vector<PoseMeasurement> poses;
  std::vector<DistanceMeasurement> distances;
};

}  // namespace robocal::calib
