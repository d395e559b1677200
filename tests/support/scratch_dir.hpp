#pragma once
// A fresh folder per test for tests that write files, and reading a written file back.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

namespace robocal::test {

// The whole content of a text file ("" when it cannot be read).
inline std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Fixture base: `dir` is <temp>/<prefix><pid>_<test name>, created before each test and removed
// after it, so tests running in parallel (ctest -j) never share files.
class ScratchDirTest : public ::testing::Test {
 protected:
  explicit ScratchDirTest(std::string prefix) : prefix_(std::move(prefix)) {}
  void SetUp() override {
    dir = std::filesystem::temp_directory_path() /
          (prefix_ + std::to_string(::getpid()) + "_" +
           ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir);
  }
  void TearDown() override { std::filesystem::remove_all(dir); }
  // Path of `name` inside the scratch folder.
  std::string file(const std::string& name) const { return (dir / name).string(); }

  std::filesystem::path dir;

 private:
  std::string prefix_;
};

}  // namespace robocal::test
