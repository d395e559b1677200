#include "test_paths.hpp"

namespace robocal::test {
const char* source_dir() {
  return ROBOCAL_PATH_SOURCE;
}
const char* testdata_dir() {
  return ROBOCAL_PATH_SOURCE "/testdata";
}
const char* shared_data_dir() {
  return ROBOCAL_PATH_SHARED_DATA;
}
const char* robocal_binary() {
  return ROBOCAL_PATH_BINARY;
}
}  // namespace robocal::test
