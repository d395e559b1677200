#pragma once
// Skipping the camera tests that need two fake GigE cameras on their own addresses: the wrapper
// tests/integration/robotio_camera/run_in_netns.sh sets ROBOCAL_NETNS_UNAVAILABLE to the reason
// when it could not create the test's network namespace.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

namespace robocal::testing {

// Why the two-address tests cannot run, or empty.
inline std::string netns_unavailable() {
  const char* reason = std::getenv("ROBOCAL_NETNS_UNAVAILABLE");
  return reason != nullptr ? std::string(reason) : std::string();
}

}  // namespace robocal::testing

#define SKIP_WITHOUT_NETNS()                                                             \
  do {                                                                                   \
    const std::string reason = ::robocal::testing::netns_unavailable();                  \
    if (!reason.empty()) {                                                               \
      GTEST_SKIP() << "two fake GigE cameras need a test network namespace: " << reason; \
    }                                                                                    \
  } while (false)
