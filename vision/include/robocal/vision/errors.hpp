#pragma once
#include <stdexcept>

namespace robocal::vision {

// A problem with a user's input file (camera, target, pose). The message always names the file
// and, where known, the line: "board.yaml:7: tag_size must be positive (got -0.02)".
class FileFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace robocal::vision
