#pragma once
// Compensation: making a controller that only knows the robot's NOMINAL model put the tool where
// it was meant to go, using the CALIBRATED model.
//
// For a target x (task coordinates), the calibrated inverse kinematics gives the actuator readings
// q = IK_cal(x) that put the real tool at x; the nominal controller produces q when it is asked
// for x' = FK_nom(q) (its own inverse kinematics of x' is q again). So:
//   - a robot driven by actuator commands is sent q (compensate_target: the commands with the
//     assembly-mode verdict of the calibrated answer);
//   - a robot driven by task-space commands (a printer's G-code) is sent x' instead of x.
// Between two task-space commands the nominal controller moves on a straight line in ITS model,
// which the real robot turns into a curve; compensate_segment subdivides a straight move until
// that curve stays within a tolerance of the straight line that was meant.
//
// Both parameter vectors belong to one Mechanism and must be expressed in the same task
// coordinates (calibrated_in_robot_frame brings an identified model into the robot file's frame).
#include "robocal/calib/inverse_kinematics.hpp"
#include "robocal/calib/mechanism.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace robocal::calib {

struct CompensationModels {
  const Mechanism* model = nullptr;
  Eigen::VectorXd nominal;     // what the controller computes with
  Eigen::VectorXd calibrated;  // the identified robot
};

enum class TargetVerdict : std::uint8_t {
  kOk,           // on the intended assembly mode, within the joint limits
  kAmbiguous,    // reached, but at a configuration where assembly modes meet (near-singular)
  kOtherMode,    // the calibrated robot reaches it only on another assembly mode
  kUnreachable,  // no closed configuration within the joint limits reaches it
};
const char* to_string(TargetVerdict verdict);

struct CompensatedTarget {
  TargetVerdict verdict = TargetVerdict::kUnreachable;
  IkResult ik;                   // calibrated IK: readings, joint values, mode check
  Eigen::Isometry3d commanded =  // FK of ik.actuator_readings through the NOMINAL model
      Eigen::Isometry3d::Identity();
  std::string problem;  // plain words when the verdict is not kOk
  // Commands that may be sent: reached, and not on another assembly mode.
  [[nodiscard]] bool usable() const {
    return verdict == TargetVerdict::kOk || verdict == TargetVerdict::kAmbiguous;
  }
};

// Calibrated IK of `target` (joint limits respected, the robot file's assembly mode enforced),
// then the nominal FK of the answer. `seed` warm-starts the IK (the previous target's answer).
CompensatedTarget compensate_target(const CompensationModels& models, const TaskTarget& target,
                                    const IkSeed& seed = {});

// Reusable compensation with one pair of models, for many targets (compensate_targets, the G-code
// rewriter): what depends only on the models is built once (both models' cached transforms, the
// Newton workspace, a linear prediction of the passive joints from the actuators for cold starts),
// and each target then costs a few allocation-free Newton steps on the calibrated IK system
// (closure + task rows) and on the nominal closure. Results are those of compensate_target: an
// answer is taken from the fast path only when it converges to the IK tolerance on an acceptable
// assembly mode within the joint limits (and the nominal closure closes on a mode that is not
// another one); otherwise the target goes through the general solver (solve_ik /
// forward_kinematics with their re-seeding), as before. The fast answer is judged as solve_ik
// judges its own: its verdict carries the closure conditioning (ambiguous near a singularity),
// and where the calibrated loops are within the design check's band of a singularity its readings
// must give the same tool pose through the robot's forward kinematics (the design's answer
// followed to the calibrated parameters) — on the rotary Delta about half of the workspace lies in
// that band, and such a target costs a cold forward kinematics more. Keeps a pointer to
// `models.model`, which must outlive it; not for use from two threads at once.
class Compensator {
 public:
  explicit Compensator(const CompensationModels& models);
  // As compensate_target(models, target, seed).
  CompensatedTarget compensate(const TaskTarget& target, const IkSeed& seed = {});
  // Its first half alone: the calibrated model's inverse kinematics (the readings that put the
  // tool on `target`, for a controller that takes actuator commands), with the verdict; the same
  // answer as compensate(target, seed).ik.
  IkResult calibrated_ik(const TaskTarget& target, const IkSeed& seed = {});
  [[nodiscard]] const CompensationModels& models() const;
  // How many answers each path gave so far (fast Newton paths vs the general solvers).
  struct Counts {
    int fast_ik = 0, general_ik = 0, fast_fk = 0, general_fk = 0;
  };
  [[nodiscard]] const Counts& counts() const;

