#pragma once
// Assembly modes: the ONE check that tells whether a kinematic answer (forward kinematics, inverse
// kinematics, a closure solved during identification, a sampled pose) lies on the robot's intended
// assembly/working mode. The same actuator readings admit several closed configurations (Delta:
// plate below or above the elbows, crossed parallelograms, a flipped universal joint; serial arm:
// elbow up/down, wrist flip), and a Newton solver lands on whichever is nearest its seed. The robot
// file declares the intended mode as sign invariants (AssemblyModeSpec in mechanism.hpp, format in
// testdata/robots/README.md); this header evaluates them.
//
// Verdicts:
//  - intended:  every invariant has its declared sign, each at least `ambiguity` away from 0;
//  - other:     at least one invariant has the opposite sign (ModeCheck::invariant names them);
//  - ambiguous: no invariant flipped, but one lies within `ambiguity` of 0, or the closure's
//               constraint Jacobian is nearly singular (sigma_min / sigma_max below
//               `min_conditioning`) — the configuration is at or near a singularity where modes
//               meet, so a small error in the geometry or the readings can put the real robot on
//               either side (ModeCheck::invariant is then "closure_conditioning");
//  - undeclared: the robot file declares no mode (nothing can be checked).
// ModeCheck::distance is the distance-to-singularity measure: min over the invariants of |value|
// (dimensionless, 0 = where modes meet, 1 = as far as the invariant can be).
//
// Cost: a few dot/cross products on poses the solver has already computed (no allocation);
// solvers run it on every answer.
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <string>
#include <vector>

namespace robocal::calib {

enum class ModeVerdict : std::uint8_t { kUndeclared, kIntended, kOther, kAmbiguous };

const char* to_string(ModeVerdict verdict);

struct ModeCheck {
  ModeVerdict verdict = ModeVerdict::kUndeclared;
  // kOther: the flipped invariants (comma separated); kAmbiguous: the one nearest 0.
  std::string invariant;
  // min over invariants of declared_sign * value: > 0 on the intended side of every invariant.
  double margin = 0.0;
  // Distance to the nearest singularity where modes meet: min |value| (0..1).
  double distance = 0.0;
  // sigma_min / sigma_max of the closure's constraint Jacobian at the answer; -1 = not evaluated
  // (no loop). check_assembly_mode(model, params, state): exact. Solvers: exact under the
  // ambiguity gate; above it a cheap estimate (which can only overstate) or, along a path of warm
  // solves, a proved lower bound, either on the same side of every threshold as the exact value.
  double conditioning = -1.0;
  bool intended() const { return verdict == ModeVerdict::kIntended; }
  // Not on another mode (intended, ambiguous or undeclared).
  bool acceptable() const { return verdict != ModeVerdict::kOther; }
  // Plain words for messages, e.g. "another assembly mode: invariant 'arm1_parallelogram'
  // flipped (value -0.98, intended positive)".
  std::string describe() const;
};

// Value in [-1, 1] of one invariant for world body poses (pose[b] maps frame b to world) and the
// per-body joint state.
double invariant_value(const ModeInvariant& invariant, const std::vector<Eigen::Isometry3d>& poses,
                       const JointState& state, const Mechanism& model);

// The verdict for an open-tree state (normally a solved closure), including the closure's
// conditioning (exact, by SVD) when the robot has loops.
ModeCheck check_assembly_mode(const Mechanism& model, const Eigen::VectorXd& params,
                              const JointState& state);
// The invariants only, from already computed body poses (body_poses()).
ModeCheck check_assembly_mode(const Mechanism& model, const std::vector<Eigen::Isometry3d>& poses,
                              const JointState& state);

// Per-body joint state of the robot file's home values (every moving body at its `home:`), the
// configuration the file declares to be on its intended mode.
JointState home_joint_state(const Mechanism& model);

}  // namespace robocal::calib
