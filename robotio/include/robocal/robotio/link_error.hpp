#pragma once
// Errors of the controller link. Every message names the device and, where there was one, what
// the controller said, so an operator can tell a cable fault from a firmware refusal.
#include <stdexcept>
#include <string>

namespace robocal::robotio {

// The controller could not be reached or answered something the link cannot accept (timeout,
// garbage, firmware error, unknown banner). `device` is the serial path or tcp address;
// `controller_said` the last line received ("" when nothing came back).
class LinkError : public std::runtime_error {
 public:
  LinkError(std::string device, const std::string& problem, std::string controller_said = "");
  const std::string& device() const { return device_; }
  const std::string& controller_said() const { return said_; }

 private:
  std::string device_;
  std::string said_;
};

// The safety guard refused a motion before anything was sent (outside the workspace, through an
// obstacle, too fast, not armed). Nothing moved.
class MotionRefused : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A motion was stopped on request (Ctrl-C, lost camera, operator) and the controller was sent its
// stop command. The session stays resumable: every move confirmed before this one stands.
class MotionInterrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace robocal::robotio
