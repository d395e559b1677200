#pragma once
// The open link's conformance check behind `robocal link-check`: each requirement of
// robotio/OPEN_LINK.md tried against a running controller and judged pass / fail / skip, with
// what the controller said. An adapter author runs it against their controller before robocal
// drives the robot through it. It moves the robot only after `confirm_motion` agrees, and only
// between targets inside the box the operator gave (a straight actuator-space line between two
// points of a box stays inside it).
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace robocal::robotio {

enum class CheckVerdict : std::uint8_t { kPass, kFail, kSkip };
const char* to_string(CheckVerdict verdict);

struct LinkCheckItem {
  std::string requirement;
  CheckVerdict verdict = CheckVerdict::kSkip;
  std::string detail;  // what the controller said, or why it was skipped
};

struct LinkCheckOptions {
  // Motion box in the controller's units (m, rad), one value per actuator; empty = no motion.
  std::vector<double> lower, upper;
  double speed = 0.01;        // m/s or rad/s along the actuator path
  double acceleration = 0.1;  // per s^2
  std::chrono::milliseconds reply_timeout{2000};
  // Asked once before the first motion with a description of the planned moves.
  std::function<bool(const std::string& plan)> confirm_motion;
};

// Runs every check in order against `address` (open:HOST:PORT). Never throws for what the
// controller does; a check that cannot run for lack of an earlier one is skipped.
std::vector<LinkCheckItem> check_open_link(const std::string& address,
                                           const LinkCheckOptions& options);

}  // namespace robocal::robotio
