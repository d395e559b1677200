#include "cli/command_registry.hpp"

#include "cli/cli_common.hpp"
#include "robocal_version.hpp"

#include <fmt/core.h>

#include <exception>
#include <map>

namespace robocal::app {

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
CommandSpec sim_controller_command();
CommandSpec plan_command();

// In the order of a calibration: the demo first, then the steps a user runs on real data.
const std::vector<CommandSpec>& all_commands() {
  static const std::vector<CommandSpec> commands = {
      demo_command(),           kin_command(),      target_command(),  render_command(),
      intrinsics_command(),     rig_command(),      measure_command(), identify_command(),
      simulate_command(),       validate_command(), batch_command(),   plan_command(),
      sim_controller_command(), version_command(),
  };
  return commands;
}

int run_cli(int argc, const char* const* argv) {
  CLI::App cli{
      "robocal measures a robot's end-effector with cameras and identifies the robot's real\n"
      "geometry (serial arms and parallel robots: Delta, linear delta, Gantry-Tau, cable robots).\n"
      "\n"
      "Run `robocal <command> --help` for what each command does and its options.\n"
      "Exit codes: 0 ok, 1 result not acceptable, 2 bad command line, 3 bad input file,\n"
      "4 internal error.",
      "robocal"};
  cli.set_version_flag("--version", std::string("robocal ") + kVersion);
  cli.require_subcommand(1);
  cli.fallthrough(false);

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
    try {
      return actions.at(sub)();
    } catch (const InputError& e) {
      fmt::print(stderr, "error: {}\n", e.what());
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
