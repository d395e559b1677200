#pragma once
#include "robocal/core/input_error.hpp"

namespace robocal::vision {

// A problem with a user's input file (camera, target, pose): the project's one input-error type
// (core/input_error.hpp). The message always names the file and, where known, the line:
// "board.yaml:7: tag_size must be positive (got -0.02)".
using FileFormatError = core::InputError;

}  // namespace robocal::vision
