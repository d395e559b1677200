#pragma once
// Task-space candidates: for a robot whose task is the full pose of the measured frame (serial
// arms), candidates drawn in joint space put the target in a random orientation, and a camera
// pair sees it whole, at the incidence and size the cell asks, at almost none of them (UR5 in the
// simulated cell: 0 of 40 000 uniform joint samples). Here each candidate is built the other way
// round: a reachable position of the target's centre (from a joint sample on the intended mode),
// the printed face turned towards the required cameras' mean position and tilted at random
// within what keeps every required camera inside the cell's maximum incidence, then inverse
// kinematics (calib::solve_ik, intended assembly mode, joint limits respected) seeded from that
// joint sample. The answer is evaluated by the same FeasibilityChecker::evaluate as a joint
// sample: reach on the intended mode, collisions, visibility; a target pose without an IK answer
// on the intended mode counts as "cannot assemble" / "only on another assembly mode".
//
// A robot with fewer than six actuators (the 4-DOF wire robot's branch: its platform's pitch
// and yaw turn the board, but it cannot take an arbitrary pose) gets its candidates the same way
// up to the face direction asked; then, instead of IK, its joints turn the printed face towards
// that direction as far as they can (damped Gauss-Newton on the face direction from the joint
// sample, every step on the intended mode), and the answer is evaluated as above. Joint samples
// put its board at random angles: its camera pair saw the board whole at 1-2 % of them.
#include "robocal/planner/feasibility.hpp"

#include <cstddef>
#include <random>
#include <vector>

namespace robocal::planner {

// True when the robot sets the target's orientation: its task is the full pose (6 rows) of
// `frame`, with at least two actuators.
bool target_turnable(const calib::Mechanism& model, int frame);

// True when task-space sampling applies: target_turnable on the checker's measured frame, and
// the cell has required cameras.
bool task_space_sampling_applies(const FeasibilityChecker& checker);

// True when the robot's own joints turn its target but it has fewer than six actuators (a pose
// task on `frame`): its candidates are aimed (above), not solved for a pose.
bool target_turned_by_joints(const calib::Mechanism& model, int frame);

// The candidate at `readings` with the target's face turned, without random tilt, towards the
// cameras of the checker's cell that can see its centre (aimed as above), then evaluated; the
// readings as they are where none can, or where turning leaves the intended mode. For
// target_turned_by_joints robots (the camera placement's coverage test).
Candidate evaluate_turned_towards_cameras(const FeasibilityChecker& checker,
                                          const Eigen::VectorXd& readings);

// `count` candidates built as above, each evaluated (every one is counted in `counts`). In a
// camera array (the cell asks for some of its cameras), a candidate faces those that can see it.
std::vector<Candidate> sample_facing_cameras(const FeasibilityChecker& checker, std::size_t count,
                                             std::mt19937& rng, FeasibilityCounts* counts);

}  // namespace robocal::planner
