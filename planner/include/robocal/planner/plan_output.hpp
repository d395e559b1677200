#pragma once
// Plan files and previews.
//
// Plan file (YAML): the robot and cell it was planned for, the selection (index, condition
// number, acceptance, predicted accuracy), then one entry per pose in motion order: id, actuator
// readings (the commands to send), measured-frame position, and per camera the expected pixel of
// the target's centre and its four outline corners (what the operator should see). Written
// atomically (temporary file + rename), so a failed plan never leaves a half-written file.
//
// SVG preview: top view (x-y) and side view (x-z) of the world: the declared workspace, the
// obstacles, each camera's position with its field of view, every feasible candidate (grey),
// the chosen poses (numbered) and the tour.
#include "robocal/calib/mechanism.hpp"
#include "robocal/planner/cell.hpp"
#include "robocal/planner/plan.hpp"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace robocal::planner {

std::string plan_to_yaml(const calib::Mechanism& model, const Cell& cell, const PlanResult& plan,
                         const PlanOptions& options);
std::string plan_to_svg(const Cell& cell, const PlanResult& plan);
// Actuator readings of every pose of a plan file (sequential mode: the poses already measured).
// Throws core::InputError("file:line: problem").
std::vector<Eigen::VectorXd> read_plan_actuators(const std::string& path);

}  // namespace robocal::planner
