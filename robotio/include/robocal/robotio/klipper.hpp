#pragma once
// A Klipper printer as Moonraker shows it: its delta geometry from the configuration Klipper
// loaded, and its stepper positions from `GET_POSITION`. Pure functions over JSON and text, shared
// by the Klipper link and the simulated Klipper so both read the protocol one way.
//
// Sources (looked up, not guessed):
// - Moonraker `printer.objects.query` {"objects": {"configfile": ["settings"]}} answers
//   {"eventtime": t, "status": {"configfile": {"settings": {section: {option: value}}}}}: the
//   settings Klipper parsed at its last start, defaults included, sections and options in lower
//   case (Klipper docs/Status_Reference.md, "configfile").
// - `[printer] kinematics: delta`, `delta_radius`; `[stepper_a]`..`[stepper_c]`: `arm_length`
//   and `position_endstop` (stepper_b and _c default to stepper_a's), `angle` (210, 330, 90),
//   `rotation_distance`, `microsteps`, `full_steps_per_rotation` (200), `gear_ratio` (pairs);
//   the step distance is rotation_distance / (full_steps_per_rotation * microsteps * gear ratio)
//   (docs/Config_Reference.md, docs/Rotation_Distance.md).
// - `GET_POSITION` (klippy/extras/gcode_move.py) answers through `respond_info`, every line
//   prefixed "// " (klippy/gcode.py): "mcu: stepper_a:N stepper_b:N stepper_c:N", "stepper:
//   stepper_a:%.6f ...", "kinematic: X:%.6f Y:%.6f Z:%.6f", "toolhead: X:.. Y:.. Z:.. E:..",
//   "gcode: ...", "gcode base: ...", "gcode homing: ...". `mcu` is the step count the micro-
//   controller holds, `stepper` the commanded carriage position (mm).
// - Errors reach a Moonraker client as a JSON-RPC error {"code": 400, "message": "..."} and as
//   a "!! ..." G-code response.
#include "robocal/robotio/delta_firmware.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace robocal::robotio {

// The configuration of a Klipper printer, as far as robocal drives it.
struct KlipperPrinter {
  std::string kinematics;              // [printer] kinematics ("delta", "cartesian", ...)
  std::optional<DeltaGeometry> delta;  // a delta's geometry (firmware kKlipper)
  double steps_per_mm = 0.0;           // of stepper_a (a delta's three must agree)
  std::string problem;                 // why robocal cannot drive it in delta mode ("" if it can)
};

// Reads `configfile.settings`. A printer that is not a delta, or whose settings lack or garble a
// figure robocal needs, gets `problem` naming the section and option.
KlipperPrinter klipper_printer_from_settings(const nlohmann::json& settings);

// The settings a Klipper delta with this geometry reports (the simulated Klipper's; the reader
// above takes them back). `steps_per_mm` becomes rotation_distance with 200 full steps and 16
// microsteps.
nlohmann::json klipper_delta_settings(const DeltaGeometry& geometry, double steps_per_mm);

// One GET_POSITION answer: the microcontroller step counts and the commanded carriage positions
// (mm) of the named steppers, in the order asked for.
struct KlipperPosition {
  std::vector<long> mcu;
  std::vector<double> stepper;
};
// Parses the G-code responses of one GET_POSITION (the "// mcu: ..." and "// stepper: ..." lines,
// in one text or several). nullopt when either line or a named stepper is missing or garbled.
std::optional<KlipperPosition> parse_get_position(const std::vector<std::string>& responses,
                                                  const std::vector<std::string>& steppers);

// The text GET_POSITION prints for a delta (the simulated Klipper's).
std::string get_position_text(const std::array<long, 3>& mcu, const std::array<double, 3>& stepper,
                              const Eigen::Vector3d& kinematic, const Eigen::Vector3d& toolhead);

// Klipper's microcontroller counts run from an arbitrary origin; homing ties them to the
// commanded position (mcu = mcu at the endstop + round((stepper - endstop coordinate) *
// steps/mm), stepper.py's offset). The count each tower's microcontroller holds at its endstop,
// from any position read while homed:
std::array<long, 3> klipper_mcu_at_endstop(const CarriageFrame& frame, const KlipperPosition& p);
// The step counts in the link's frame (CarriageFrame: the firmware's count at the endstop plus
// the steps since) of the microcontroller counts.
std::vector<long> klipper_frame_counts(const CarriageFrame& frame, const KlipperPosition& p,
                                       const std::array<long, 3>& mcu_at_endstop);

}  // namespace robocal::robotio
