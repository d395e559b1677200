#pragma once
// Tests on real recorded data (../shared/data/real) skip cleanly where it is absent, with the
// path in the message; but where the data should be there (CI sets ROBOCAL_REQUIRE_REAL_DATA=1
// when it sees the folder), a test that cannot find it fails instead of skipping silently.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace robocal::test {

inline bool real_data_required() {
  const char* required = std::getenv("ROBOCAL_REQUIRE_REAL_DATA");
  return required != nullptr && std::string(required) == "1";
}

}  // namespace robocal::test

#define SKIP_OR_FAIL_WITHOUT_REAL_DATA(dir)                                                 \
  do {                                                                                      \
    if (!std::filesystem::exists(dir)) {                                                    \
      if (::robocal::test::real_data_required()) {                                          \
        FAIL() << "real data expected (ROBOCAL_REQUIRE_REAL_DATA=1) but absent: " << (dir); \
      }                                                                                     \
      GTEST_SKIP() << "shared data absent: " << (dir);                                      \
    }                                                                                       \
  } while (false)
