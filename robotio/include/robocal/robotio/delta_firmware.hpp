#pragma once
// A delta printer's firmware in its own kinematics (firmware-native mode): the delta geometry
// Marlin and RepRapFirmware report, their inverse and forward kinematics, and how their carriage
// coordinates map to the robot file's carriage readings. Pure functions over text and numbers,
// shared by the G-code link and the simulated firmware so both read the protocol one way.
//
// Sources (looked up, not guessed):
// - Marlin 2.x `M503` lists the active settings, each as "echo:  M665 L.. R.. H.. S.. X.. Y.. Z..
//   A.. B.. C.." (diagonal rod, delta radius, delta height, segments per second, tower angle trims,
//   diagonal rod trims) and "echo:  M666 X.. Y.. Z.." (endstop adjustments, <= 0) under
//   "echo:; ..." headings. Towers at 210 + X, 330 + Y, 90 + Z degrees on the radius R; tower i's
//   carriage coordinate is z + sqrt((L + trim_i)^2 - (x - x_i)^2 - (y - y_i)^2); a step count is
//   lround(coordinate * steps/mm). Homing backs each carriage |M666| below its endstop and calls
//   that position (0, 0, H). On a delta, `M114` names the stepper counts A, B, C: "X:.. Y:.. Z:..
//   E:.. Count A:n B:n C:n".
// - RepRapFirmware 3.x `M665` without parameters answers "Diagonals 215.000:215.000:215.000, delta
//   radius 105.000, homed height 250.000, bed radius 85.0, X 0.000°, Y 0.000°, Z 0.000°"; `M666`
//   answers "Endstop adjustments X0.00 Y0.00 Z0.00, tilt X0.00% Y0.00%". Carriage coordinate
//   z + sqrt(L_i^2 - dx^2 - dy^2) + x * tilt_x + y * tilt_y; motor steps lrintf(coordinate *
//   steps/mm); at the endstop the carriage coordinate is H + sqrt(L_i^2 - R^2) + M666_i. M114
//   lists the counts in motor order after "Count".
// - Klipper (klippy/kinematics/delta.py, docs/Config_Reference.md "Linear Delta Kinematics"):
//   `delta_radius`, per tower `arm_length`, `angle` (210, 330, 90 by default) and
//   `position_endstop`; the carriage coordinate at tower i's endstop is position_endstop_i +
//   sqrt(arm_i^2 - R^2), the same form as RRF's with H = stepper_a's position_endstop and the
//   others' differences as adjustments (klipper.hpp reads the configuration).
#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/gcode_dialect.hpp"

#include <Eigen/Core>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// A firmware's delta geometry in its own units (mm, degrees), towers A, B, C = X, Y, Z.
struct DeltaGeometry {
  Firmware firmware = Firmware::kMarlin;
  std::array<double, 3> diagonal_rod{};        // per tower (Marlin: L + A/B/C trim)
  double radius = 0.0;                         // delta radius R
  double height = 0.0;                         // H: nozzle height when homed
  std::array<double, 3> angle_trim{};          // degrees added to 210, 330, 90
  std::array<double, 3> endstop_adjustment{};  // M666 X Y Z
  double tilt_x = 0.0, tilt_y = 0.0;           // RRF M666 A B, as fractions (not %)
  double segments_per_second = 200.0;          // Marlin S (reported back, not geometry)
  double bed_radius = 85.0;                    // RRF B (reported back, not geometry)
};

// Marlin: the M665 and M666 lines among `M503`'s reply lines. nullopt when no M665 line is
// there (the firmware was not built for a delta); a malformed value is nullopt too.
std::optional<DeltaGeometry> parse_marlin_delta_settings(const std::vector<std::string>& lines);
// RepRapFirmware: the replies to `M665` and `M666` without parameters. nullopt when the M665
// reply is not a delta's ("Diagonals ..."); a missing or malformed M666 reply is nullopt too.
std::optional<DeltaGeometry> parse_rrf_delta_settings(const std::vector<std::string>& m665_lines,
                                                      const std::vector<std::string>& m666_lines);

// What each firmware prints (the simulator's replies; the parsers above read them back).
std::vector<std::string> marlin_m503_lines(const std::optional<DeltaGeometry>& delta,
                                           double steps_per_mm);
std::string rrf_m665_reply(const DeltaGeometry& g);
std::string rrf_m666_reply(const DeltaGeometry& g);

// Tower i's position on the firmware's circle (mm).
Eigen::Vector2d tower_xy(const DeltaGeometry& g, int tower);
// The firmware's inverse kinematics: carriage coordinates (mm) of the nozzle at `xyz` (mm);
// nullopt when a rod cannot reach.
std::optional<Eigen::Vector3d> carriage_coordinates(const DeltaGeometry& g,
                                                    const Eigen::Vector3d& xyz);
// Its forward kinematics: the nozzle (mm) for carriage coordinates (mm), the solution below the
// carriages; nullopt when the rods cannot meet.
std::optional<Eigen::Vector3d> nozzle_position(const DeltaGeometry& g,
                                               const Eigen::Vector3d& carriages);
