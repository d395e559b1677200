#pragma once
// G-code programs for printer-style robots, and their compensated rewrite.
//
// parse_gcode reads the subset the rewrite must understand (RepRap/Marlin flavour): G0/G1 moves,
// G2/G3 arcs in the XY plane (G17; centre by I/J or radius by R), G90/G91 absolute/relative
// positioning, M82/M83 absolute/relative extrusion, G92 set position, G20/G21 units (inches are
// refused), G28 home; comments (';' to the end of the line, '(...)' inline). Everything else is
// kept verbatim. A malformed line throws core::InputError naming "<source>:<line>".
//
// rewrite_gcode turns a program written for the NOMINAL model into one that, run by a controller
// that only knows the nominal model, puts the tool where the program meant with the CALIBRATED
// robot (compensation.hpp): every meant position p becomes p' = FK_nom(IK_cal(p)); arcs are cut
// into chords within half the tolerance; every straight piece is subdivided until the calibrated
// tool stays within the tolerance of it. Positioning modes, G92 offsets, feeds (F) and comments are
// kept; extrusion (E) is split over the pieces in proportion to their length.
//
// Why here: the rewrite is compensation science on a program's geometry (calib's), and calib is
// the lowest part that has both models; the text parsing is a small pure function beside it,
// independent of robotio's controller link (which sends commands and may not be included by calib).
#include "robocal/calib/compensation.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace robocal::calib {

struct GcodeWord {
  char letter = 0;  // upper case
  double value = 0.0;
  std::string text;  // as written (kept when a line is copied)
};

struct GcodeLine {
  int number = 0;                // 1-based line in the source
  std::string text;              // the line as written (without the line break)
  std::string command;           // "G1", "G92", "M83" ... (upper case; empty: no command)
  std::vector<GcodeWord> words;  // the words after the command
  std::string comment;  // comments of the line, as written (';...' and '(...)'), space-separated
  [[nodiscard]] const GcodeWord* word(char letter) const;
};

struct GcodeProgram {
  std::string source;  // file name for messages
  std::vector<GcodeLine> lines;
};

GcodeProgram parse_gcode(const std::string& text, const std::string& source);

struct GcodeRewriteOptions {
  double tolerance = 10e-6;  // m: the tool's distance to the meant path between emitted points
  int decimals = 4;          // of the emitted millimetres (1e-4 mm = 0.1 µm); degrees get one more
  // What the controller's axis words are (the robot file's `controller: {gcode_axes}` or the
  // user's word for it): the tool position for a firmware with the robot's nominal kinematics,
  // or one axis per actuator (see gcode_actuator_axes). kUnknown is refused.
  GcodeAxes axes = GcodeAxes::kTool;
};

// The controller's axis of one actuator in raw-axis mode, as robocal's G-code link drives it
// (robotio axes_for_robot): letter X Y Z U V W A B C in actuator order; value = reading x
// `unit_factor` (millimetres for a prismatic joint, degrees for a revolute one, through the
// robot file's nominal encoder scale).
struct GcodeActuatorAxis {
  char letter = 'X';
  std::string body;  // the actuated body's name
  bool revolute = true;
  double unit_factor = 1.0;
};
// Throws core::InputError for more than 9 actuators.
std::vector<GcodeActuatorAxis> gcode_actuator_axes(const Mechanism& model,
                                                   const Eigen::VectorXd& nominal);

struct GcodeRewriteStats {
  int moves = 0;                // meant moves (G0/G1/G2/G3 lines with X, Y or Z)
  int emitted_moves = 0;        // moves written
  double max_correction = 0.0;  // largest |p' - p| (m)
  double max_deviation = 0.0;   // largest predicted tool error between emitted points (m)
};

struct GcodeRewrite {
  std::string text;
  GcodeRewriteStats stats;
};

// Positions in the program are millimetres in the robot's task coordinates (the robot file's
// base frame). Throws core::InputError naming "<source>:<line>" for a line that cannot be
// compensated (malformed, unreachable, another assembly mode, a move from an unknown position).
// The robot's task must be a position (printer-style robots).
//
// With `options.axes` kActuators the output is for a controller whose axes are the actuators:
// every meant point becomes the calibrated inverse kinematics' readings, written per axis
// (gcode_actuator_axes); the controller interpolates the axes linearly, so each move is bisected
// until the calibrated robot, driven along the interpolated readings, stays within the tolerance
// of the meant path at 1/4, 1/2 and 3/4 of every piece (arcs are followed as arcs). A piece's feed
// becomes the axes' rate that takes the piece's meant time (F mm/min of the tool -> F axis units
// per minute); a piece whose start is unknown gets no F. G92's X/Y/Z words shift the program's
// coordinates, which the output has already applied: they are dropped from the line (its E kept).
// max_correction is then the distance between the meant point and where the nominal model puts
// the tool at the written readings.
GcodeRewrite rewrite_gcode(const GcodeProgram& program, const CompensationModels& models,
                           const GcodeRewriteOptions& options = {});

// The meant tool path of a program as points (m) every `step` metres or closer (arcs as true arcs;
// from the first fully known position on). Tests and benches execute it on a simulated robot.
struct GcodePathPoint {
  Eigen::Vector3d position;
  int line = 0;
};
std::vector<GcodePathPoint> gcode_path(const GcodeProgram& program, double step);

}  // namespace robocal::calib