  Compensator(const Compensator&) = delete;
  Compensator& operator=(const Compensator&) = delete;
  Compensator(Compensator&&) noexcept;
  Compensator& operator=(Compensator&&) noexcept;
  ~Compensator();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

// Every target of a list, with one Compensator. Each IK starts from the answer of the nearest
// target already solved when it lies within 1 cm (task-space distance; a path, a fine grid: two or
// three Newton steps), else cold (closed-form seed: about five); a warm start that does not give
// a usable answer is retried cold.
std::vector<CompensatedTarget> compensate_targets(const CompensationModels& models,
                                                  const std::vector<TaskTarget>& targets);

// Tool position the robot reaches (model `params`) when a nominal controller is commanded to
// `commanded` (task position): nominal IK, then FK through `params`. false with `why` when the
// nominal controller or the robot cannot reach it.
// `seed`: readings near the answer (the calibrated IK of a nearby meant point), to start warm.
bool executed_position(const CompensationModels& models, const Eigen::VectorXd& params,
                       const Eigen::Vector3d& commanded, Eigen::Vector3d& reached, std::string& why,
                       const IkSeed& seed = {});

// One straight move meant from `from` to `to` (task positions, position-task robots), for a
// nominal controller that interpolates straight lines between the commanded points.
struct CompensatedSegment {
  std::vector<double> fractions;           // of the meant move, increasing, last = 1
  std::vector<Eigen::Vector3d> commanded;  // x' per fraction (what to send)
  double max_deviation = 0.0;              // largest predicted tool error at the checked points (m)
  IkSeed end_seed;  // the calibrated IK answer at the end (seed for the next move)
  bool ok = false;
  std::string problem;
};

struct SegmentOptions {
  double tolerance = 10e-6;  // m: calibrated tool path vs the meant straight line
  int max_depth = 16;        // bisections of one move (2^16 pieces at most)
};

// Bisects the move until, between consecutive commanded points, the calibrated robot driven by
// the nominal controller stays within `tolerance` of the meant point at 1/4, 1/2 and 3/4 of each
// piece (the error of a chord of a smooth curve peaks near its middle). `from_commanded` is the
// already compensated start (x' of `from`); `from_seed` its calibrated IK answer (warm starts).
CompensatedSegment compensate_segment(const CompensationModels& models, const Eigen::Vector3d& from,
                                      const Eigen::Vector3d& from_commanded,
                                      const Eigen::Vector3d& to, const SegmentOptions& options = {},
                                      const IkSeed& from_seed = {});

// An identified parameter vector expressed in the robot file's own coordinates, so targets are
// given relative to the robot rather than to the measurement world:
//  - the base frame (parameters of the bodies hanging from the world) takes `file_nominal`'s
//    values (identification placed it in the measurement world, e.g. the first camera's frame);
//  - the parameters of `mount_body` (the measured frame whose values a session's target mount
//    replaced, -1 = none) take `file_nominal`'s values: they were the pose of the end-effector
//    BOARD on that frame, and what identification changed in them is the board's mounting, not
//    the tool's (the tool keeps the robot file's offset from the identified bodies before it);
//  - every other parameter keeps its identified value.
Eigen::VectorXd calibrated_in_robot_frame(const Mechanism& model, const Eigen::VectorXd& estimate,
                                          const Eigen::VectorXd& file_nominal, int mount_body);

// The calibrated robot in the user's frames, for exports (URDF, firmware settings, DH): the
// robot's own base frame and its own tool (calibrated_in_robot_frame's parameters), with the two
// frames the calibration measured in kept beside them instead of in the robot's place:
//  - the measured frame (the end-effector board as mounted and identified) on the body before it;
//  - the measurement world (the first camera's frame) placed in the robot's world.
struct UserFrames {
  Eigen::VectorXd params;  // the robot in its own frames (calibrated_in_robot_frame)
  int measured_body = -1;  // the body whose frame was measured (-1: none given)
  // The measured frame's pose on its predecessor body (the identified mounting); its
  // predecessor's index (-1: the world).
  int measured_parent = -1;
  Eigen::Isometry3d parent_T_measured = Eigen::Isometry3d::Identity();
  // The measurement world (the identification's world, the first camera's frame) in the robot's
  // world frame; world_T_base of the robot's own base is then T(file) and its camera the same.
  Eigen::Isometry3d world_T_measurement = Eigen::Isometry3d::Identity();
};

// `estimate`: an identified parameter vector whose world is the measurement world and whose
// `measured_body` carries the board's mount when `mount_replaced` (a session's target mount);
// `file_nominal`: the robot file's own values. Every body hanging from the world is moved by one
// rigid transform (the first body's own base goes to its file values, the others keep their
// place relative to it), so the identified geometry is unchanged. Throws std::invalid_argument
// for vectors of the wrong size or a measured body out of range.
UserFrames user_frames(const Mechanism& model, const Eigen::VectorXd& estimate,
                       const Eigen::VectorXd& file_nominal, int measured_body, bool mount_replaced);

}  // namespace robocal::calib
