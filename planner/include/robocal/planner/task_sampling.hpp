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
#include "robocal/planner/feasibility.hpp"

#include <cstddef>
#include <random>
#include <vector>

namespace robocal::planner {

// True when task-space sampling applies: the model's task is the full pose (6 rows) of the
// checker's measured frame, it has at least six actuators (any orientation can be asked for)
// and the cell has required cameras.
bool task_space_sampling_applies(const FeasibilityChecker& checker);

// `count` candidates built as above, each evaluated (every one is counted in `counts`).
std::vector<Candidate> sample_facing_cameras(const FeasibilityChecker& checker, std::size_t count,
                                             std::mt19937& rng, FeasibilityCounts* counts);

}  // namespace robocal::planner
