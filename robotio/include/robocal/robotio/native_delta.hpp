#pragma once
// Moves of a delta printer in its firmware's own kinematics (firmware-native mode), one way for
// every link that drives one: the G-code link (Marlin, RepRapFirmware) and the Klipper link. The
// guard checks a straight path in actuator space; the firmware moves straight in its Cartesian
// frame; so a move is sent as Cartesian segments between points of the checked path, each the
// firmware's forward kinematics of the step counts wanted there (delta_firmware.hpp), at a feed
// that makes each segment take as long as the requested joint speed.
#include "robocal/calib/mechanism.hpp"
#include "robocal/robotio/delta_firmware.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal/robotio/safety_guard.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::robotio {

// Which geometry the operator trusts when the firmware's delta geometry disagrees with the robot
// file's beyond the file's tolerance. kAsk: the link refuses to connect and names every
// difference (nothing moves); kFirmware / kRobotFile: the operator's answer. Moves are computed
// with the firmware's own model either way (only it lands the carriages on the requested steps);
// the answer is the operator's record of which drawing is right (GcodeLink::geometry_disagreements
// keeps what was accepted; collect writes both into the session).
enum class GeometryChoice : std::uint8_t { kAsk, kFirmware, kRobotFile };

// The firmware's delta geometry differs from the robot file's beyond its tolerance and the
// operator has not chosen which to trust (GeometryChoice::kAsk): nothing moved. what() names
// every difference.
class GeometryDisagreement final : public LinkError {
 public:
  using LinkError::LinkError;
};

// The frame a link drives the firmware with: its geometry, the robot file's carriage readings at
// the endstops, its steps/mm. `disagreements` gets every figure where the firmware and the robot
// file differ beyond the file's tolerance (plain words); with GeometryChoice::kAsk and any, throws
// GeometryDisagreement naming them all (nothing has moved).
CarriageFrame native_frame(const DeltaGeometry& firmware, const calib::Mechanism& model,
                           double steps_per_mm, GeometryChoice choice, const std::string& device,
                           std::vector<std::string>& disagreements);

// The points (readings) the straight path from `from` to `to` is sent through: at most `segment`
// of joint travel apart (joint lengths are readings times `joint_per_reading`). An unknown start
// (`from` empty) is one point, the target.
std::vector<Eigen::VectorXd> native_waypoints(const Eigen::VectorXd& from,
                                              const Eigen::VectorXd& to,
                                              const Eigen::VectorXd& joint_per_reading,
                                              double segment);

// The firmware's G1 lines for the move. Throws MotionRefused (nothing sent) when a point of the
// path cannot be commanded in the firmware's kinematics, LinkError naming `device` when its model
// cannot reach one.
std::vector<std::string> native_move_gcodes(const CarriageFrame& frame, const Eigen::VectorXd& from,
                                            const Eigen::VectorXd& to, const MoveSpeed& speed,
                                            const Eigen::VectorXd& joint_per_reading,
                                            double segment, const std::string& device);

// Cartesian path length (mm) per joint length of the whole move: the firmware's acceleration is
// Cartesian too. 1000 (mm per m) when the start is unknown or the move has no length.
double native_gcode_per_joint(const CarriageFrame& frame, const Eigen::VectorXd& from,
                              const Eigen::VectorXd& to, const Eigen::VectorXd& joint_per_reading);

// Each native segment is its own move, standstill to standstill at worst: the move's duration.
double native_expected_seconds(const Eigen::VectorXd& from, const Eigen::VectorXd& to,
                               const MoveSpeed& speed, const Eigen::VectorXd& joint_per_reading,
                               double segment);

}  // namespace robocal::robotio
