#pragma once
// The link an address names, for every command that takes --link: "open:HOST:PORT" is the open
// link protocol (OPEN_LINK.md); "ur:HOST" (or ur:HOST:RTDE:SECONDARY:DASHBOARD ports) is a
// Universal Robots controller (ur_link.hpp); "manual" is the operator (manual_link.hpp, standard
// input and output); "moonraker:HOST[:PORT]" is a Klipper printer through Moonraker
// (klipper_link.hpp); a serial device path or tcp:HOST:PORT is a G-code firmware.
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/gcode_link.hpp"
#include "robocal/robotio/robot_link.hpp"

#include <memory>
#include <optional>

namespace robocal::robotio {

// `options.address` selects the protocol; the G-code options (axes, baud) apply to G-code only,
// the timeouts and attempts to both. Throws LinkError for a malformed address.
std::unique_ptr<RobotLink> make_robot_link(SafetyGuard& guard, const GcodeLinkOptions& options);

// The frame a connected link drives a delta printer's own kinematics with (a G-code link in
// native mode, the Klipper link); nullopt for every other link: what the firmware can command
// (firmware_can_command) follows from it.
std::optional<CarriageFrame> firmware_delta_frame(const RobotLink& link);

}  // namespace robocal::robotio
