// `robocal link-check ADDRESS`: the open link conformance check (robotio/OPEN_LINK.md) an adapter
// author runs against their controller. Orchestration only: the checks are robocal_robotio's
// check_open_link.
#include "cli/command_registry.hpp"
#include "robocal/robotio/open_link.hpp"
#include "robocal/robotio/open_link_check.hpp"

#include <fmt/core.h>

#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace robocal::app {
namespace {

struct LinkCheckCli {
  std::string address;
  std::string lower, upper;
  double speed = 0.01;
  double acceleration = 0.1;
  double reply_timeout_s = 2.0;
  bool yes = false;
};

// "0.1,0.2,0.3" -> numbers; nullopt when an item is not a number.
std::optional<std::vector<double>> parse_list(const std::string& text) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      std::size_t used = 0;
      out.push_back(std::stod(item, &used));
      if (used != item.size()) return std::nullopt;
    } catch (const std::exception&) {
      return std::nullopt;
    }
  }
  return out;
}

// Checked while the command line is parsed, so a bad list is a usage error (exit 2).
const CLI::Validator kNumberList(
    [](std::string& text) {
      return parse_list(text) ? std::string()
                              : "expected numbers separated by commas, got '" + text + "'";
    },
    "N,N,...");

bool ask_operator(const std::string& plan) {
  fmt::print("{}.\nType yes to move the robot: ", plan);
  std::fflush(stdout);
  std::string answer;
  return static_cast<bool>(std::getline(std::cin, answer)) && answer == "yes";
}

int run_link_check(const LinkCheckCli& o) {
  robotio::LinkCheckOptions options;
  options.lower = parse_list(o.lower).value_or(std::vector<double>{});
  options.upper = parse_list(o.upper).value_or(std::vector<double>{});
  options.speed = o.speed;
  options.acceleration = o.acceleration;
  options.reply_timeout = std::chrono::milliseconds(static_cast<long>(1000.0 * o.reply_timeout_s));
  options.confirm_motion = [&o](const std::string& plan) {
    if (o.yes) {
      fmt::print("{} (confirmed by --yes).\n", plan);
      return true;
    }
    return ask_operator(plan);
  };
  fmt::print("link-check {}: {} {}.{}\n", o.address, robotio::kOpenLinkProtocol,
             robotio::kOpenLinkMajor, robotio::kOpenLinkMinor);
  int failed = 0, passed = 0, skipped = 0;
  for (const robotio::LinkCheckItem& item : robotio::check_open_link(o.address, options)) {
    fmt::print("{}  {}: {}\n", robotio::to_string(item.verdict), item.requirement, item.detail);
    failed += item.verdict == robotio::CheckVerdict::kFail;
    passed += item.verdict == robotio::CheckVerdict::kPass;
    skipped += item.verdict == robotio::CheckVerdict::kSkip;
  }
  fmt::print("link-check: {} passed, {} failed, {} skipped\n", passed, failed, skipped);
  return failed == 0 ? kExitOk : kExitFailure;
}

}  // namespace

CommandSpec link_check_command() {
  return {"link-check", "Check an open link controller against the protocol's requirements",
          [](CLI::App& cmd) -> CommandAction {
            auto o = std::make_shared<LinkCheckCli>();
            cmd.description(
                "Runs each requirement of the open link protocol (robotio/OPEN_LINK.md) against\n"
                "a controller or adapter at ADDRESS (open:HOST:PORT) and prints PASS, FAIL or\n"
                "SKIP for each, with what the controller said. The robot moves only when\n"
                "--lower and --upper give a box of actuator positions (the controller's units,\n"
                "m or rad, one value per actuator), the robot is inside it, and the operator\n"
                "types yes (--yes confirms in advance). Exit codes: 0 every check passed,\n"
                "1 a check failed, 2 bad command line.");
            cmd.add_option("address", o->address, "open:HOST:PORT")->required();
            cmd.add_option("--lower", o->lower, "Lowest actuator positions of the motion box")
                ->check(kNumberList);
            cmd.add_option("--upper", o->upper, "Highest actuator positions of the motion box")
                ->check(kNumberList);
            cmd.add_option("--speed", o->speed, "Speed along the actuator path (m/s or rad/s)")
                ->check(CLI::PositiveNumber);
            cmd.add_option("--acceleration", o->acceleration, "Acceleration (per s^2)")
                ->check(CLI::PositiveNumber);
            cmd.add_option("--reply-timeout", o->reply_timeout_s, "Seconds to wait for a reply")
                ->check(CLI::PositiveNumber);
            cmd.add_flag("--yes", o->yes, "Confirm the motion checks without asking");
            return [o] { return run_link_check(*o); };
          }};
}

}  // namespace robocal::app
