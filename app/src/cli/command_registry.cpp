#include "cli/command_registry.hpp"

#include "cli/cli_common.hpp"
#include "robocal/core/interrupt_cleanup.hpp"
#include "robocal/robotio/camera_source.hpp"
#include "robocal/robotio/link_error.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>

#include <filesystem>

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <exception>
#include <map>
#include <string>

namespace robocal::app {

namespace {

// Ctrl-C or a termination request: remove what was being written (temporary files, staging
// folders: core/interrupt_cleanup.hpp), say what is on disk and how to go on, then stop at once
// (128 + signal). Only async-signal-safe calls here; the text is made before the handler is
// installed. A command that moves a robot installs its own handler (robotio's safety guard: the
// first Ctrl-C stops the motion) in place of this one while it is armed.
char interrupt_message[512];
std::size_t interrupt_length = 0;

extern "C" void on_interrupt(int sig) {
  core::remove_unfinished_writes();
  if (interrupt_length > 0) {
    const ssize_t written = ::write(STDERR_FILENO, interrupt_message, interrupt_length);
    (void)written;
  }
  ::_exit(128 + sig);
}

void install_interrupt_handler(const std::string& command) {
  const std::string text = fmt::format(
      "\nrobocal {}: interrupted. Every file already written is complete (files and results are "
      "replaced whole or not at all: what was not finished is removed, earlier results are as "
      "they were) and recorded data is never overwritten: run the command again to redo what "
      "was not finished.\n",
      command);
  interrupt_length = std::min(text.size(), sizeof interrupt_message);
  std::memcpy(interrupt_message, text.data(), interrupt_length);
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

// The command names, as `robocal --help` lists them, for the refusal of an unknown one.
std::string command_list(const std::vector<CommandSpec>& commands) {
  std::string list;
  for (const CommandSpec& spec : commands) list += (list.empty() ? "" : ", ") + spec.name;
  return list;
}

// The first argument names the command; a word that is no command is named as such (the
// parser alone would say only that a command is missing).
bool is_unknown_command(int argc, const char* const* argv,
                        const std::vector<CommandSpec>& commands) {
  if (argc < 2 || argv[1][0] == '-') return false;
  const std::string word = argv[1];
  return std::none_of(commands.begin(), commands.end(),
                      [&word](const CommandSpec& spec) { return spec.name == word; });
}

}  // namespace

// Each command file defines one of these.
CommandSpec version_command();
CommandSpec kin_command();
CommandSpec target_command();
CommandSpec render_command();
CommandSpec intrinsics_command();
CommandSpec rig_command();
CommandSpec measure_command();
CommandSpec identify_command();
CommandSpec demo_command();
CommandSpec simulate_command();
CommandSpec validate_command();
CommandSpec batch_command();
CommandSpec batch_merge_command();
CommandSpec sim_controller_command();
CommandSpec link_check_command();
CommandSpec sim_cell_command();
CommandSpec plan_command();
CommandSpec compensate_command();
CommandSpec report_command();
CommandSpec export_command();
CommandSpec collect_command();
CommandSpec wizard_command();
CommandSpec handeye_command();

// In the order of a calibration: the demo first, then the steps a user runs on real data.
const std::vector<CommandSpec>& all_commands() {
  static const std::vector<CommandSpec> commands = {
      // clang-format off
      demo_command(), kin_command(), target_command(), render_command(), intrinsics_command(),
      rig_command(), measure_command(), identify_command(), simulate_command(),
      validate_command(), batch_command(), batch_merge_command(), plan_command(),
      link_check_command(),
      wizard_command(), sim_cell_command(), collect_command(), sim_controller_command(), version_command(), compensate_command(),
      report_command(), export_command(), handeye_command(),
      // clang-format on
  };
  return commands;
}

int run_cli(int argc, const char* const* argv) {
  CLI::App cli{
      "robocal measures a robot's end-effector with cameras and identifies the robot's real\n"
      "geometry (serial arms and parallel robots: Delta, linear delta, Gantry-Tau, cable robots).\n"
      "\n"
      "Run `robocal <command> --help` for what each command does and its options.\n"
      "Exit codes: 0 ok, 1 result not acceptable (or a camera or controller failed), 2 bad\n"
      "command line (an unknown command or option, a value outside its choices, options that\n"
      "conflict or do not apply), 3 bad input file, 4 internal error.",
      "robocal"};
  cli.set_version_flag("--version", std::string("robocal ") + kVersion);
  cli.require_subcommand(1);
  cli.fallthrough(false);

  if (is_unknown_command(argc, argv, all_commands())) {
    fmt::print(stderr,
               "error: unknown command '{}'; the commands are: {}\nRun `robocal --help` for what "
               "each does.\n",
               argv[1], command_list(all_commands()));
    return kExitUsage;
  }

  std::map<const CLI::App*, CommandAction> actions;
  for (const CommandSpec& spec : all_commands()) {
    CLI::App* sub = cli.add_subcommand(spec.name, spec.summary);
    actions[sub] = spec.install(*sub);
  }

  try {
    cli.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return cli.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return cli.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return cli.exit(e);
  } catch (const CLI::ParseError& e) {
    cli.exit(e);
    return kExitUsage;
  }

  for (const CLI::App* sub : cli.get_subcommands()) {
    install_interrupt_handler(sub->get_name());
    try {
      return actions.at(sub)();
    } catch (const UsageError& e) {
      fmt::print(stderr, "error: {}\nRun `robocal {} --help` for its options.\n", e.what(),
                 sub->get_name());
      return kExitUsage;
    } catch (const InputError& e) {
      fmt::print(stderr, "error: {}\n", e.what());
      return kExitBadInput;
    } catch (const robotio::CameraError& e) {
      // A device that failed (unplugged, lost on a busy network): not a robocal bug.
      fmt::print(stderr, "error: {}\nEverything written before stays on disk.\n", e.what());
      return kExitFailure;
    } catch (const robotio::LinkError& e) {
      fmt::print(stderr, "error: {}\nEverything written before stays on disk.\n", e.what());
      return kExitFailure;
    } catch (const std::filesystem::filesystem_error& e) {
      // A folder that cannot be created or read (permissions, a full disk, a file where a folder
      // should be): the operator's environment, not a robocal bug.
      fmt::print(stderr, "error: {}\n", filesystem_problem(e));
      return kExitBadInput;
    } catch (const std::exception& e) {
      fmt::print(stderr, "internal error: {}\n(please report this with the command you ran)\n",
                 e.what());
      return kExitInternal;
    }
  }
  return kExitUsage;
}

}  // namespace robocal::app
