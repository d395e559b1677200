#pragma once
// Serial-arm exports: URDF out and in (read through Debian's urdfdom), and the
// Denavit-Hartenberg table of a robot whose file already gives its joints in DH or modified DH.
//
// URDF: every robocal body becomes a link with the same frame. A moving body's transform
// A · J(q) · B (the elementary ops before its joint, the joint's motion, the ops after it) becomes
// a joint with origin A (the encoder offset folded in: the URDF joint value is the controller's
// reading) and, when B is not the identity, a fixed joint "<body>_offset" from link
// "<body>_moving" to link "<body>". The root body hangs from a link "world". Origins are written
// with 17 significant digits, so the file reproduces the model to rounding.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace robocal::calib {

// A frame written beside the robot's own bodies: the end-effector board a calibration measured, a
// camera. `parent` is the body it is fixed to (-1: the world); `what` says in words what it is.
struct ExtraFrame {
  std::string name;
  int parent = -1;
  Eigen::Isometry3d parent_T_frame = Eigen::Isometry3d::Identity();
  std::string what;
};

// Joint speed and force written into a URDF joint whose robot file gives none (URDF requires
// both on revolute and prismatic joints, and 0 means "cannot move" to MoveIt): the UR5's rated
// joint speed (180 deg/s) and its base joints' rated torque; 0.5 m/s and 1000 N for a prismatic
// joint.
inline constexpr double kDefaultRevoluteVelocity = 3.14159265358979323846;  // rad/s
inline constexpr double kDefaultRevoluteEffort = 150.0;                     // N m
inline constexpr double kDefaultPrismaticVelocity = 0.5;                    // m/s
inline constexpr double kDefaultPrismaticEffort = 1000.0;                   // N

// Why `model` cannot be written as a URDF, or "" when it can (a tree of bodies without closed
// loops whose moving joints are all actuated).
std::string urdf_mismatch(const Mechanism& model);

// The URDF of `model` at parameter vector `params` (throws std::invalid_argument with
// urdf_mismatch's reason, or for an extra frame whose name is a link's already). Encoder scales
// other than 1 cannot be written (the URDF joint value would be reading × scale): they are named
// in a comment and the joint value is then q. Joint limits: the robot file's `limits` (position),
// `velocity` and `effort`, converted to reading units; where the file gives no velocity or
// effort, the defaults above, named in a comment. `extra` frames become links on fixed joints.
std::string urdf_text(const Mechanism& model, const Eigen::VectorXd& params,
                      const std::vector<ExtraFrame>& extra = {});

// A URDF (read with urdfdom) as a robocal robot file (xyz_rpy bodies, rotation_order zyx = URDF's
// rpy, joint axes along ±x, ±y or ±z). Throws core::InputError naming `source` and the joint for
// what robocal's model cannot take (planar or floating joints, a joint axis off the frame axes).
std::string robot_yaml_from_urdf(const std::string& urdf, const std::string& source);

// The DH table (classic: Rz(θ) Tz(d) Tx(a) Rx(α); modified: Rx(α) Tx(a) Rz(θ) Tz(d)) of the
// moving joints at `params`, θ including the encoder offset, plus the base and tool frames as
// xyz/rpy. Throws std::invalid_argument saying why when the robot's moving joints are not all in
// one of the two DH conventions (the table would not be the robot's model: a DH table has 4
// numbers per joint, robocal's xyz_rpy or MCPC joints up to 6).
// `extra` frames are listed after the base and tool frames (xyz/rpy from their parent).
std::string dh_table_text(const Mechanism& model, const Eigen::VectorXd& params,
                          const std::vector<ExtraFrame>& extra = {});

}  // namespace robocal::calib
