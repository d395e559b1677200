#pragma once
// The one error type for bad input: a missing or malformed file, a value out of range, data that
// does not fit together. The message says what is wrong and where ("board.yaml:7: tag_size must
// be positive (got -0.02)"); front ends turn it into exit code 3. Every part throws this type (or
// an alias of it), so a caller needs one catch for "the user's input is wrong".
#include <stdexcept>

namespace robocal::core {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace robocal::core
