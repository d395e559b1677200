#pragma once
// Robot description files (YAML; format in testdata/robots/README.md) -> Mechanism.
// Every error names the file, the line and the problem (RobotFileError).
#include "robocal/calib/mechanism.hpp"
#include "robocal/core/input_error.hpp"

#include <Eigen/Core>

#include <stdexcept>
#include <string>
#include <vector>

namespace robocal::calib {

// The project's one input-error type (core/input_error.hpp).
using RobotFileError = core::InputError;

// Reads and validates a robot file.
Mechanism load_robot_file(const std::string& path);
// Same from text; `source` names it in messages.
Mechanism parse_robot_yaml(const std::string& text, const std::string& source);

// Evaluates a numeric expression: numbers, + - * / ^, parentheses, pi, sqrt(), sin(), cos(),
// deg(x) (degrees -> rad). Throws std::invalid_argument with the problem.
double evaluate_expression(const std::string& text);

// Parses "NAME=VALUE" (VALUE an expression) and sets params[index of NAME]. Throws
// RobotFileError naming the model's file and the unknown parameter (with close matches).
void apply_parameter_override(const Mechanism& model, Eigen::VectorXd& params,
                              const std::string& assignment);

}  // namespace robocal::calib
