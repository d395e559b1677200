#pragma once
// Measurements file (YAML): actuator readings per pose plus what was observed of the measured
// frame there. Format documented in testdata/measurements/README.md. Every error names the file,
// the line and the problem (MeasurementsFileError).
#include "robocal/calib/identification.hpp"
#include "robocal/calib/pixel_observations.hpp"
#include "robocal/core/input_error.hpp"

#include <stdexcept>
#include <string>

namespace robocal::calib {

// The project's one input-error type (core/input_error.hpp).
using MeasurementsFileError = core::InputError;

struct MeasurementsFile {
  std::string source;
  std::string robot;  // robot name the data belongs to ("" = not stated)
  std::string frame;  // measured body name ("" = the robot's tool frame)
  Measurements measurements;
  Eigen::VectorXd actuator_sigma;  // optional per-actuator reading noise (reading units)
  // Cameras of the pixel observations (PixelObservation::camera indexes this list); the first is
  // the gauge. Build the model with CameraRigPredictor(robot, cameras).
  std::vector<ObservingCamera> cameras;
};

MeasurementsFile load_measurements_file(const std::string& path);
MeasurementsFile parse_measurements_yaml(const std::string& text, const std::string& source);

// Writes measurements (metres, radians) in the same format; used by simulation.
void save_measurements_file(const MeasurementsFile& file, const std::string& path);
std::string measurements_to_yaml(const MeasurementsFile& file);

}  // namespace robocal::calib