// The carriage coordinate (mm) the firmware gives tower i at its endstop.
double endstop_coordinate(const DeltaGeometry& g, int tower);
// Where homing leaves tower i below its endstop (mm): Marlin backs off |M666|, RRF stays.
double homing_backoff(const DeltaGeometry& g, int tower);

// The carriage readings of the robot file (m) and the firmware's carriage coordinates (mm) differ
// by a constant per tower: both are carriage heights, the firmware's counted from its own zero.
// The endstop is where they are tied together: at tower i's endstop the reading is
// `endstop_reading[i]` (the robot file's upper carriage limit, as the firmware exports assume),
// taken at the whole step the firmware counts there, so a homed carriage reads exactly that
// limit (not half a step beyond it, which the guard would refuse).
struct CarriageFrame {
  DeltaGeometry geometry;
  std::array<double, 3> endstop_reading{};  // m
  double steps_per_mm = 80.0;
};
// The step count the firmware holds at tower i's endstop.
long endstop_count(const CarriageFrame& f, int tower);
double carriage_coordinate_of_reading(const CarriageFrame& f, int tower, double reading);
double reading_of_carriage_coordinate(const CarriageFrame& f, int tower, double coordinate);
// A firmware's carriage coordinate (mm) of a step count and the step count it plans for a
// coordinate. Marlin and RRF count steps from their coordinate's zero (count = round(coordinate *
// steps/mm)); Klipper counts them from where homing set the position (stepper.py: mcu position =
// round((commanded position + offset) / step distance), the offset set so that the endstop
// coordinate falls on the step counted there), so its steps lie on a grid through the endstop.
double coordinate_of_count(const CarriageFrame& f, int tower, long count);
long count_of_coordinate(const CarriageFrame& f, int tower, double coordinate);
// Step counts of readings (what the firmware counts there) and readings of step counts.
std::vector<long> delta_counts(const CarriageFrame& f, const Eigen::VectorXd& readings);
Eigen::VectorXd delta_readings(const CarriageFrame& f, const std::vector<long>& counts);
// The firmware's Cartesian target (mm) that puts the carriages on exactly `counts`: the forward
// kinematics of the counted coordinates, so the firmware's inverse rounds back to them.
std::optional<Eigen::Vector3d> cartesian_for_counts(const CarriageFrame& f,
                                                    const std::vector<long>& counts);
// The step counts the firmware plans for a Cartesian target (its inverse kinematics, rounded as
// it rounds); nullopt when unreachable.
std::optional<std::vector<long>> counts_for_cartesian(const CarriageFrame& f,
                                                      const Eigen::Vector3d& xyz);

// A frame as one line of text and back, every figure exact, for a caller that keeps it between
// runs (the wizard, between connecting and planning): "firmware=Klipper rods=A,B,C radius=R
// height=H angle_trim=A,B,C endstops=X,Y,Z tilt=A,B steps_per_mm=S endstop_reading=A,B,C" (mm,
// degrees; the readings in m). nullopt for text that does not hold every figure.
std::string carriage_frame_text(const CarriageFrame& f);
std::optional<CarriageFrame> carriage_frame_from_text(const std::string& text);

// Whether the firmware's kinematics can hold the carriages on `counts`: its inverse kinematics
// puts every carriage above the nozzle (z + sqrt(...)), so a configuration with a rod rising
// from its carriage to the effector has no Cartesian command; the round trip then fails.
bool firmware_can_command(const CarriageFrame& f, const std::vector<long>& counts);

// The robot file's drawing as firmware geometry (mm, degrees), with the tolerance of each figure
// (3 sigma of the robot file's own tolerances): the closed form's rails, rods and platform
// offsets. Empty `problem` when the robot is a linear delta the firmware can drive.
struct RobotFileDelta {
  std::string problem;
  std::array<double, 3> diagonal_rod{};
  double radius = 0.0;
  std::array<double, 3> tower_angle{};  // degrees, absolute
  double rod_tolerance = 0.0, radius_tolerance = 0.0, angle_tolerance = 0.0;
  std::array<double, 3> endstop_reading{};  // m: each carriage's upper limit
};
RobotFileDelta robot_file_delta(const calib::Mechanism& model);

// The geometry an owner who built the printer from the robot file's drawing enters: its rods,
// radius and tower angles, no endstop adjustments, and the homed height H that puts the
// firmware's origin on the robot file's base (equal rods; otherwise tower A's).
DeltaGeometry drawing_geometry(const RobotFileDelta& file, Firmware firmware);
// Sets one figure from "NAME=VALUE" (mm, degrees): L (every rod), L_A, L_B, L_C, R, H, X, Y, Z
// (tower angle trims), M666_X, M666_Y, M666_Z. Throws std::invalid_argument naming the item.
void apply_delta_setting(DeltaGeometry& g, const std::string& item);

// Each figure where the firmware and the robot file disagree by more than the tolerance, in
// plain words ("tower A diagonal rod: the firmware says 217.00 mm, the robot file 215.00 mm
// (tolerance 1.50 mm)"); empty when they agree.
std::vector<std::string> geometry_disagreements(const DeltaGeometry& firmware,
                                                const RobotFileDelta& file);

}  // namespace robocal::robotio
