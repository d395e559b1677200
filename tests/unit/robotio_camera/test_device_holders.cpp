// Who holds a device open, from /proc/*/fd: what a camera that answers EBUSY is explained with.
// Checked on an ordinary file held by this process and by a child process, since a test machine
// need not have a camera.
#include "robocal/robotio/camera_v4l2.hpp"

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace robocal::robotio {
namespace {

namespace fs = std::filesystem;

bool holds(const std::vector<DeviceHolder>& holders, int pid) {
  for (const DeviceHolder& h : holders)
    if (h.pid == pid) return true;
  return false;
}

std::string own_command() {
  std::string command;
  std::ifstream comm("/proc/self/comm");
  std::getline(comm, command);
  return command;
}

struct DeviceHolders : ::testing::Test {
  fs::path dir = fs::temp_directory_path() / ("robocal_holders_" + std::to_string(::getpid()));
  std::string path = (dir / "video9").string();
  DeviceHolders() {
    fs::create_directories(dir);
    std::ofstream(path) << "x";
  }
  ~DeviceHolders() override { fs::remove_all(dir); }
};

TEST_F(DeviceHolders, FindsThisProcessOnlyWhileItHasThePathOpen) {
  EXPECT_FALSE(holds(processes_holding(path), ::getpid()));
  const int fd = ::open(path.c_str(), O_RDONLY);
  ASSERT_GE(fd, 0);
  const std::vector<DeviceHolder> holders = processes_holding(path);
  ASSERT_TRUE(holds(holders, ::getpid()));
  for (const DeviceHolder& h : holders)
    if (h.pid == ::getpid()) {
      EXPECT_EQ(h.command, own_command());
    }
  // The same file through another spelling of its path.
  EXPECT_TRUE(holds(processes_holding((dir / "." / "video9").string()), ::getpid()));
  ::close(fd);
  EXPECT_FALSE(holds(processes_holding(path), ::getpid()));
}

// Another process holds the device: the explanation names its PID and command and what to do;
// once it has exited, nobody is named.
TEST_F(DeviceHolders, TheExplanationNamesTheOtherProcessAndWhatToDo) {
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int fd = ::open(path.c_str(), O_RDONLY);
    const char byte = fd >= 0 ? '1' : '0';
    (void)!::write(ready[1], &byte, 1);
    ::pause();
    ::_exit(0);
  }
  char byte = 0;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1);
  ASSERT_EQ(byte, '1');
  const std::string said = busy_device_explanation(path);
  EXPECT_NE(said.find(path + " is in use by another process: PID " + std::to_string(child) + " (" +
                      own_command() + ") holds it open"),
            std::string::npos)
      << said;
  EXPECT_NE(said.find("kill PID"), std::string::npos) << said;
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
  ::close(ready[0]);
  ::close(ready[1]);
  const std::string after = busy_device_explanation(path);
  EXPECT_EQ(after.find("PID " + std::to_string(child)), std::string::npos) << after;
  EXPECT_NE(after.find("none found"), std::string::npos) << after;
}

}  // namespace
}  // namespace robocal::robotio
