// Every test gets its own temporary folder: at the start of each test, TMPDIR points at
// <TMPDIR>/t<pid>-<n> (the n-th test of the process), so temp_directory_path() and any robocal
// process the test starts write there. ctest runs each TEST as its own process, in parallel: two
// tests that pick the same scratch name (a helper shared by several tests, say) no longer remove
// each other's files. The folder is removed when the test passes and kept when it fails, for a look
// (its file `test` names the test). The name stays short: programs put Unix socket paths (at most
// 107 bytes) under TMPDIR, Chromium's profile lock among them.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>

namespace {

namespace fs = std::filesystem;

class PerTestTmpdir : public ::testing::EmptyTestEventListener {
 public:
  PerTestTmpdir() : base_(fs::temp_directory_path()) {}

  void OnTestStart(const ::testing::TestInfo& info) override {
    std::ostringstream name;  // not "t" + std::to_string(..): GCC 12's -Wrestrict false positive
    name << 't' << ::getpid() << '-' << ++count_;
    dir_ = base_ / name.str();
    fs::create_directories(dir_);
    std::ofstream(dir_ / "test") << info.test_suite_name() << "." << info.name() << "\n";
    ::setenv("TMPDIR", dir_.c_str(), 1);
  }

  void OnTestEnd(const ::testing::TestInfo& info) override {
    ::setenv("TMPDIR", base_.c_str(), 1);
    const auto* result = info.result();
    if (result != nullptr && !result->Failed()) {
      std::error_code ignored;
      fs::remove_all(dir_, ignored);
    }
  }

 private:
  fs::path base_;
  fs::path dir_;
  int count_ = 0;
};

// Registered before main() runs the tests (gtest_main); the listener list owns it.
const bool registered = [] {
  ::testing::UnitTest::GetInstance()->listeners().Append(new PerTestTmpdir);
  return true;
}();

}  // namespace
